"""The table sampler's moves (:mod:`idtool._levels._sample`): the levels posterior's,
and a redraw of a parameter whose posterior arm the ridge's shear cannot straighten."""

from __future__ import annotations

from typing import Any

import numpy as np

from idtool._posterior._box import BoxTarget
from idtool._posterior._moves import sampler_moves
from idtool._posterior._record import LEVELS
from idtool._posterior._ridge import RidgeTarget

__all__ = ["redraw_move", "table_moves"]


def redraw_move(sampled: BoxTarget | RidgeTarget, index: int):
    """An ``emcee.moves.MHMove`` that redraws parameter ``index``'s place in its range
    (its box coordinate ``u``) uniformly over ``(0, 1)``, every other coordinate kept
    (module docstring). Along a ridge the walkers hold the parameter's offset from the
    ridge's path, ``x = u - path(z)``: the path's value at the walker's own profiled
    coordinate ``z`` (which this move keeps) is subtracted. The proposal does not depend
    on the walker's place, so its Hastings factor is zero and the move keeps the
    target (Metropolis within Gibbs, an independence proposal on one coordinate)."""
    import emcee

    if isinstance(sampled, RidgeTarget):
        grid, path, along = np.asarray(sampled.grid), np.asarray(sampled.path), sampled.index
    else:
        grid, path, along = np.zeros(2), np.zeros((2, len(sampled.slopes))), None

    def propose(coords: np.ndarray, random: Any) -> tuple[np.ndarray, np.ndarray]:
        n = coords.shape[0]
        shift = 0.0 if along is None else np.interp(coords[:, along], grid, path[:, index])
        new = np.array(coords, float, copy=True)
        new[:, index] = random.rand(n) - shift
        return new, np.zeros(n)

    return emcee.moves.MHMove(propose)


def table_moves(sampled: BoxTarget | RidgeTarget, redraw: list[int]):
    """The table sampler's moves (module docstring): the levels posterior's
    (:func:`~idtool._posterior._moves.sampler_moves`, with the ridge's jump along it),
    and a tenth of the steps per parameter in ``redraw`` (:func:`redraw_move`), taken
    from differential evolution and the snooker alike."""
    ridge = sampled if isinstance(sampled, RidgeTarget) else None
    moves = list(sampler_moves(LEVELS, ridge))
    extra = [(redraw_move(sampled, i), 0.1) for i in redraw]
    if not extra:
        return moves
    share = 0.05 * len(extra)
    (de, w_de), (snooker, w_snooker), *rest = moves
    return [(de, w_de - share), (snooker, w_snooker - share), *rest, *extra]
