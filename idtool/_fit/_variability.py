"""Pull-to-pull scatter and model discrepancy: the hierarchical model of the levels (issue 10).

A real bench does not repeat itself: two pulls at the same load and amplitude give
friction ratios a few percent apart (webbing wear and position, horn heating), their OFF
levels differ by ~1% in mu, and the physical model's curve cannot pass exactly through
every operating point (its coupling law has a shape; the bench's has another). A fit that
knows only the load cell's noise then reports bands of +-0.001 around a curve that is
0.03 off. This module adds the missing variance, nested so that zero gives today's model:

    log OFF_i = log F_off(theta; N_i)        + a_i          a_i ~ N(0, scatter_mu^2)
    log FR_i  = log FR(theta; x_i) + d(x_i) + c_i           c_i ~ N(0, scatter_fr^2)
    d ~ GP(0, discrepancy_fr^2 rho)                 (x = (ln N, alpha, ln v), rho smooth)

(log scale: each sd is a relative one; ``FR x sd`` in FR units). ``a`` and ``c`` are
per trace (pull), ``d`` a smooth function of the operating point
(:mod:`idtool._fit._discrepancy`: traces at one operating point share it, neighbouring
points are correlated, and predictions condition it on the data). With a single trace
per operating point ``c`` and ``d`` cannot be told apart: their sum is estimated as
``discrepancy_fr`` and the report says so.

Estimation, in two stages (a Laplace approximation of the marginal likelihood):

1. **Free levels** (:func:`~idtool._fit._free_levels.free_levels`): every trace's OFF
   and ON levels fitted freely, with the bench nuisances, on the fit's own block means:
   estimates ``y`` (log OFF, log FR) and covariance ``V`` (:mod:`idtool._fit._free_levels`).
2. **Levels model**: ``y ~ N(g(theta), V + Sigma(sds))`` with ``g`` the physical model's
   log levels. The sds are estimated by restricted maximum likelihood (REML: the
   physical parameters profiled on the linearised model, so that fitting k parameters
   to a few operating points does not bias the discrepancy low, as plain ML would), with
   optimistix's BFGS on the log sds, alternated with Gauss-Newton steps in theta.
   Each sd's uncertainty is its REML likelihood on a grid (the others at their
   estimates) times a spike-and-slab prior: probability 1/2 that the sd is zero (the
   physical model exact, no scatter), else half-normal with scale
   :data:`SD_SLAB_SCALE` (10%, the sampler's prior). Its 95% interval and the draws that
   predictions integrate over come from this posterior, so a discrepancy seen at four
   operating points widens the bands by what four points can tell, while on data that
   show none the evidence for "none" (Bayes's Occam factor: the slab spreads its prior
   over sds the data cannot tell from zero) keeps the bands close to the noise-only
   ones (a flat prior on the sd made them 1.75x as wide on clean simulated data).

Lack of fit: at zero sds, ``chi2 = r^T V^-1 r`` of the free levels against the model's
curve has ``n - k`` degrees of freedom if the physical model and the noise explain the
traces; a small p-value is reported as a warning.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from idtool._diagnostic import Diagnostic
from idtool._fit._free_levels import MIN_AT_LEVEL_S, FreeLevels, free_levels, model_log_levels
from idtool._fit._level_cov import LevelCovariance, factor, solve, to_pairs
from idtool._fit._level_design import level_design
from idtool._fit._reml import GRID, at_sds, evaluate, fit_sds
from idtool._model._benchmodel import BenchModel
from idtool._model._params import Param

__all__ = [
    "MISFIT",
    "SD_PARAMS",
    "ThetaGivenSds",
    "Variability",
    "estimate_variability",
    "theta_covariance",
]

SD_PARAMS = (
    Param(
        "scatter_mu",
        "1",
        "log",
        1e-6,
        2.0,
        description="pull-to-pull sd of the OFF level (relative)",
    ),
    Param(
        "scatter_fr",
        "1",
        "log",
        1e-6,
        2.0,
        description="pull-to-pull sd of the friction ratio (relative)",
    ),
    Param(
        "discrepancy_fr",
        "1",
        "log",
        1e-6,
        2.0,
        description="operating-point sd of the friction ratio about the physical model "
        "(relative): what the model's curve misses",
    ),
)
# A discrepancy whose 95% interval starts above this (3% of the friction ratio) says the
# physical model is misspecified: on the coverage benches it does so on 6 of the 6
# whose coupling has a shape the fit does not ship (lower ends 0.04-0.08) and on none
# of the 15 others (at most 0.016, a scatter bench with one trace per operating point).
MISSPECIFIED_SD = 0.03
# How every warning that the physical model misses the data begins (the report shows
# them as banners)
MISFIT = "the physical model misses"
SD_SLAB_SCALE = 0.1  # half-normal scale of an sd's prior when it is not zero
SD_PRIOR_ZERO = 0.5  # prior probability that an sd is zero


@dataclasses.dataclass(frozen=True)
class Variability:
    """Scatter and discrepancy sds of a fit (module docstring) and the levels model's
    estimate of the physical parameters.

    ``sds`` maps each of :data:`SD_PARAMS` to (estimate, ci95 low, ci95 high); ``grids``
    each to its posterior on a grid ``(sd values, probabilities)``: REML likelihood times
    the spike-and-slab prior (module docstring).
    """

    free: FreeLevels
    sds: dict[str, tuple[float, float, float]]
    grids: dict[str, tuple[np.ndarray, np.ndarray]]
    separable: bool
    theta: np.ndarray
    cov_theta: np.ndarray
    chi2: float
    dof: int
    p_value: float
    loglik: float
    loglik_without: float  # at zero sds
    warnings: tuple[str, ...]
    notes: tuple[str, ...] = ()  # facts about the data for the report, not doubts
    # G = d g / d theta at ``theta`` in the rows of ``free.y`` (n, k): with ``free``'s
    # covariance and the design's discrepancy, the physical parameters' covariance at any
    # sds (:class:`ThetaGivenSds`), what predictions draw them from
    jacobian: np.ndarray | None = None

    def summary(self) -> str:
        """One line per sd, in relative terms, for reports."""
        lines = []
        for p in SD_PARAMS:
            if p.name not in self.sds:
                continue
            est, lo, hi = self.sds[p.name]
            lines.append(
                f"{p.name:15s} {100 * est:6.2f}%  (95% {100 * lo:.2f}-{100 * hi:.2f}%)  "
                f"{p.description}"
            )
        return "\n".join(lines)


class NoMeasuredLevels(ValueError):
    """No trace measures its own friction ratio: the levels model has nothing to fit."""


def _spike_and_slab(grid: np.ndarray, likelihood: np.ndarray) -> np.ndarray:
    """Posterior probabilities over ``grid`` (sd values from 0, evenly spaced) from the
    likelihood there (relative) under the spike-and-slab prior (module docstring): the
    slab's mass on each grid cell, and the spike's at ``grid[0] = 0``."""
    slab = np.exp(-0.5 * (grid / SD_SLAB_SCALE) ** 2)
    slab *= math.sqrt(2.0 / math.pi) / SD_SLAB_SCALE * (grid[1] - grid[0])  # mass per cell
    w = (1.0 - SD_PRIOR_ZERO) * likelihood * slab
    w[0] += SD_PRIOR_ZERO * likelihood[0]
    return w / w.sum()


def _gls_form(parts: LevelCovariance, tau2: np.ndarray):
    """``(res, cols) -> (res^T C^-1 res, cols^T C^-1 cols)`` at the variances ``tau2``
    (rows of the levels model; ``C`` in blocks, :mod:`idtool._fit._level_cov`)."""
    f = factor(np.asarray(tau2, float), *parts.arrays)
    meas = parts.measured.astype(bool)

    def form(res: np.ndarray, cols: np.ndarray | None = None):
        rp = to_pairs(np.asarray(res, float), meas)
        quad = float(np.sum(rp * solve(f, rp[:, :, None])[:, :, 0]))
        if cols is None:
            return quad, None
        gp = to_pairs(np.asarray(cols, float), meas)
        return quad, np.einsum("mik,mil->kl", gp, solve(f, gp))

    return form


def theta_covariance(parts: LevelCovariance, jacobian: np.ndarray, tau2) -> np.ndarray:
    """The physical parameters' covariance (k, k), internal scale, on the linearised
    levels model at the variances ``tau2`` (3,) of (scatter_mu, scatter_fr,
    discrepancy_fr): ``Sigma(sds) = (G^T C(sds)^-1 G)^-1`` (the generalised least-squares
    estimate's, module docstring), ``G`` the ``jacobian`` (n, k) in the levels model's
    rows, ``C = V + Sigma(sds)`` in blocks (``parts`` with the discrepancy's root,
    :mod:`idtool._fit._level_cov`). At the REML ``tau2`` it is the fit's
    :attr:`Variability.cov_theta`, by construction (one function computes both)."""
    jacobian = np.asarray(jacobian, float)
    info = _gls_form(parts, tau2)(np.zeros(jacobian.shape[0]), jacobian)[1]
    return np.linalg.inv(info)


@dataclasses.dataclass(frozen=True)
class ThetaGivenSds:
    """The physical parameters' covariance given the sds (:func:`theta_covariance`), for
    predictions that draw the sds: conditionally on them, theta ~ N(theta_hat,
    Sigma(sds)). ``parts``: ``V`` in blocks with the discrepancy's root; ``jacobian``
    ``G`` (n, k); ``tau2`` (3,) the REML variances, what an sd not drawn keeps."""

    parts: LevelCovariance
    jacobian: np.ndarray
    tau2: np.ndarray

    def at(self, sds: dict[str, float]) -> np.ndarray:
        """``Sigma`` (k, k) at the sds ``sds`` (name -> relative sd; the others at their
        REML estimates: zero for one the data cannot inform)."""
        tau2 = np.array(self.tau2, float)
        for j, p in enumerate(SD_PARAMS):
            if p.name in sds:
                tau2[j] = float(sds[p.name]) ** 2
        try:
            return theta_covariance(self.parts, self.jacobian, tau2)
        except np.linalg.LinAlgError:
            # A direction the levels do not inform (a coupling law with a parameter the
            # data cannot place: the fit warns; on the small bench the load-power law's
            # information had eigenvalues 6e-10 to 1.4e7) is singular at some sds to
            # round-off: as predictions treat a degenerate covariance, no spread there.
            info = _gls_form(self.parts, tau2)(np.zeros(self.jacobian.shape[0]), self.jacobian)[1]
            return np.linalg.pinv(0.5 * (info + info.T), hermitian=True)


def _line_search(model, z, state, y, rows, form, theta, step, r, at_theta):
    """``theta`` moved along the Gauss-Newton ``step``, halved until the generalised
    residual sum of squares ``r' C^-1 r`` does not rise (at most 30 halvings: then no
    move); returns the new ``theta``, the step taken and the model's log levels and
    their Jacobian there (``at_theta``, those at ``theta``, when it does not move), so
    the next iteration need not evaluate them again. Where the levels barely inform a
    direction (the sdof law's Kt, gain and R on two amplitudes) the full step ran into
    a bound, where the Jacobian loses its column and the covariance is singular; on a
    well-posed fit the full step is taken, as before."""
    k = theta.size

    def gls(res):
        return form(res)[0]

    before = gls(r)
    for _ in range(31):
        trial = theta + step
        with np.errstate(divide="ignore", invalid="ignore"):  # a level at zero: rejected
            levels = model_log_levels(model, np.concatenate([trial, z[k:]]), state)
        g_all = levels[0]
        if np.all(np.isfinite(g_all)) and gls(y - g_all[rows]) <= before * (1.0 + 1e-12):
            return trial, step, levels
        step = 0.5 * step
    return theta, np.zeros_like(step), at_theta


def estimate_variability(
    model: BenchModel, z: np.ndarray, state, free: FreeLevels | None = None
) -> Variability:
    """Stages 1 and 2 (module docstring) from a converged fit's ``z`` and noise
    ``state`` (its noise model's correlation state; AR(1): ``[phi]``). ``free``: the
    traces' free levels to fit (another fit's of the same traces, so that models are
    compared on the same data, :mod:`idtool._fit._choice_levels`); by default this
    fit's own."""
    k = model.n_physical
    if free is None:
        free = free_levels(model, np.asarray(z), state)
    design = level_design(model, free.measured)
    if not design.active[2]:
        raise NoMeasuredLevels("no trace's ON window is long enough to measure its ON level")
    rows, separable = design.rows, design.separable
    mask = design.active.astype(float)
    meas = free.measured
    assert free.cov_parts is not None  # a fresh free_levels'
    parts = dataclasses.replace(free.cov_parts, disc=design.disc_root)
    # NumPy arrays throughout: the jitted programs take them as they are, and the host's
    # own arithmetic on them dispatches no eager JAX operations (:mod:`idtool._model._xp`)
    args = parts.arrays
    z = np.asarray(z, float)
    theta = z[:k].copy()
    s = np.log(np.full(3, 0.01))
    levels = model_log_levels(model, np.concatenate([theta, z[k:]]), state)
    for _ in range(12):
        g_all, jac_all = levels
        r, g = free.y - g_all[rows], jac_all[rows]
        r2, g2 = to_pairs(r, meas), to_pairs(g, meas)
        s = np.asarray(fit_sds(s, mask, r2, g2, *args))
        s = np.clip(s, math.log(1e-6), math.log(2.0))
        tau2 = mask * np.exp(2.0 * s)
        _, step = at_sds(tau2, r2, g2, args)
        form = _gls_form(parts, tau2)
        theta, step, levels = _line_search(
            model, z, state, free.y, rows, form, theta, step, r, levels
        )
        cov = np.linalg.inv(form(r, g)[1])
        if not np.all(np.diag(cov) > 0.0):
            raise np.linalg.LinAlgError("they do not inform every physical parameter")
        if np.max(np.abs(step) / np.sqrt(np.diag(cov))) < 1e-3:
            break
    g_all, jac_all = levels  # at theta
    r, g = free.y - g_all[rows], jac_all[rows]
    r2, g2 = to_pairs(r, meas), to_pairs(g, meas)
    cov_theta = theta_covariance(parts, g, tau2)
    if not (np.all(np.isfinite(cov_theta)) and np.all(np.diag(cov_theta) > 0.0)):
        raise np.linalg.LinAlgError("they do not inform every physical parameter")
    nll, _ = at_sds(tau2, r2, g2, args)
    nll0, step0 = at_sds(np.zeros(3), r2, g2, args)
    if not (np.isfinite(nll) and np.isfinite(nll0)):
        # a fit whose levels' covariance is not positive definite (on a fading-horn bench
        # the grid's likelihood was NaN everywhere and the predictions' sd draws failed)
        raise np.linalg.LinAlgError("their likelihood is not finite")
    n = r.size
    const = 0.5 * n * math.log(2 * math.pi)

    # lack of fit at zero sds: the free levels against the model's best curve
    r0 = r - g @ step0
    chi2 = free.cov_parts.quad(r0)  # r0' V^-1 r0
    dof = int(n - k)
    # here, not at the top: 0.15-0.25 s of import for one call, which `idtool fit`
    # makes in the background while XLA runs (idtool._cli._fit, LATE_IMPORTS)
    import scipy.special

    p_value = float(scipy.special.gammaincc(dof / 2.0, chi2 / 2.0)) if dof > 0 else 1.0

    sds, grids = {}, {}
    for j, p in enumerate(SD_PARAMS):
        if mask[j] == 0.0:
            continue
        est = math.sqrt(tau2[j])
        # wide enough that the likelihood has fallen off (< 1e-3 of its peak) at the
        # end: the slab's evidence integrates over it
        top = max(5.0 * est, 0.03)
        for _ in range(4):
            grid = np.linspace(0.0, top, GRID)
            t2 = np.tile(tau2, (GRID, 1))
            t2[:, j] = grid**2
            nl = np.asarray(evaluate(t2, r2, g2, *args, True)[0])
            # a grid point whose covariance is not positive definite has no likelihood
            nl = np.where(np.isfinite(nl), nl, np.inf)
            if not np.isfinite(nl.min()):
                raise np.linalg.LinAlgError(f"their likelihood is not finite along {p.name}")
            if nl[-1] - nl.min() > math.log(1e3):
                break
            top *= 2.0
        w = _spike_and_slab(grid, np.exp(-(nl - nl.min())))
        cdf = np.cumsum(w)
        lo = float(grid[np.searchsorted(cdf, 0.025)])
        hi = float(grid[min(int(np.searchsorted(cdf, 0.975)), GRID - 1)])
        sds[p.name] = (est, min(lo, est), max(hi, est))
        grids[p.name] = (grid, w)

    warnings = []
    if p_value < 0.01:
        warnings.append(
            Diagnostic(
                "misfit_levels",
                f"{MISFIT} the traces' own levels by more than their noise "
                f"explains (chi2 = {chi2:.1f} on {dof} degrees of freedom, p = "
                f"{p_value:.2g}): pull-to-pull scatter or model discrepancy; both are in "
                "the bands",
                chi2=chi2,
                dof=dof,
                p_value=p_value,
            )
        )
    disc = sds.get("discrepancy_fr")
    if disc is not None and disc[1] > MISSPECIFIED_SD:
        warnings.append(
            Diagnostic(
                "misfit_operating_points",
                f"{MISFIT} the operating points by {100 * disc[0]:.0f}% in "
                f"friction ratio (discrepancy sd, 95% interval {100 * disc[1]:.0f}-"
                f"{100 * disc[2]:.0f}%): the bands carry it, but Kt and the coupling "
                "parameters are read through the coupling law's shape (Lambda = Kt a / "
                "(mu N)) and their intervals assume it is right; on simulated benches "
                "whose coupling had another shape Kt came out 0.13-0.42x its truth under "
                "the power limit, outside its interval. Compare the laws (--coupling "
                "auto), and treat Kt as depending on the coupling law",
                discrepancy_sd=disc,
            )
        )
    # What the design lets the levels model measure: facts of the data, not doubts about
    # the fit (a short ON window is the bench's design, the OFF level still counts).
    notes = []
    if not separable:
        notes.append(
            "one trace per operating point: pull-to-pull scatter and model discrepancy "
            "cannot be told apart; discrepancy_fr is their sum"
        )
    unmeasured = int(np.count_nonzero(~free.measured))
    if unmeasured:
        notes.append(
            f"{unmeasured} trace(s) switch the horn off before the force settles at its ON "
            f"level (< {MIN_AT_LEVEL_S} s at level): their friction ratio is not measured "
            "on its own and enters the levels model through the OFF level only"
        )
    return Variability(
        free=free,
        sds=sds,
        grids=grids,
        separable=separable,
        theta=theta,
        cov_theta=cov_theta,
        chi2=chi2,
        dof=dof,
        p_value=p_value,
        loglik=-float(nll) - const,
        loglik_without=-float(nll0) - const,
        warnings=tuple(warnings),
        notes=tuple(notes),
        jacobian=g,
    )
