"""Estimate a table's physical parameters, scatter and discrepancy (the levels model of
:mod:`idtool._fit._variability`, on the table's own levels).

Data per row: ``y = (log OFF, log FR)``, ``FR = ON / OFF``. Their covariance is

    C = M + scatter_mu^2 I (OFF rows) + scatter_fr^2 I (FR rows) + discrepancy_fr^2 K

with ``M`` the known measurement variance from the table's standard errors (relative:
``Var log OFF = (se_off / OFF)^2``, ``Var log FR = (se_on / ON)^2 + (se_off / OFF)^2``,
their covariance ``-(se_off / OFF)^2``), and ``K`` 1 between rows at one condition (the
discrepancy is the condition's; independent between conditions here, where the trace
fit's is a smooth function of the operating point). With one row per condition the
scatter and the discrepancy cannot be told apart: their sum is ``discrepancy_fr``.
Each sd is bounded below by :data:`SD_FLOOR` (a table's values are rounded; an exact
fit of ``k`` parameters to ``k`` numbers would otherwise drive an sd to zero).

Stages: multi-start Gauss-Newton (:func:`scipy.optimize.least_squares`, on the
whitened residuals ``C^-1/2 (y - g(theta))``) at starting sds, then alternately the sds
by restricted maximum likelihood (REML, theta profiled on the linearised model) and
theta by generalised least squares, until the sds settle; by REML, the discrepancy sd
then integrated over its likelihood (:mod:`idtool._levels._discrepancy`: a table rarely
pins it) and theta solved again at the sd that gives. Intervals: each parameter's
Wald interval checked against its profile (the others refitted, the sds held), as
:mod:`idtool._lawfit._profile` does: a side where ``-2 log L`` rises by less than 3 is
walked out to a rise of 3.84, or to the parameter's range (then open).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from typing import Any, Protocol

import numpy as np
import scipy.linalg
import scipy.optimize

from idtool._fit._result import Z95, Z_AT_BOUND
from idtool._lawfit._profile import (
    CHI2_95,
    CROSSING_TOL,
    MAX_BISECTIONS,
    TOO_FLAT,
    Side,
    line_crossing,
)
from idtool._levels._discrepancy import DiscrepancyPosterior, discrepancy_posterior
from idtool._model._params import Param

__all__ = ["SD_FLOOR", "SD_NAMES", "Optimum", "TableModel", "estimate", "profile_sides"]

SD_NAMES = ("scatter_mu", "scatter_fr", "discrepancy_fr")
SD_FLOOR = 1e-3  # relative: 0.1%
SD_CEIL = 2.0
NULL_EIG = 1e-8  # an eigenvalue of the scaled information below this: not informed
_DRAWS = 400  # random points screened by their cost (one model evaluation each)
_STARTS = 12  # the best of them, each taken to its optimum
_ROUNDS = 8


class TableModel(Protocol):
    """What the stages read of a table's model: the law's
    (:class:`~idtool._levels._model.LevelsModel`) or the law-free one
    (:class:`~idtool._levels._free.FreeAmplitudeModel`)."""

    @property
    def table(self) -> Any: ...

    @property
    def params(self) -> tuple[Param, ...]: ...

    def log_levels(self, theta) -> Any: ...

    def jacobian(self, theta) -> Any: ...

    def internal(self, **values: float) -> np.ndarray: ...


@dataclasses.dataclass(frozen=True)
class Optimum:
    """What :func:`estimate` found.

    Attributes:
        theta: internal estimate (k,).
        cov_theta: its covariance (k, k), internal scale (pseudo-inverse where the data
            do not inform a direction).
        sds: each of :data:`SD_NAMES` -> relative sd (0 for one not estimated).
        active: the sds estimated (scatter_fr needs repeats at a condition).
        y, cov: the data's log levels (2 n,) and their covariance at ``sds``.
        chi2: ``r' C^-1 r`` at the optimum; ``chi2_noise``: against the measurement
            variance alone (NaN without standard errors).
        null: unit directions (k, m) of theta the data do not inform (m may be 0).
        loglik: log-likelihood at the optimum (the sds at their REML estimates).
        restricted: the sds by REML (else ML: no residual degrees of freedom).
        discrepancy: by REML, the discrepancy sd's posterior
            (:mod:`idtool._levels._discrepancy`); then ``sds["discrepancy_fr"]``, ``cov``,
            ``theta``, ``cov_theta`` and ``chi2`` are at its band sd, not at REML's
            estimate.
    """

    theta: np.ndarray
    cov_theta: np.ndarray
    sds: dict[str, float]
    active: tuple[bool, bool, bool]
    y: np.ndarray
    cov: np.ndarray
    chi2: float
    null: np.ndarray
    loglik: float
    restricted: bool = True
    discrepancy: DiscrepancyPosterior | None = None


def _data(model: TableModel) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``y`` (2 n,), the measurement covariance ``M`` and the condition matrix ``K``."""
    t = model.table
    n = t.n_rows
    y = np.concatenate([np.log(t.off), np.log(t.on / t.off)])
    s_off = np.nan_to_num(t.off_se / t.off)
    s_on = np.nan_to_num(t.on_se / t.on)
    m = np.zeros((2 * n, 2 * n))
    i = np.arange(n)
    m[i, i] = s_off**2
    m[n + i, n + i] = s_on**2 + s_off**2
    m[i, n + i] = m[n + i, i] = -(s_off**2)
    index, _ = t.operating_points
    k = (index[:, None] == index[None, :]).astype(float)
    return y, m, k


