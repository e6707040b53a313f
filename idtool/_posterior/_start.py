"""Where the walkers start (issue 5): the posterior mode, checked for a better one.

1. The noise parameters start from the fit's residuals (sigma from the whitened
   residuals, the correlation state (AR(1): phi) from the fit's, nu = 10), with their
   asymptotic standard errors.
2. The log-posterior is maximised (optimistix's BFGS on its JAX gradient) from the fit's optimum
   and from each other optimum of the fit's multi-start with a residual sum of squares
   within ``RSS_FACTOR`` of the best. A fit can stop in a local
   optimum (its multi-start ranks basins with the nuisances at their start values):
   on the small two-load designs of tests/test_sample.py it does for 2 seeds in 10,
   with a log-posterior 16 lower than the global mode and a friction ratio at 450 N off
   by 0.05. If another start reaches a log-posterior higher by more than
   ``MODE_MARGIN``, the walkers start there, the nuisances are re-linearised at that
   mode, and a warning says the fit should be redone.
3. Walkers: a multivariate normal around the mode with the fit's covariance (the shared
   block of ``cov_z``; the noise parameters' asymptotic errors), brought inside the
   bounded parameters' ranges (:func:`start_within`). The log-posterior must be finite
   at the mode and at every walker (walkers outside the support are redrawn).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx

from idtool._diagnostic import Diagnostic
from idtool._errors import IdtoolError
from idtool._fit._folder import FIT_JSON
from idtool._fit._result import Z_AT_BOUND
from idtool._model._params import Param
from idtool._posterior._likelihood import (
    Target,
    log_posterior,
    marginal_loglik,
    physical_values,
    predict_blocks,
)

__all__ = [
    "MAX_START_SD_Z",
    "MODE_MARGIN",
    "Start",
    "find_start",
    "initial_walkers",
    "start_within",
]

MODE_MARGIN = 3.0  # log-posterior units: e^3 = 20 times more probable
# The walkers' largest spread on a bounded parameter's internal scale (start_within): a
# unit there is a quarter of its range's logarithm near the middle (2.2 decades of Kt),
# wide enough that the ensemble finds the posterior's extent itself within its burn-in.
MAX_START_SD_Z = 0.5
RSS_FACTOR = 2.0  # other multi-start optima polished: RSS within this factor of the best


_predict = jax.jit(predict_blocks)


@dataclasses.dataclass(frozen=True)
class Start:
    """The centre and spread of the walkers, and the target they sample."""

    theta: np.ndarray  # internal, at the mode
    cov: np.ndarray
    log_posterior: float
    z_lin: np.ndarray  # full FitModel vector: where the nuisances are linearised
    target: Target
    modes: tuple[tuple[str, float], ...]  # every polished start: (label, log-posterior)
    warnings: tuple[str, ...]


def _noise_start(fit: Any, target: Target) -> tuple[list[float], list[float]]:
    """Start values of the noise parameters and their sds (physical units)."""
    k = fit.model.n_shared
    shared = {p.name: jnp.asarray(p.value(fit.z[i])) for i, p in enumerate(target.params[:k])}
    e = np.asarray(_predict(shared, target) - target.force_n)
    n = e.size
    noise = target.model.noise
    # the fit's state by name (the sampler's noise model may be another one)
    state = noise.state_from_names(fit.model.noise.state_by_name(fit.noise_state))
    state_sd = noise.state_sd(state, n)
    w = np.asarray(noise.whiten(jnp.asarray(e), target.first, state))
    sigma = float(np.sqrt(np.mean(w**2)))
    start, sd = [], []
    for p in target.params[k:]:
        if p.name == "sigma_n":
            scale = 1.0 if noise.gaussian else 0.8  # a t scale is below the sd
            start.append(scale * sigma)
            sd.append(scale * sigma / np.sqrt(2.0 * n))
        elif p in noise.state_params:
            j = noise.state_params.index(p)
            start.append(float(state[j]))
            sd.append(float(state_sd[j]))
        else:  # nu
            start.append(10.0)
            sd.append(3.0)
    return start, sd


@jax.jit
def _maximise(theta, target):
    """The log-posterior's maximum from ``theta`` and its value there, and the value at
    ``theta``: optimistix's BFGS on its JAX gradient (a point outside the prior's
    support has log-posterior -inf: the backtracking line search rejects it like any
    other uphill step; a start there stays where it is). One program for the check and
    the climb: a separate value-and-gradient program for the start's check compiled the
    log-posterior's gradient a second time (2.6-3.8 s on two busy cores, per sample)."""

    def loss(th, tg):
        return -log_posterior(th, tg)

    start = -loss(theta, target)

    def climb(th):
        sol: optx.Solution = optx.minimise(
            loss, optx.BFGS(rtol=1e-10, atol=1e-8), th, target, max_steps=500, throw=False
        )
        return sol.value, -loss(sol.value, target)

    mode, value = jax.lax.cond(jnp.isfinite(start), climb, lambda th: (th, start), theta)
    return mode, value, start


