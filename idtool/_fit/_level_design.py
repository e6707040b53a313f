"""The levels model's data layout (:mod:`idtool._fit._variability`): which per-trace log
levels it holds, which sds they inform, and how the discrepancy correlates them; and what
predictions need to condition the discrepancy on the traces' own friction ratios."""

from __future__ import annotations

import dataclasses

import numpy as np

from idtool._fit._discrepancy import (
    Conditioning,
    correlation,
    length_scales,
    operating_coordinates,
)
from idtool._fit._free_levels import FreeLevels
from idtool._fit._level_cov import discrepancy_root
from idtool._model._benchmodel import BenchModel

__all__ = ["LevelDesign", "discrepancy_conditioning", "level_design"]


@dataclasses.dataclass(frozen=True)
class LevelDesign:
    """Layout of the levels model's data ``y`` (module docstring).

    ``rows``: which of (log OFF per trace, log FR per trace) ``y`` holds; ``kinds``
    (n, 2) one-hot OFF / FR rows; ``disc_root`` (traces, 2, p) a root in pairs of the
    discrepancy's correlation between the rows (:meth:`disc_corr`, ``from_pairs(D)
    from_pairs(D)^T``, :mod:`idtool._fit._level_cov`); ``active`` which of
    :data:`SD_PARAMS` the data can inform (``scatter_fr`` only with repeated operating
    points); ``coords`` (n_FR, 3) and ``scales`` the FR rows' operating-point
    coordinates and the correlation's length scales.
    """

    rows: np.ndarray
    kinds: np.ndarray
    op: np.ndarray
    active: np.ndarray
    disc_root: np.ndarray
    coords: np.ndarray
    scales: np.ndarray

    @property
    def separable(self) -> bool:
        return bool(self.active[1])

    def disc_corr(self) -> np.ndarray:
        """The discrepancy's correlation between the rows of ``y``, dense (n, n): 1
        where two FR rows share an operating point, 0 in the OFF rows. Only for the
        dense path (a fit folder written before the blocks); the blocks' is
        :attr:`disc_root`."""
        n = self.rows.size
        m = n - self.coords.shape[0]
        out = np.zeros((n, n))
        out[m:, m:] = np.asarray(correlation(self.coords, self.coords, self.scales))
        return out


def level_design(model: BenchModel, measured: np.ndarray) -> LevelDesign:
    """The :class:`LevelDesign` of ``model``'s traces, ``measured`` their ON levels."""
    m = model.data.n_traces
    idx = np.flatnonzero(measured)
    n = m + idx.size
    kinds = np.zeros((n, 2))
    kinds[:m, 0] = 1.0
    kinds[m:, 1] = 1.0
    op = np.asarray(model.data.op_index)[idx]
    x = _measured_coordinates(model, measured)
    scales = np.asarray(length_scales(model.data))
    repeated = bool(op.size and np.any(np.bincount(op) >= 2))
    active = np.array([True, repeated, op.size > 0])
    root = discrepancy_root(x, measured, scales)
    rows = np.concatenate([np.arange(m), m + idx])
    return LevelDesign(rows, kinds, op, active, root, x, scales)


def discrepancy_conditioning(model: BenchModel, free: FreeLevels) -> Conditioning:
    """What predictions need to condition the discrepancy on the traces' own friction
    ratios (:class:`~idtool._fit._discrepancy.Conditioning`)."""
    m = free.off_n.size
    x = _measured_coordinates(model, free.measured)
    scales = length_scales(model.data)
    if free.cov_y is None and free.cov_parts is not None:  # in blocks: nothing (n, n)
        idx = np.flatnonzero(free.measured)
        parts = free.cov_parts
        return Conditioning(x, free.y[m:], None, scales, parts.block[idx, 1, 1], parts.low[idx, 1])
    return Conditioning(x, free.y[m:], free.fr_covariance(), scales)


def _measured_coordinates(model: BenchModel, measured: np.ndarray) -> np.ndarray:
    """Operating-point coordinates (:func:`operating_coordinates`) of the traces whose
    ON level is ``measured``: the FR rows of the levels model, in trace order."""
    d = model.data
    op = np.asarray(d.op_index)[measured]
    return np.asarray(operating_coordinates(d.op_load_n[op], d.op_alpha[op], d.op_speed_m_s[op]))