def _cov(m: np.ndarray, k: np.ndarray, sds: np.ndarray) -> np.ndarray:
    n = k.shape[0]
    c = m.copy()
    c[:n, :n] += sds[0] ** 2 * np.eye(n)
    c[n:, n:] += sds[1] ** 2 * np.eye(n) + sds[2] ** 2 * k
    return c


def _whitened(model, y, c, fixed: dict[int, float] | None = None):
    """Residual and Jacobian functions of the free parameters for least_squares."""
    chol = np.linalg.cholesky(c)
    k = len(model.params)
    fixed = fixed or {}
    free = [j for j in range(k) if j not in fixed]

    def full(x):
        theta = np.empty(k)
        theta[free] = x
        for j, v in fixed.items():
            theta[j] = v
        return theta

    def fun(x):
        r = y - np.asarray(model.log_levels(full(x)))
        return scipy.linalg.solve_triangular(chol, r, lower=True)

    def jac(x):
        g = np.asarray(model.jacobian(full(x)))[:, free]
        return -scipy.linalg.solve_triangular(chol, g, lower=True)

    return fun, jac, full, free


def _solve(model, y, c, theta0, fixed=None):
    fun, jac, full, free = _whitened(model, y, c, fixed)
    x0 = np.clip(np.asarray(theta0, float)[free], -Z_AT_BOUND, Z_AT_BOUND)
    with np.errstate(all="ignore"):
        res = scipy.optimize.least_squares(fun, x0, jac=jac, method="trf", x_scale="jac")
    return full(res.x), float(2.0 * res.cost)


def _starts(model: TableModel, rng: np.random.Generator) -> list[np.ndarray]:
    """Seeded random points: each parameter log-uniform in its start box (or at its start),
    mu from the OFF levels, the coupling gain placed so that the velocity ratio at the
    fastest condition lies below 1 (no start on the flat FR = 1 plateau)."""
    t = model.table
    mu = float(np.median(t.off if t.friction == "coefficient" else t.off / t.normal_load_n))
    omega = 2 * math.pi * float(np.min(t.vibration_frequency_hz))
    gain_min = float(np.max(t.sliding_speed_m_s)) / (float(np.min(t.amplitude_m)) * omega)
    out = []
    for _ in range(_DRAWS):
        values = {}
        for p in model.params:
            if p.name == "mu":
                values[p.name] = mu
            elif p.name == "coupling_gain":
                values[p.name] = min(gain_min * 10 ** rng.uniform(-0.5, 2.0), 0.99 * p.hi)
            elif p.start_box is not None:
                lo, hi = (math.log10(b) for b in p.start_box)
                values[p.name] = 10 ** rng.uniform(lo, hi)
            else:
                values[p.name] = p.start
        values = {
            p.name: float(np.clip(values[p.name], p.lo * 1.01, p.hi * 0.99)) for p in model.params
        }
        out.append(model.internal(**values))
    return out


