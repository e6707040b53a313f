"""Checks of the levels model's intervals against its own likelihood.

The default fit reports the physical parameters' intervals from the levels model
(:mod:`idtool._fit._variability`): ``y ~ N(g(theta), C)``, ``y`` the traces' free log
levels, ``C = V + Sigma(sds)`` at the REML sds, and the Gauss-Newton (Wald) covariance
``(G^T C^-1 G)^-1``. That takes ``-2 log L`` as quadratic in each parameter's internal
value. Where the friction ratio hardly moves with a parameter it need not be: near the
Coulomb limit (``Lambda = Kt a / (mu N)`` about 10, the transverse direction's small
bench of :mod:`idtool._simulate._direction_bench`) Kt's profile has two basins, at the
truth and 0.3-0.6 decades above it, their minima within 1.3 of each other and a barrier
of 0.5-7 units of ``-2 log L`` between them. The fit lands in either, and its Wald
interval covers that basin only: it missed the truth on 6 of 10 seeds, though the truth
was within 3.03 of the profile's minimum on all 10. (The noise-only fit's check,
:func:`idtool._fit._intervals.check_intervals`, does not reach the reported interval:
the levels model replaces it.)

:func:`check_level_intervals` refits the other physical parameters with one held at
its Wald ends and at 1.5 and 2 times their distance from the estimate; a quadratic
rises by 3.84, 8.6 and 15.4 there. Where it rises by less than half that at any of
them (the likelihood is flatter than the interval assumes: another basin or a plateau
beyond), the interval is widened to its union with the profile likelihood's: walked
out from the estimate on each side (:func:`profile_side`) and taken from the profile's
minimum over both sides (every basin within 3.84 of it). Never narrowed: with the sds
held at their REML values the profile can be overconfident where the model misses the
data (a profile end inside the Wald interval excluded the truth on a departure the
Wald end held). A refit is a Gauss-Newton solve on the traces' levels, no
time series: 10-30 ms; 1-2 s per fit where an interval is profiled.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable

import numpy as np

from idtool._diagnostic import Diagnostic
from idtool._fit._free_levels import model_log_levels
from idtool._fit._level_design import level_design
from idtool._fit._result import Z95, Z_AT_BOUND, Estimate, one_sided
from idtool._fit._variability import SD_PARAMS, Variability, _gls_form
from idtool._model._benchmodel import BenchModel

__all__ = [
    "check_level_intervals",
    "level_criterion",
    "profile_ends",
    "profile_side",
    "refit_others",
]

_CHI2_95 = 3.84  # -2 log L rise at the ends of a 95% interval, one parameter
# Where the Wald interval is checked, in half-widths from the estimate: a quadratic
# rises by 3.84 m^2 at m of them. A rise below half that at any of them says the
# likelihood is flatter than the interval assumes (another basin or a plateau beyond):
# on the transverse benches 0.45-4.2 at 1.5 half-widths and 1.9-5.7 at 2, where the
# along and normal benches' profiles are quadratic.
_PROBES = (1.0, 1.5, 2.0)
_FLATTER = 0.5
# The profile walk: steps of half a Wald standard error (internal scale), up to
# _FINE_STEPS of them (12 se: the basins above are 2-5 se apart), stopping early once
# the rise above the side's minimum exceeds _CAP (the chi-square's 99.9% point: a basin
# beyond a barrier that high is not searched); then, while still within 3.84 of the
# minimum (a plateau: Kt's Coulomb limit), doubling steps towards the bound.
_FINE_STEP = 0.5
_FINE_STEPS = 24
_CAP = 10.83
_GN_STEPS = 30  # Gauss-Newton iterations of a refit (2-6 taken on the direction benches)
_GN_TOL = 1e-6  # a refit stops once its decrement, in units of -2 log L, is below this

# theta (internal) -> (r^T C^-1 r, r^T C^-1 G, G^T C^-1 G): level_criterion
Criterion = Callable[[np.ndarray], tuple[float, np.ndarray, np.ndarray]]


def level_criterion(model: BenchModel, z: np.ndarray, state, v: Variability) -> Criterion:
    """The levels model's ``-2 log L`` (up to a constant: the sds held at their REML
    values, so only the quadratic form ``r^T C^-1 r`` moves) as a function of the
    physical parameters ``theta`` (internal scale; the bench parameters at ``z``'s).
    Returns ``theta -> (r^T C^-1 r, r^T C^-1 G, G^T C^-1 G)``, ``r`` the residuals of
    the free log levels and ``G`` the model's Jacobian there."""
    k = model.n_physical
    assert v.free.cov_parts is not None  # a fresh free_levels'
    design = level_design(model, v.free.measured)
    parts = dataclasses.replace(v.free.cov_parts, disc=design.disc_root)
    tau2 = np.array([v.sds[p.name][0] ** 2 if p.name in v.sds else 0.0 for p in SD_PARAMS])
    form = _gls_form(parts, tau2 * design.active)
    rest = np.asarray(z, float)[k:]

    def criterion(theta: np.ndarray):
        with np.errstate(divide="ignore", invalid="ignore"):  # a level at zero: inf
            g, jac = model_log_levels(model, np.concatenate([theta, rest]), state)
        r, jr = v.free.y - g[design.rows], jac[design.rows]
        if not (np.all(np.isfinite(r)) and np.all(np.isfinite(jr))):
            return np.inf, np.zeros(k), np.eye(k)
        # one solve gives all three: [r, G]^T C^-1 [r, G]
        full = form(r, np.column_stack([r, jr]))[1]
        return float(full[0, 0]), full[0, 1:], full[1:, 1:]

    return criterion


def refit_others(criterion: Criterion, theta: np.ndarray, i: int) -> tuple[float, np.ndarray]:
    """Gauss-Newton on every physical parameter but ``i`` (held at ``theta[i]``), each
    step halved until ``-2 log L`` does not rise; returns its value and the refitted
    ``theta`` (internal scale)."""
    free = np.arange(theta.size) != i
    theta = np.array(theta, float)
    q, rg, gg = criterion(theta)
    for _ in range(_GN_STEPS):
        step = np.zeros_like(theta)
        # least squares: a parameter run to its bound has no column (singular G^T C^-1 G)
        step[free] = np.linalg.lstsq(gg[np.ix_(free, free)], rg[free], rcond=None)[0]
        if not float(rg[free] @ step[free]) > _GN_TOL:
            break
        for _ in range(30):
            trial = criterion(theta + step)
            if trial[0] <= q:
                theta, (q, rg, gg) = theta + step, trial
                break
            step = 0.5 * step
        else:
            break
    return q, theta


def profile_side(
    criterion: Criterion, theta: np.ndarray, i: int, side: float, se_z: float, q0: float
) -> tuple[np.ndarray, np.ndarray]:
    """The profile of parameter ``i`` walked from ``theta`` towards ``side`` (+1, -1):
    internal values and their rise of ``-2 log L`` over ``q0``, the estimate's, each
    refit starting from the previous one (module docstring for the steps). The last
    point is at the bound where the profile never leaves the 95% region."""
    zs, rises = [float(theta[i])], [0.0]
    warm = np.array(theta, float)
    step, n = _FINE_STEP * se_z, 0
    while side * zs[-1] < Z_AT_BOUND:
        n += 1
        if n > _FINE_STEPS:
            if rises[-1] - min(rises) >= _CHI2_95:
                break
            step *= 2.0
        elif rises[-1] - min(rises) >= _CAP:
            break
        warm[i] = side * min(side * zs[-1] + step, Z_AT_BOUND)
        q, warm = refit_others(criterion, warm, i)
        zs.append(float(warm[i]))
        rises.append(q - q0)
    return np.array(zs), np.array(rises)


def profile_ends(zs: np.ndarray, rises: np.ndarray) -> tuple[float, float]:
    """The 95% profile interval (internal scale) from profile points ``zs`` (ascending)
    and their rises: the outermost crossings of 3.84 above the minimum (linear
    interpolation), so that it spans every basin within 3.84; an end that never
    crosses is the last point (at the bound: the side is open)."""
    inside = np.flatnonzero(rises - rises.min() < _CHI2_95)
    lo_j, hi_j = int(inside[0]), int(inside[-1])
    level = rises.min() + _CHI2_95
    lo = float(zs[lo_j])
    if lo_j > 0:
        lo = float(np.interp(level, [rises[lo_j], rises[lo_j - 1]], [zs[lo_j], zs[lo_j - 1]]))
    hi = float(zs[hi_j])
    if hi_j < zs.size - 1:
        hi = float(np.interp(level, [rises[hi_j], rises[hi_j + 1]], [zs[hi_j], zs[hi_j + 1]]))
    return lo, hi


def _too_narrow(criterion: Criterion, theta: np.ndarray, i: int, se_z: float, q0: float):
    """The rises at the Wald ends (both sides), and whether the Wald interval is too
    narrow: a rise below :data:`_FLATTER` times the quadratic's at any of
    :data:`_PROBES` on either side."""
    ends, narrow = [], False
    for side in (-1.0, 1.0):
        for mult in _PROBES:
            zi = float(theta[i]) + side * mult * Z95 * se_z
            if abs(zi) >= Z_AT_BOUND:  # the range's end, no information beyond
                rise = np.inf
            else:
                trial = np.array(theta, float)
                trial[i] = zi
                rise = refit_others(criterion, trial, i)[0] - q0
            if mult == 1.0:
                ends.append(rise)
            narrow |= rise < _FLATTER * _CHI2_95 * mult**2
    return ends, narrow


def check_level_intervals(
    model: BenchModel,
    state,
    v: Variability,
    z: np.ndarray,
    se_z: np.ndarray,
    estimates: dict[str, Estimate],
) -> tuple[dict[str, Estimate], list[Diagnostic]]:
    """``estimates`` (the levels model's, at internal ``z`` with Wald standard errors
    ``se_z`` of the physical parameters) with each physical parameter's interval checked
    against the levels model's likelihood (module docstring), widened to its union with
    the profile's where too narrow; a warning per parameter widened."""
    criterion = level_criterion(model, z, state, v)
    theta = np.asarray(z, float)[: model.n_physical]
    q0 = criterion(theta)[0]
    out, warnings = dict(estimates), []
    for i, spec in enumerate(model.shared_params[: model.n_physical]):
        est = estimates[spec.name]
        if not spec.bounded or est.at_bound or not se_z[i] > 0.0:
            continue
        rises, narrow = _too_narrow(criterion, theta, i, float(se_z[i]), q0)
        if not narrow:
            continue
        down = profile_side(criterion, theta, i, -1.0, float(se_z[i]), q0)
        up = profile_side(criterion, theta, i, 1.0, float(se_z[i]), q0)
        zs = np.concatenate([down[0][:0:-1], up[0]])
        d = np.concatenate([down[1][:0:-1], up[1]])
        p_lo, p_hi = profile_ends(zs, d)
        # Widened, never narrowed: the union with the Wald interval. Where the profile
        # rises faster than the quadratic its end is not taken: with the sds held at
        # their REML values the profile can be overconfident under misfit (departure
        # "ceiling", seed 903: the profile's [5.3e9, 9.8e12] N/m excluded the truth
        # 1.06e9 that the Wald [7.8e5, 3.2e12] held)
        half = Z95 * float(se_z[i])
        z_lo, z_hi = min(p_lo, theta[i] - half), max(p_hi, theta[i] + half)
        lo, hi = float(spec.value(z_lo)), float(spec.value(z_hi))
        prof = (float(spec.value(p_lo)), float(spec.value(p_hi)))
        out[spec.name] = dataclasses.replace(est, ci95=(lo, hi), one_sided=one_sided(z_lo, z_hi))
        best = float(spec.value(float(zs[int(np.argmin(d))])))
        better = (
            f"; the profile's best point, {best:.4g} {spec.unit}, beats the estimate by "
            f"{-d.min():.2f}"
            if d.min() < -0.1
            else ""
        )
        warnings.append(
            Diagnostic(
                "profile_interval",
                f"{spec.name}: the levels model's Gauss-Newton 95% interval "
                f"[{est.ci95[0]:.4g}, {est.ci95[1]:.4g}] {spec.unit} is too narrow: "
                f"refitting the others there, -2 log L rises only {rises[0]:.2f} and "
                f"{rises[1]:.2f} (3.84 expected), and its profile is not quadratic"
                f"{better}; reported instead: [{lo:.4g}, {hi:.4g}], the union of that "
                f"interval and the profile likelihood's [{prof[0]:.4g}, {prof[1]:.4g}]. "
                "The data barely inform it",
                parameter=spec.name,
                wald_ci95=est.ci95,
                profile_ci95=prof,
                ci95=(lo, hi),
            )
        )
    return out, warnings