def _polish(theta: np.ndarray, target: Target) -> tuple[np.ndarray, float, float]:
    """The mode reached from ``theta`` (:func:`_maximise`), its log-posterior, and the
    log-posterior at ``theta``; a start outside the support stays where it is, at
    -inf."""
    mode, value, start = _maximise(jnp.asarray(theta), target)
    return np.asarray(mode), float(value), float(start)


def _other_optima(fit: Any) -> list[tuple[str, np.ndarray]]:
    """The physical block (internal) of the fit's other multi-start optima whose
    residual sum of squares is within ``RSS_FACTOR`` of the best one's: a fit stopped
    short (a step budget, a stored fit from an older run) may sit in a local optimum,
    and the posterior's main mode is then reached from one of those."""
    optima = [(o["rss"], np.asarray(o["z"])) for o in fit.optima]
    if not optima:
        return []
    best = min(rss for rss, _ in optima)
    return [
        (f"multi-start optimum {j}", zp)
        for j, (rss, zp) in enumerate(optima[1:], 2)
        if rss <= RSS_FACTOR * best
    ]


def find_start(fit: Any, target: Target, rebuild: Callable[[np.ndarray], Target]) -> Start:
    """The walkers' centre: the best posterior mode reached from the fit's optima."""
    k = fit.model.n_shared
    params = target.params
    noise0, noise_sd = _noise_start(fit, target)
    noise_z = [p.internal(x) for p, x in zip(params[k:], noise0, strict=True)]
    theta_fit = np.concatenate([fit.z[:k], noise_z])
    best_theta, best_lp, fit_start = _polish(theta_fit, target)
    if not np.isfinite(fit_start):
        outside = [
            f"{p.name} = {float(p.value(jnp.asarray(c))):.4g} ({prior.describe()})"
            for p, prior, c in zip(params, target.priors, theta_fit, strict=True)
            if not np.isfinite(float(prior.logpdf(p.value(jnp.asarray(c)))))
        ]
        why = "; outside the prior: " + ", ".join(outside) if outside else ""
        raise IdtoolError(f"the log-posterior is not finite at the fit's optimum{why}")
    fit_lp = best_lp
    modes = [("fit optimum", best_lp)]
    best_label = "fit optimum"
    for label, zp in _other_optima(fit):
        theta = theta_fit.copy()
        theta[: zp.size] = zp
        th, lp, _ = _polish(theta, target)
        modes.append((label, lp))
        if lp > best_lp:
            best_theta, best_lp, best_label = th, lp, label
    warnings: list[str] = []
    z_lin = np.asarray(fit.z, float).copy()
    if best_lp > fit_lp + MODE_MARGIN:
        v = physical_values(jnp.asarray(best_theta), target)
        e = predict_blocks(v, target) - target.force_n
        shift = np.asarray(marginal_loglik(e, v, target)[1])
        z_lin[:k] = best_theta[:k]
        n = fit.model.data.n_traces
        for j in range(len(fit.model.trace_groups)):
            z_lin[k + j * n : k + (j + 1) * n] += shift[:, j]
        target = rebuild(z_lin)
        best_theta, best_lp, _ = _polish(best_theta, target)
        names = ", ".join(
            f"{p.name} = {float(p.value(jnp.asarray(best_theta[i]))):.4g}"
            for i, p in enumerate(params[: fit.model.n_physical])
        )
        warnings.append(
            Diagnostic(
                "sampler_start",
                f"the fit stopped in a local optimum: from its {best_label} the "
                f"log-posterior rises {best_lp - fit_lp:.1f} higher ({names}); the walkers "
                "start there. Redo the fit (other --seed or more --starts) before trusting "
                f"{FIT_JSON.name}",
                log_posterior_rise=float(best_lp - fit_lp),
            )
        )
    noise = zip(params[k:], noise_sd, best_theta[k:], strict=True)
    sd_z = [s / p.slope(c) for p, s, c in noise]
    cov = np.zeros((len(params), len(params)))
    cov[:k, :k] = fit.cov_z.leading(k)
    cov[k:, k:] = np.diag(np.square(sd_z))
    return Start(best_theta, cov, best_lp, z_lin, target, tuple(modes), tuple(warnings))