def _reml(log_sds, active, r, g, m, kmat, restricted=True):
    return _reml_at(np.where(active, np.exp(log_sds), 0.0), r, g, m, kmat, restricted)


def _reml_at(sds, r, g, m, kmat, restricted=True):
    """Negative (restricted) log-likelihood at the sds (3,) (a constant left out)."""
    c = _cov(m, kmat, sds)
    try:
        chol = np.linalg.cholesky(c)
    except np.linalg.LinAlgError:
        return 1e30
    rw = scipy.linalg.solve_triangular(chol, r, lower=True)
    gw = scipy.linalg.solve_triangular(chol, g, lower=True)
    logdet_info = 0.0
    if restricted:
        info = gw.T @ gw
        scale = np.sqrt(np.maximum(np.diag(info), 1e-300))
        eig = np.linalg.eigvalsh(info / np.outer(scale, scale))
        logdet_info = float(np.sum(np.log(np.maximum(eig, NULL_EIG))) + 2 * np.sum(np.log(scale)))
    return 0.5 * (2 * np.sum(np.log(np.diag(chol))) + rw @ rw + logdet_info)


def _rank(g: np.ndarray) -> int:
    """Number of directions of theta that ``g``'s rows inform (scaled, as :func:`_null`)."""
    return int(g.shape[1] - _null(g.T @ g)[1].shape[1])


