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

from typing import Any

import numpy as np

__all__ = ["RIDGE_UNIFORM_SHARE", "cell_edges", "ridge_cells", "ridge_jump"]

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


def ridge_jump(index: int, grid: np.ndarray, log_post: np.ndarray):
    """An ``emcee.moves.MHMove`` that redraws coordinate ``index`` of every walker from
    the ridge's proposal density (:func:`ridge_cells`), the other coordinates kept;
    the Hastings factor ``log q(z) - log q(z')``. A walker outside the cells' span
    (beyond the profile's ends) is not moved by it (factor ``-inf``)."""
    import emcee

    edges, share = ridge_cells(grid, log_post)
    log_density = np.log(share / np.diff(edges))

    def log_q(z: np.ndarray) -> np.ndarray:
        cell = np.searchsorted(edges, z, side="right") - 1
        inside = (cell >= 0) & (cell < share.size)
        return np.where(inside, log_density[np.clip(cell, 0, share.size - 1)], -np.inf)

    def propose(coords: np.ndarray, random: Any) -> tuple[np.ndarray, np.ndarray]:
        n = coords.shape[0]
        cell = random.choice(share.size, size=n, p=share)
        z_new = edges[cell] + random.rand(n) * (edges[cell + 1] - edges[cell])
        new = np.array(coords, float, copy=True)
        new[:, index] = z_new
        return new, log_q(coords[:, index]) - log_q(z_new)  # -inf: a walker outside

    return emcee.moves.MHMove(propose)
