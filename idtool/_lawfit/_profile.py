"""Each physical parameter's 95% interval: Wald where the profile agrees, the profile
likelihood's end where it does not (the rule of :mod:`idtool._fit._intervals`).

For every physical parameter the others are refitted with it held at both ends of its
Wald interval (internal scale, clipped to the range's edge :data:`Z_AT_BOUND`); the rise
of ``-2 log L`` there should be 3.84. A side whose rise is below 1 (the loss is far
flatter than ``J^T J`` says), or whose Wald end lies beyond the range, is replaced by
the profile's end: the walk goes outward in doubling steps until the rise reaches 3.84
(then bisects) or the range's edge (then the side is open, and the statement says the
data bound the parameter on one side only, or not at all). All sides of a stage run as
one vmapped batch of LM refits.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from idtool._fit._result import Z95, Z_AT_BOUND
from idtool._lawfit._solve import Optimum, refit_batch

__all__ = ["CHI2_95", "TOO_FLAT", "Side", "profile_intervals"]

CHI2_95 = 3.84
TOO_FLAT = 1.0
_DOUBLINGS = 5
_BISECTIONS = 6


@dataclasses.dataclass(frozen=True)
class Side:
    """One end of a parameter's interval on the internal scale.

    Attributes:
        z: the end (``+-inf`` when open: the data do not bound this side).
        wald_rise: the rise of -2 log L at the (clipped) Wald end.
        method: ``"wald"``, ``"profile"`` or ``"open"``.
    """

    z: float
    wald_rise: float
    method: str


def profile_intervals(lm, opt: Optimum, n_physical: int) -> list[tuple[Side, Side]]:
    """(lower, upper) :class:`Side` of each of the first ``n_physical`` parameters."""
    se = np.sqrt(np.diag(opt.cov_z))[:n_physical]
    idx = np.repeat(np.arange(n_physical), 2)
    sign = np.tile([-1.0, 1.0], n_physical)
    # an optimum beyond the range's edge is at its bound: walked from there, not from a
    # far-off internal value the bisections cannot cross (idtool._levels._estimate)
    centre = np.clip(opt.z[idx], -Z_AT_BOUND, Z_AT_BOUND)
    wald = centre + sign * Z95 * np.where(np.isfinite(se[idx]), se[idx], np.inf)
    beyond = np.abs(wald) >= Z_AT_BOUND
    ends = np.clip(wald, -Z_AT_BOUND, Z_AT_BOUND)
    # an end on the wrong side of the optimum (an optimum beyond the edge): no interval
    ends = np.where(sign * (ends - centre) > 0, ends, centre + sign * 1e-6)
    _, rise = refit_batch(lm, opt, idx, ends)
    method = np.where(rise < TOO_FLAT, "profile", "wald").astype(object)
    method[beyond] = "profile"
    result = ends.copy()
    walk = method == "profile"
    if walk.any():
        result = _walk(lm, opt, idx, sign, centre, ends, rise, walk, method)
    out = []
    for i in range(n_physical):
        lo, hi = (
            Side(
                float(result[2 * i + k])
                if method[2 * i + k] != "open"
                else float(sign[2 * i + k]) * np.inf,
                float(rise[2 * i + k]),
                str(method[2 * i + k]),
            )
            for k in (0, 1)
        )
        out.append((lo, hi))
    return out


def _walk(lm, opt, idx, sign, centre, ends, rise, walk, method):
    """Move the sides in ``walk`` out to a rise of 3.84, or mark them open."""
    inner = centre.copy()  # last point known below 3.84
    outer = np.where(rise >= CHI2_95, ends, np.nan)  # first point known above
    inner = np.where(walk & (rise < CHI2_95), ends, inner)
    step = np.abs(ends - centre)
    for _ in range(_DOUBLINGS):
        active = walk & np.isnan(outer) & (np.abs(inner) < Z_AT_BOUND)
        if not active.any():
            break
        step = np.where(active, 2.0 * step, step)
        trial = np.clip(centre + sign * step, -Z_AT_BOUND, Z_AT_BOUND)
        _, r = refit_batch(lm, opt, idx, np.where(active, trial, ends))
        above = active & (r >= CHI2_95)
        outer = np.where(above, trial, outer)
        inner = np.where(active & ~above, trial, inner)
    at_edge = walk & np.isnan(outer)
    method[at_edge] = "open"
    bisect = walk & ~at_edge
    for _ in range(_BISECTIONS):
        if not bisect.any():
            break
        mid = 0.5 * (inner + np.where(bisect, outer, inner))
        _, r = refit_batch(lm, opt, idx, np.where(bisect, mid, ends))
        up = bisect & (r >= CHI2_95)
        outer = np.where(up, mid, outer)
        inner = np.where(bisect & ~up, mid, inner)
    return np.where(bisect, 0.5 * (inner + outer), ends)
