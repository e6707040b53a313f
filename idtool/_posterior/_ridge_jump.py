"""A Metropolis-Hastings move that jumps along a profiled ridge (issue 26).

On a bench whose coupling law the fit does not ship, Kt's levels posterior is a peak
between a creep plateau and a Coulomb plateau (:mod:`idtool._posterior._ridge`). The
plateaus lie only 3-5 lower in log-density than the peak but span most of Kt's prior
range, so they can hold most of its mass: on the "coupling" bench (seed 503) the
marginal of Kt, computed along the ridge by importance sampling at each profile point
independently of any chain, puts its 95% interval at [3e4, 3e12] N/m, while chains
sampled with differential evolution alone "converged" (emcee's tau rule, R-hat, ESS)
at [1.9e8, 1.0e9]: once the walkers gather in the peak their differences are small, so
no proposal reaches a plateau again, and the autocorrelation seen within the peak
looks short.

This move proposes the profiled coordinate afresh for every walker from a fixed
density ``q`` along it, keeping the other sheared coordinates (each parameter's offset
from the ridge, :class:`~idtool._posterior._ridge.RidgeTarget`): an independence
proposal for one coordinate, accepted with ``p(x') q(z) / (p(x) q(z'))``, so the chain
keeps its target. ``q`` is the profile's density between its points (piecewise
constant per cell) mixed half and half with the uniform over the same span, so every
part of the range is proposed whatever the profile says (a defensive mixture: the
acceptance ratio is bounded where the uniform's part dominates).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np
from scipy.special import gammaln

__all__ = ["RIDGE_UNIFORM_SHARE", "cell_edges", "conditional_spread", "ridge_cells", "ridge_jump"]

# The uniform's share of the proposal density: the profile alone underweights the
# plateaus (their volume in the other parameters is larger than the peak's: on seed 503
# the marginal is 3 below the peak where the profile is 4.5 below).
RIDGE_UNIFORM_SHARE = 0.5


def cell_edges(grid: np.ndarray) -> np.ndarray:
    """The edges (points + 1,) of the cells around a profile's points (points,):
    halfway between neighbours, and half a cell beyond either end."""
    g = np.asarray(grid, float)
    edges = np.concatenate([[g[0]], 0.5 * (g[1:] + g[:-1]), [g[-1]]])
    edges[0] -= 0.5 * (g[1] - g[0])
    edges[-1] += 0.5 * (g[-1] - g[-2])
    return edges


def ridge_cells(grid: np.ndarray, log_post: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The proposal's cells along the profiled coordinate: their edges
    (:func:`cell_edges`, as the walkers' start,
    :func:`~idtool._posterior._ridge.ridge_walkers`) and each cell's probability
    (points,): its share of ``exp(log_post)`` times its width, mixed with its width's
    share of the whole span (:data:`RIDGE_UNIFORM_SHARE`). Points where the profile
    failed (non-finite) count as zero density."""
    edges = cell_edges(grid)
    width = np.diff(edges)
    lp = np.asarray(log_post, float)
    ok = np.isfinite(lp)
    mass = np.where(ok, np.exp(np.where(ok, lp, 0.0) - np.max(lp, where=ok, initial=-np.inf)), 0.0)
    mass = mass * width
    share = width / width.sum()
    if mass.sum() > 0.0:
        share = RIDGE_UNIFORM_SHARE * share + (1.0 - RIDGE_UNIFORM_SHARE) * mass / mass.sum()
    return edges, share


