"""Walkers spread along a parameter the data barely bound (issue 26).

The friction ratio depends on Kt only through ``Lambda = Kt a / (mu N)`` (notes §4), and
at one pull speed the slip amplitude ``a`` is tied across loads and amplitudes by the
coupling law alone (:func:`idtool._fit._run.kt_through_coupling`). On a bench whose
coupling law the fit does not ship, the levels posterior along Kt is two plateaus, the
creep limit (Kt below 1e7 N/m, ``Lambda -> 0``) and the Coulomb limit (above 3e9), each
with its own coupling gain (0.048 and 0.019: the two limits' amplitudes differ by
``pi^2 / 4``), joined through a valley 5-7 lower in log-posterior. Walkers started around
the fit's optimum all sit on one plateau; the differential-evolution moves, scaled for
steps within a mode, never cross to the other (32 x 2400 steps on the "ceiling" bench,
seed 901: every walker below 1.2e7 N/m, the posterior "converged" with Kt's interval
excluding its truth, 1.4e9).

So where the fit's 95% interval of a physical log-scale parameter spans more than
:data:`RIDGE_DECADES` (or it sits at a bound), the start profiles the log-posterior along
it (every other parameter maximised, :func:`ridge_profile`) over its whole internal range
and places the walkers on that profile in proportion to its density
(:func:`ridge_walkers`), so every mode starts populated; the sampler's mode-hopping move
(:func:`idtool._posterior._moves.levels_moves`) then carries walkers between them. The
same profile, with the parameter's own prior taken out, says which sides the data bound
(:func:`open_sides`, the fit's rule: :func:`idtool._fit._result.one_sided`).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable
from typing import Any

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array

from idtool._fit._result import Z95, Z_AT_BOUND, one_sided
from idtool._model._params import Param
from idtool._posterior._reparam import AbstractReparameterised
from idtool._posterior._ridge_jump import cell_edges, ridge_jump

__all__ = [
    "RIDGE_DECADES",
    "RIDGE_POINTS",
    "RIDGE_REFINE_LEVELS",
    "RIDGE_REFINE_WITHIN",
    "Ridge",
    "RidgeTarget",
    "open_sides",
    "ridge_profile",
    "ridge_walkers",
    "weak_parameter",
]

# A log-scale parameter whose Wald 95% interval spans more decades than this is profiled.
# Not only where the interval is useless: on the "coupling" bench (a truth-only coupling
# law, seed 503) the fit's Kt interval spans 0.8 decades around a sharp peak of the
# levels posterior, but the creep and Coulomb plateaus 4-5 lower on either side hold
# several percent of its mass, which walkers started at the peak never reach: their Kt
# interval missed the truth (1.5e9 N/m), the ridge-sampled one, [6.8e7, 8.5e9], holds it.
# Nor only above half a decade: on the "scatter" bench (seed 101) Kt's interval spans
# 0.33 decades, [9.8e8, 2.1e9], yet the posterior holds about a third of its mass on the
# plateaus (its 5-95% range 4e8 to 2.5e12 N/m, 40,000-step chains), which walkers
# started at the peak crossed to only slowly (Kt's integrated time 630-730 steps, against
# 61 along the ridge). The example's Kt spans 0.035 decades, the departure benches
# without pull-to-pull scatter or a foreign coupling 0.04-0.05 (their start is
# unchanged); "fading" 701 spans 0.25.
RIDGE_DECADES = 0.2
# Profile points over the internal range [-Z_AT_BOUND, Z_AT_BOUND] (one internal unit
# apart: the valley between Kt's plateaus is about one wide).
RIDGE_POINTS = 15
# Where the posterior has mass the profile is then refined, each cell whose log-density
# reaches within RIDGE_REFINE_WITHIN of the top halved RIDGE_REFINE_LEVELS times (a
# quarter unit apart there). The sheared coordinates follow the profile linearly between
# its points, and one internal unit of Kt is 2.25 decades in the middle of its range:
# on the "all" bench (seed 602, Kt's posterior about three decades wide) a kink of the
# coarse path inside the mass slowed the chain to 16,610 steps (slowest tau 124,
# coupling_gain); refined, 3,164 steps (tau 50) for 35 more maximisations (5 s).
# e^-8 = 3e-4: cells below that hold no walker's start and next to no posterior mass.
RIDGE_REFINE_WITHIN = 8.0
RIDGE_REFINE_LEVELS = 2
_CHI2_95 = 3.84  # -2 log L rise at a 95% interval's end, one parameter (as the fit's)
# Central-difference step on the internal scale: truncation error ~ step^2 (1e-10),
# rounding ~ 1e-16 |log-posterior| / step (2e-9 at 200)
_FD_STEP = 1e-5


@dataclasses.dataclass(frozen=True)
class Ridge:
    """The log-posterior profiled along parameter ``index`` (internal scale).

    ``grid`` (points,) the parameter's internal values; ``theta`` (points, ndim) the
    maximising vectors; ``log_post`` the log-posterior there (internal scale: prior and
    Jacobian included); ``log_lik`` the same without the parameter's own prior and
    Jacobian (what the data say about it)."""

    index: int
    grid: np.ndarray
    theta: np.ndarray
    log_post: np.ndarray
    log_lik: np.ndarray


def weak_parameter(
    params: tuple[Param, ...], z: np.ndarray, cov: np.ndarray, n_physical: int
) -> int | None:
    """The physical log-scale parameter whose Wald 95% interval (internal ``z`` +- 1.96
    sd, through the transform as the fit's, :func:`idtool._fit._result.estimate_of`)
    spans the most decades, if more than :data:`RIDGE_DECADES`; at a bound of its range
    (beyond :data:`Z_AT_BOUND`) counts as unbounded. None when every one is narrower."""
    best, widest = None, RIDGE_DECADES
    for i, p in enumerate(params[:n_physical]):
        if p.kind != "log":
            continue
        sd = float(np.sqrt(max(cov[i, i], 0.0)))
        if abs(z[i]) > Z_AT_BOUND:
            decades = math.log10(p.hi / p.lo)
        else:
            lo, hi = (float(p.value(float(z[i] + s * Z95 * sd))) for s in (-1.0, 1.0))
            decades = math.log10(hi / lo)
        if decades > widest:
            best, widest = i, decades
    return best


def _maximise_others(
    theta: np.ndarray, index: int, log_post: Callable[[np.ndarray], np.ndarray]
) -> tuple[np.ndarray, float]:
    """``theta`` with every entry but ``index`` maximising ``log_post`` (batched: (n,
    ndim) -> (n,)); ``theta`` itself if it does not improve on it. SciPy's BFGS on
    central differences (step :data:`_FD_STEP`), each value and gradient one batch of
    the program the sampler compiles anyway: the JAX gradient's own compilation took
    7-18 s, as long as the whole run of a ridge sampled without it. Stops at a gradient
    norm of 1e-3: with curvatures of 1e3 and more (a coupling gain known to 3%) the
    maximum is then placed to 1e-6 and its value to 1e-9."""
    from scipy.optimize import minimize

    free = np.flatnonzero(np.arange(theta.size) != index)
    shifts = np.zeros((2 * free.size + 1, theta.size))
    shifts[1 + np.arange(free.size), free] = _FD_STEP
    shifts[1 + free.size + np.arange(free.size), free] = -_FD_STEP

    def neg(x):
        th = theta.copy()
        th[free] = x
        f = log_post(th + shifts)
        if not np.all(np.isfinite(f)):
            return 1e30, np.zeros(x.size)
        grad = (f[1 : 1 + free.size] - f[1 + free.size :]) / (2.0 * _FD_STEP)
        return -f[0], -grad

    opts = {"maxiter": 500, "gtol": 1e-3}
    res = minimize(neg, theta[free], jac=True, method="BFGS", options=opts)
    out = theta.copy()
    if res.fun < neg(theta[free])[0]:
        out[free] = res.x
    value = float(log_post(out[None])[0])
    return out, value if np.isfinite(value) else -np.inf


def ridge_profile(
    log_post: Callable[[np.ndarray], np.ndarray], target: Any, theta: np.ndarray, index: int
) -> Ridge:
    """The log-posterior ``log_post`` (batched, (n, ndim) -> (n,)) of ``target`` (a
    :class:`~idtool._posterior._levels.LevelsTarget`: its parameters and priors) profiled
    along parameter ``index`` (:class:`Ridge`): over :data:`RIDGE_POINTS` internal values
    spanning its range, walking out from the point nearest ``theta`` in both directions,
    each maximisation (:func:`_maximise_others`) warm-started from its neighbour's, so
    the profile follows the ridge from one plateau to the other (the other plateau's
    coupling gain is 10 of its sds away from the fit's); then refined where the
    posterior has mass (:func:`_refined`)."""
    grid = np.linspace(-Z_AT_BOUND, Z_AT_BOUND, RIDGE_POINTS)
    theta = np.array(theta, float)
    theta[index] = float(np.clip(theta[index], -Z_AT_BOUND, Z_AT_BOUND))
    mid = int(np.argmin(np.abs(grid - theta[index])))
    out = np.empty((grid.size, theta.size))
    lp = np.full(grid.size, -np.inf)
    for order in (range(mid, grid.size), range(mid, -1, -1)):
        x = theta.copy()
        for j in order:
            x[index] = grid[j]
            out[j], lp[j] = _maximise_others(x, index, log_post)
            if np.isfinite(lp[j]):
                x = out[j].copy()
    for _ in range(RIDGE_REFINE_LEVELS):
        grid, out, lp = _refined(grid, out, lp, index, log_post)
    p, prior = target.params[index], target.priors[index]
    own = np.array([float(prior.logpdf(p.value(g))) + float(p.log_jacobian(g)) for g in grid])
    return Ridge(index, grid, out, lp, lp - own)


def _refined(
    grid: np.ndarray,
    theta: np.ndarray,
    lp: np.ndarray,
    index: int,
    log_post: Callable[[np.ndarray], np.ndarray],
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The profile with a point added in the middle of each cell whose log-density
    reaches within :data:`RIDGE_REFINE_WITHIN` of the top, maximised from its two
    neighbours' mean (their ridge is continuous between them)."""
    top = float(np.max(lp))
    cells = np.flatnonzero(np.maximum(lp[:-1], lp[1:]) > top - RIDGE_REFINE_WITHIN)
    ok = np.isfinite(lp[cells]) & np.isfinite(lp[cells + 1])
    cells = cells[ok]
    new = []
    for j in cells:
        x = 0.5 * (theta[j] + theta[j + 1])
        x[index] = 0.5 * (grid[j] + grid[j + 1])
        new.append(_maximise_others(x, index, log_post))
    if not new:
        return grid, theta, lp
    grid = np.concatenate([grid, 0.5 * (grid[cells] + grid[cells + 1])])
    theta = np.concatenate([theta, np.array([t for t, _ in new])])
    lp = np.concatenate([lp, np.array([v for _, v in new])])
    order = np.argsort(grid, kind="stable")
    return grid[order], theta[order], lp[order]


def open_sides(ridge: Ridge) -> str:
    """Which side alone the data bound the profiled parameter on (``"lower"``: bounded
    below only, ``"upper"``: above only, ``""``: both or neither), by the fit's rule
    (:func:`idtool._fit._result.one_sided`): a side is open when the likelihood-ratio
    95% set, where ``-2 log L`` is within 3.84 of its minimum, reaches the edge of the
    range on it. The set's ends are the profile points just outside it: a profile with
    a valley and a second plateau (Kt's creep and Coulomb limits) is open on both."""
    ll = ridge.log_lik
    inside = np.nonzero(2.0 * (np.max(ll) - ll) < _CHI2_95)[0]
    first, last = int(inside[0]), int(inside[-1])
    z_lo = float(ridge.grid[first - 1]) if first > 0 else -Z_AT_BOUND
    z_hi = float(ridge.grid[last + 1]) if last < ll.size - 1 else Z_AT_BOUND
    return one_sided(z_lo, z_hi)


def ridge_walkers(
    ridge: Ridge, cov: np.ndarray, walkers: int, rng: np.random.Generator
) -> tuple[np.ndarray, np.ndarray]:
    """Each walker's centre (walkers, ndim): a profile point drawn in proportion to the
    profile's mass in its cell (``exp(log_post)`` times the cell's width: the points are
    closer where the profile was refined), the profiled parameter spread uniformly over
    the cell (halfway to each neighbour); and the covariance of the walkers' spread
    around their centres (``cov`` without the profiled parameter's correlations, a tenth
    of its variance: the profile already follows the ridge)."""
    edges = cell_edges(ridge.grid)
    w = np.exp(ridge.log_post - np.max(ridge.log_post)) * np.diff(edges)
    w = np.where(np.isfinite(w), w, 0.0)
    pick = rng.choice(ridge.grid.size, size=walkers, p=w / w.sum())
    centres = ridge.theta[pick].copy()
    centres[:, ridge.index] = rng.uniform(edges[pick], edges[pick + 1])
    spread = 0.1 * np.asarray(cov, float)
    spread[ridge.index, :] = 0.0
    spread[:, ridge.index] = 0.0
    spread[ridge.index, ridge.index] = 1e-12  # the cell's uniform spread is its spread
    return centres, spread


class RidgeTarget(AbstractReparameterised):
    """A log-posterior sampled on coordinates sheared along a :class:`Ridge`: the walkers
    hold the profiled parameter's internal value ``z`` and every other parameter's offset
    from the profile's maximising value at ``z`` (linear between the profile points,
    the end points' beyond them), ``theta = x + path(z)``. The shear's Jacobian is 1, so
    the density is the target's own; along the ridge the other parameters stay near
    zero, and the creep and Coulomb plateaus of Kt (whose coupling gains differ by
    ``pi^2 / 4``) become one straight valley the walkers cross along ``z`` alone."""

    base: Any  # the LevelsTarget
    index: int = eqx.field(static=True)
    grid: Array  # (points,) the profiled parameter's internal values
    path: Array  # (points, ndim): the maximising vectors, the profiled column zero
    # (points,) the profile's log-density (failed points 50 below its lowest): the
    # ridge-jump move's proposal (idtool._posterior._ridge_jump)
    log_post: Array

    @classmethod
    def along(cls, base: Any, ridge: Ridge) -> RidgeTarget:
        """The shear of ``base`` along ``ridge`` (points where the profile failed take
        their neighbours' values)."""
        ok = np.isfinite(ridge.log_post)
        path = np.stack(
            [np.interp(ridge.grid, ridge.grid[ok], c[ok]) for c in ridge.theta.T], axis=1
        )
        path[:, ridge.index] = 0.0
        lp = np.where(ok, ridge.log_post, np.min(ridge.log_post[ok]) - 50.0)
        return cls(base, ridge.index, jnp.asarray(ridge.grid), jnp.asarray(path), jnp.asarray(lp))

    @classmethod
    def from_doc(cls, base: Any, doc: dict) -> RidgeTarget:
        """Rebuilt from :meth:`to_doc` (a resumed chain; a chain sampled before the
        profile's density was recorded proposes uniformly along the ridge)."""
        grid = jnp.asarray(doc["grid"])
        lp = jnp.asarray(doc["log_post"]) if "log_post" in doc else jnp.zeros_like(grid)
        return cls(base, int(doc["index"]), grid, jnp.asarray(doc["path"]), lp)

    def to_doc(self) -> dict:
        """The shear as data (recorded with the chain, which holds the sheared ``x``:
        ``theta[:, k] = x[:, k] + interp(x[:, index], grid, path[:, k])``), and the
        profile's log-density at ``grid``."""
        return {
            "kind": "ridge",
            "index": self.index,
            "grid": np.asarray(self.grid).tolist(),
            "path": np.asarray(self.path).tolist(),
            "log_post": np.asarray(self.log_post).tolist(),
            "formula": "theta[k] = x[k] + interp(x[index], grid, path[:, k])",
        }

    def jump_move(self):
        """The move that redraws the profiled coordinate along the ridge
        (:func:`idtool._posterior._ridge_jump.ridge_jump`)."""
        return ridge_jump(self.index, np.asarray(self.grid), np.asarray(self.log_post))

    def _shift(self, x):
        z = x[..., self.index]
        return jnp.stack([jnp.interp(z, self.grid, c) for c in self.path.T], axis=-1)

    def to_internal(self, x):
        """Internal vectors ``theta`` (..., ndim) of sheared ones ``x``."""
        return x + self._shift(x)

    def from_internal(self, theta):
        """Sheared vectors ``x`` of internal ones ``theta`` (..., ndim)."""
        return theta - self._shift(theta)

    def log_posterior_batch(self, x: Array) -> Array:
        """The base's log-posterior at the sheared vectors ``x`` (walkers, ndim)."""
        return self.base.log_posterior_batch(self.to_internal(x))