def start_within(
    theta: np.ndarray, cov: np.ndarray, params: tuple[Param, ...]
) -> tuple[np.ndarray, np.ndarray]:
    """The walkers' centre and covariance (internal scale) brought inside the bounded
    parameters' ranges: the centre to within :data:`Z_AT_BOUND` of the middle, the
    spread to at most :data:`MAX_START_SD_Z` (the covariance's rows and columns scaled,
    its correlations kept).

    A fit that leaves a parameter at a bound of its range (Kt at 1e4 N/m, the creep
    limit, on a bench whose coupling law the fit does not ship) has its internal value
    far beyond it (-30) and a Gauss-Newton variance there of 1e19, since the transform is
    flat: walkers drawn from it started at internal Kt -7e9, log-posterior -7e9, and the
    whole default run (44,000 steps, 10 minutes) was the ensemble crawling in from there,
    its differential-evolution steps throwing every other parameter to its bounds on the
    way (tau 968, never converged). The posterior itself is inside the range: where the
    data do not bound a parameter the prior does (:mod:`idtool._posterior._prior`)."""
    theta = np.array(theta, float)
    scale = np.ones(theta.size)
    for i, p in enumerate(params):
        if p.bounded:
            theta[i] = float(np.clip(theta[i], -Z_AT_BOUND, Z_AT_BOUND))
            sd = float(np.sqrt(max(cov[i, i], 0.0)))
            if sd > MAX_START_SD_Z:
                scale[i] = MAX_START_SD_Z / sd
    return theta, np.asarray(cov, float) * np.outer(scale, scale)


def initial_walkers(
    theta: np.ndarray,
    cov: np.ndarray,
    fn: Callable[[np.ndarray], np.ndarray],
    walkers: int,
    rng: np.random.Generator,
    params: tuple[Param, ...],
) -> np.ndarray:
    """``walkers`` positions around ``theta`` (normal, covariance ``cov``, both brought
    inside the ranges of ``params``, :func:`start_within`), every one with a finite
    log-posterior. ``theta`` (ndim,) one centre, or (walkers, ndim) one per walker
    (:func:`idtool._posterior._ridge.ridge_walkers`)."""
    centres = np.broadcast_to(np.asarray(theta, float), (walkers, np.shape(theta)[-1]))
    centres = np.stack([start_within(c, cov, params)[0] for c in centres])
    cov = start_within(centres[0], cov, params)[1]
    ndim = centres.shape[1]
    chol = np.linalg.cholesky(cov + 1e-14 * np.diag(np.maximum(np.diag(cov), 1e-30)))
    p0 = centres + rng.standard_normal((walkers, ndim)) @ chol.T
    for _ in range(50):
        bad = ~np.isfinite(fn(p0))
        if not bad.any():
            return p0
        p0[bad] = centres[bad] + rng.standard_normal((int(bad.sum()), ndim)) @ chol.T
    raise IdtoolError(
        "could not place every walker where the log-posterior is finite; "
        "are the priors much narrower than the fit's intervals?"
    )