def _null(info: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Pseudo-inverse of the information and its uninformed unit directions (k, m)."""
    scale = np.sqrt(np.maximum(np.diag(info), 1e-300))
    eig, vec = np.linalg.eigh(info / np.outer(scale, scale))
    keep = eig > NULL_EIG * max(float(eig.max()), 1e-300)
    inv = (vec[:, keep] / eig[keep]) @ vec[:, keep].T
    cov = inv / np.outer(scale, scale)
    null = vec[:, ~keep] / scale[:, None]
    null = null / np.maximum(np.max(np.abs(null), axis=0), 1e-300)
    return cov, null


def _alternate(model, y, m, kmat, active, theta, restricted):
    """The sds (REML or ML) and theta (GLS) in turn until the sds settle. Each theta
    step starts both where theta is and at the multi-start's optimum (``theta`` on
    entry), keeping the lower GLS cost: a plateau of the model (FR = 1 past VR = 1)
    otherwise captured theta once the sds had widened."""
    anchor = np.asarray(theta, float).copy()
    lo, hi = math.log(SD_FLOOR), math.log(SD_CEIL)
    log_sds = np.log(np.where(active, 0.03, 1.0))
    for _ in range(_ROUNDS):
        r = y - np.asarray(model.log_levels(theta))
        g = np.asarray(model.jacobian(theta))
        res = scipy.optimize.minimize(
            _reml,
            log_sds,
            args=(active, r, g, m, kmat, restricted),
            method="L-BFGS-B",
            bounds=[(lo, hi)] * 3,
        )
        moved = np.max(np.abs(res.x - log_sds)[active])
        log_sds = res.x
        c = _cov(m, kmat, np.where(active, np.exp(log_sds), 0.0))
        theta = min(_solve(model, y, c, theta), _solve(model, y, c, anchor), key=lambda x: x[1])[0]
        if moved < 1e-3:
            break
    return theta, log_sds


def estimate(
    model: TableModel, seed: int = 0, starts: Sequence[np.ndarray] | None = None
) -> Optimum:
    """Stages of the module docstring; returns the :class:`Optimum`. ``starts``
    (internal theta) replace the seeded multi-start's random points."""
    y, m, kmat = _data(model)
    index, first = model.table.operating_points
    separable = bool(index.size > first.size)
    active = np.array([True, separable, True])
    sds = np.where(active, 0.03, 0.0)
    c = _cov(m, kmat, np.maximum(sds, SD_FLOOR * active))
    rng = np.random.default_rng(seed)
    chol = np.linalg.cholesky(c)

    def cost(theta):
        with np.errstate(all="ignore"):
            r = y - np.asarray(model.log_levels(theta))
        w = scipy.linalg.solve_triangular(chol, r, lower=True)
        return float(w @ w) if np.all(np.isfinite(w)) else math.inf

    draws = sorted(_starts(model, rng) if starts is None else starts, key=cost)[:_STARTS]
    best = min((_solve(model, y, c, s) for s in draws), key=lambda x: x[1])
    theta = best[0]
    # REML needs residual degrees of freedom among the friction ratios: with as many
    # informed directions as conditions (two speeds, a two-parameter coupling) its
    # likelihood is flat or rises without end in the discrepancy; plain ML then
    # (the misfit itself sets it; biased low)
    n_cond = int(first.size)
    g_fr = np.asarray(model.jacobian(theta))[y.size // 2 :][first]
    restricted = n_cond - _rank(g_fr) > 0
    theta, log_sds = _alternate(model, y, m, kmat, active, theta, restricted)
    if restricted and np.any(log_sds[active] >= math.log(SD_CEIL) - 1e-6):
        # REML ran to the ceiling: the residual degrees of freedom the rank counted sit
        # on a plateau of the model (FR = 1 past VR = 1); the ML sds instead
        restricted = False
        theta, log_sds = _alternate(model, y, m, kmat, active, best[0], restricted)
    sd_values = np.where(active, np.exp(log_sds), 0.0)
    c = _cov(m, kmat, sd_values)
    r = y - np.asarray(model.log_levels(theta))
    chol = np.linalg.cholesky(c)
    rw = scipy.linalg.solve_triangular(chol, r, lower=True)
    # the likelihood's maximum, at the estimated sds: what BIC and the shape check read
    loglik = -0.5 * (
        float(rw @ rw) + 2 * float(np.sum(np.log(np.diag(chol)))) + y.size * math.log(2 * math.pi)
    )
    discrepancy = None
    if restricted:
        # the discrepancy sd integrated over its REML likelihood (_discrepancy.py); theta
        # by GLS again at the sd the intervals and bands use
        g = np.asarray(model.jacobian(theta))

        def nll(tau: float) -> float:
            return _reml_at(np.array([sd_values[0], sd_values[1], tau]), r, g, m, kmat)

        discrepancy = discrepancy_posterior(nll, float(sd_values[2]))
        sd_values[2] = discrepancy.band_sd
        c = _cov(m, kmat, sd_values)
        theta = min(_solve(model, y, c, theta), _solve(model, y, c, best[0]), key=lambda x: x[1])[0]
        r = y - np.asarray(model.log_levels(theta))
        chol = np.linalg.cholesky(c)
        rw = scipy.linalg.solve_triangular(chol, r, lower=True)
    g = np.asarray(model.jacobian(theta))
    gw = scipy.linalg.solve_triangular(chol, g, lower=True)
    cov_theta, null = _null(gw.T @ gw)
    chi2 = float(rw @ rw)
    return Optimum(
        theta=theta,
        cov_theta=cov_theta,
        sds={name: float(s) for name, s in zip(SD_NAMES, sd_values, strict=True)},
        active=(bool(active[0]), bool(active[1]), bool(active[2])),
        y=y,
        cov=c,
        chi2=chi2,
        null=null,
        loglik=loglik,
        restricted=restricted,
        discrepancy=discrepancy,
    )


def profile_sides(model: TableModel, opt: Optimum, j: int) -> tuple[Side, Side, np.ndarray]:
    """Parameter ``j``'s interval sides (module docstring), internal scale, and theta
    refitted at each end (2, k) (at the range's edge for an open side): what
    predictions read where the table does not pin the parameter."""
    # an estimate the optimiser ran beyond the range's edge (a direction the table
    # leaves flat: Kt of a soft transverse contact reached z = -3.6e4) is at its bound;
    # walked from there, six bisections of [-3.6e4, 7] stopped at z = -271 (Kt's lower
    # bound) and stated Kt < 1e4 N/m against a truth of 2e6 inside the flat region
    z = float(np.clip(opt.theta[j], -Z_AT_BOUND, Z_AT_BOUND))
    var = float(opt.cov_theta[j, j])
    uninformed = opt.null.shape[1] > 0 and np.max(np.abs(opt.null[j])) > 0.1
    se = math.sqrt(var) if var > 0 and not uninformed else math.inf

    refits: dict[float, np.ndarray] = {}

    def rise(at: float) -> float:
        refits[at], chi2 = _solve(model, opt.y, opt.cov, opt.theta, {j: at})
        return max(chi2 - opt.chi2, 0.0)

    sides = []
    for sign in (-1.0, 1.0):
        end = z + sign * Z95 * se if math.isfinite(se) else sign * Z_AT_BOUND
        beyond = abs(end) >= Z_AT_BOUND
        end = float(np.clip(end, -Z_AT_BOUND, Z_AT_BOUND))
        if sign * (end - z) <= 0:  # an optimum at the range's edge
            sides.append(Side(sign * math.inf, 0.0, "open"))
            continue
        r = rise(end)
        if r >= TOO_FLAT and not beyond and math.isfinite(se):
            sides.append(Side(end, r, "wald"))
            continue
        sides.append(_walk(rise, z, sign, end, r))
    ends = np.empty((2, opt.theta.size))
    for k, side in enumerate(sides):
        at = float(np.clip(side.z, -Z_AT_BOUND, Z_AT_BOUND))
        if sign_of(k) * (at - z) <= 0:
            ends[k] = opt.theta
            continue
        if at not in refits:
            rise(at)
        ends[k] = refits[at]
    return sides[0], sides[1], ends


def sign_of(k: int) -> float:
    return -1.0 if k == 0 else 1.0


def _walk(rise, z: float, sign: float, end: float, r_end: float) -> Side:
    """Out from ``z`` to where the rise reaches 3.84 (bracketed by doubling steps, then
    :func:`crossing`), or open at the edge."""
    inner, outer = z, None
    r_inner, r_outer = 0.0, math.nan
    step = abs(end - z)
    at, r = end, r_end
    for _ in range(6):
        if r >= CHI2_95:
            outer, r_outer = at, r
            break
        inner, r_inner = at, r
        if abs(at) >= Z_AT_BOUND:
            return Side(sign * math.inf, r_end, "open")
        step *= 2.0
        at = float(np.clip(z + sign * step, -Z_AT_BOUND, Z_AT_BOUND))
        r = rise(at)
    if outer is None:
        if r >= CHI2_95:
            outer, r_outer = at, r
        else:
            return Side(sign * math.inf, r_end, "open")
    return Side(crossing(rise, inner, r_inner, outer, r_outer), r_end, "profile")


def crossing(rise, inner: float, r_inner: float, outer: float, r_outer: float) -> float:
    """Where ``rise`` reaches 3.84 between ``inner`` (below it) and ``outer`` (at or
    above it): bisected to :data:`~idtool._lawfit._profile.CROSSING_TOL` on the internal
    scale, then read off the line through the bracket's ends
    (:func:`~idtool._lawfit._profile.line_crossing`, as ``fit-law``'s walk)."""
    for _ in range(MAX_BISECTIONS):
        if abs(outer - inner) <= CROSSING_TOL:
            break
        mid = 0.5 * (inner + outer)
        r = rise(mid)
        if r >= CHI2_95:
            outer, r_outer = mid, r
        else:
            inner, r_inner = mid, r
    return float(line_crossing(inner, r_inner, outer, r_outer))