def conditional_spread(
    log_post: Callable[[np.ndarray], np.ndarray], theta: np.ndarray, index: int
) -> np.ndarray:
    """The Cholesky factors (points, d, d) of the other coordinates' spread at each
    profile point ``theta`` (points, ndim), ``d = ndim - 1``: the inverse of minus the
    log-posterior's Hessian in them (Laplace's approximation of their conditional law
    given the profiled coordinate), by central differences of ``log_post`` (batched)
    with steps of half the coordinate's own curvature width; eigenvalues of the
    precision floored at 1/9 (an sd of at most 3 internal units: a direction the
    posterior leaves flat is bounded by the parameter's prior, not by the data). A
    point whose log-posterior is not finite gets the floor's spread."""
    points, ndim = theta.shape
    others = np.flatnonzero(np.arange(ndim) != index)
    d = others.size
    out = np.empty((points, d, d))
    pairs = [(a, b) for a in range(d) for b in range(a, d)]
    signs = ((1, 1), (1, -1), (-1, 1), (-1, -1))
    for j in range(points):
        x0 = theta[j]
        probe = 1e-4
        shifted = np.repeat(x0[None], 2 * d + 1, axis=0)
        shifted[1 + np.arange(d), others] += probe
        shifted[1 + d + np.arange(d), others] -= probe
        f = log_post(shifted)
        curv = (f[1 : 1 + d] + f[1 + d :] - 2.0 * f[0]) / probe**2
        step = np.where(curv < 0.0, 0.5 / np.sqrt(np.abs(curv) + 1e-300), 0.5)
        step = np.clip(step, 1e-6, 0.5)
        rows = []
        for a, b in pairs:
            for sa, sb in signs:
                x = x0.copy()
                x[others[a]] += sa * step[a]
                x[others[b]] += sb * step[b]
                rows.append(x)
        f = log_post(np.array(rows)).reshape(len(pairs), 4)
        hess = np.zeros((d, d))
        for (a, b), (fpp, fpm, fmp, fmm) in zip(pairs, f, strict=True):
            hess[a, b] = hess[b, a] = (fpp - fpm - fmp + fmm) / (4.0 * step[a] * step[b])
        if not np.all(np.isfinite(hess)):
            out[j] = 3.0 * np.eye(d)
            continue
        evals, evecs = np.linalg.eigh(-0.5 * (hess + hess.T))
        cov = (evecs / np.maximum(evals, 1.0 / 9.0)) @ evecs.T
        out[j] = np.linalg.cholesky(0.5 * (cov + cov.T))
    return out


# The other coordinates' proposal: a Student t with 4 degrees of freedom around the
# ridge, scaled 1.2 times the Laplace spread (heavier tails than the conditional law,
# whose log-sds are skewed, so the independence proposal's weights stay bounded).
_T_DOF = 4.0
_T_SCALE = 1.2


def ridge_jump(
    index: int, grid: np.ndarray, log_post: np.ndarray, spread: np.ndarray | None = None
):
    """An ``emcee.moves.MHMove`` that redraws coordinate ``index`` of every walker from
    the ridge's proposal density (:func:`ridge_cells`) and, given ``spread`` (the
    Cholesky factors of :func:`conditional_spread`, one per profile point), the other
    (sheared) coordinates too, from a Student t around the ridge with the spread of the
    proposed point's cell; without ``spread`` they are kept. The Hastings factor is
    ``log q(x) - log q(x')``. A walker outside the cells' span (beyond the profile's
    ends) is not moved by it (factor ``-inf``)."""
    import emcee

    edges, share = ridge_cells(grid, log_post)
    log_density = np.log(share / np.diff(edges))
    ncells = share.size
    if spread is not None:
        d = spread.shape[1]
        log_det = np.sum(np.log(_T_SCALE * np.diagonal(spread, axis1=1, axis2=2)), axis=1)
        norm = (
            gammaln(0.5 * (_T_DOF + d))
            - gammaln(0.5 * _T_DOF)
            - 0.5 * d * np.log(_T_DOF * np.pi)
            - log_det
        )

    def log_q(x: np.ndarray) -> np.ndarray:
        cell = np.searchsorted(edges, x[:, index], side="right") - 1
        inside = (cell >= 0) & (cell < ncells)
        cell = np.clip(cell, 0, ncells - 1)
        out = np.where(inside, log_density[cell], -np.inf)
        if spread is None:
            return out
        y = np.delete(x, index, axis=1)[..., None]
        white = np.linalg.solve(_T_SCALE * spread[cell], y)[..., 0]
        r2 = np.sum(white**2, axis=1)
        return out + norm[cell] - 0.5 * (_T_DOF + d) * np.log1p(r2 / _T_DOF)

    def propose(coords: np.ndarray, random: Any) -> tuple[np.ndarray, np.ndarray]:
        n = coords.shape[0]
        cell = random.choice(ncells, size=n, p=share)
        new = np.array(coords, float, copy=True)
        new[:, index] = edges[cell] + random.rand(n) * (edges[cell + 1] - edges[cell])
        if spread is not None:
            g = (
                random.standard_normal((n, d))
                / np.sqrt(random.chisquare(_T_DOF, n) / _T_DOF)[:, None]
            )
            y = np.einsum("nij,nj->ni", _T_SCALE * spread[cell], g)
            new[:, np.flatnonzero(np.arange(coords.shape[1]) != index)] = y
        return new, log_q(coords) - log_q(new)  # -inf: a walker outside

    return emcee.moves.MHMove(propose)
