"""Each physical parameter's 95% interval: Wald where the profile agrees, the profile
likelihood's end where it does not (the rule of :mod:`idtool._fit._intervals`).

For every physical parameter the others are refitted with it held at both ends of its
Wald interval (internal scale, clipped to the range's edge :data:`Z_AT_BOUND`); the rise
of ``-2 log L`` there should be 3.84. A side whose rise is below 1 (the loss is far
flatter than ``J^T J`` says), or whose Wald end lies beyond the range, is replaced by
the profile's end: the walk goes outward in doubling steps until the rise reaches 3.84
(then bisects to :data:`CROSSING_TOL` and reads the crossing off the line through the
bracket's ends: :func:`line_crossing`) or the range's edge (then the side is open, and
the statement says the data bound the parameter on one side only, or not at all). All
sides of a stage run as one vmapped batch of LM refits.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from idtool._fit._result import Z95, Z_AT_BOUND
from idtool._lawfit._solve import Optimum, refit_batch

__all__ = [
    "CHI2_95",
    "CROSSING_TOL",
    "MAX_BISECTIONS",
    "TOO_FLAT",
    "Side",
    "json_number",
    "line_crossing",
    "profile_intervals",
]

CHI2_95 = 3.84
# A Wald end where -2 log L rises by less than this is walked out to 3.84: the profile
# is flatter there than the Wald interval assumes (a rise of 3.0 at the Wald end puts
# the profile's own end at most ~13% further out, if it stays that flat). At 1.0, a
# transverse table's Kt rose 1.5 at its Wald end, stayed below 2.5 for two decades
# beyond it, and the stated [7e6, 3.3e7] N/m missed the truth 2e6.
TOO_FLAT = 3.0
_DOUBLINGS = 5
# A profile's end is bisected until its bracket is this wide on the internal scale
# (0.015 decades of Kt near the middle of its range, where d log10 Kt / dz is largest),
# then read off the line through the bracket's ends. Six bisections and the midpoint
# left it anywhere in 1/64 of the walk's last step: up to 0.3 decades, and the one-sided
# bounds of different tables came out the same number.
CROSSING_TOL = 0.01
MAX_BISECTIONS = 12


def line_crossing(inner, r_inner, outer, r_outer):
    """Where the straight line through ``(inner, r_inner)`` and ``(outer, r_outer)``
    reaches 3.84 (arrays or floats; the midpoint where the rises do not order)."""
    inner, outer = np.asarray(inner, float), np.asarray(outer, float)
    r_inner, r_outer = np.asarray(r_inner, float), np.asarray(r_outer, float)
    ordered = np.isfinite(r_outer) & np.isfinite(r_inner) & (r_outer > r_inner)
    t = np.where(ordered, (CHI2_95 - r_inner) / np.where(ordered, r_outer - r_inner, 1.0), 0.5)
    return inner + np.clip(t, 0.0, 1.0) * (outer - inner)


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

    def to_json(self) -> list:
        """``[z, wald_rise, method]``, an infinite number as ``"inf"`` or ``"-inf"``
        (JSON has none): how a fit file stores a side."""
        return [json_number(self.z), json_number(self.wald_rise), self.method]

    @classmethod
    def from_json(cls, entry: list) -> Side:
        """The side :meth:`to_json` wrote."""
        return cls(float(entry[0]), float(entry[1]), str(entry[2]))


def json_number(x: float) -> float | str:
    """A float for JSON: an infinite one as "inf" or "-inf"."""
    return float(x) if math.isfinite(x) else ("inf" if x > 0 else "-inf")


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
    # every refit starts from the optimum with each physical parameter brought back to
    # the range's edge (Z_AT_BOUND; its value moves by < 0.1% of its range): one deep in
    # its sigmoid's tail has no gradient, and refits held it there. A presliding series
    # through a lagging cell put sigma1 at z = -13.7, and sigma2's refits, unable to hand
    # the damping back to sigma1, stated [167, 390] N s/m against 20 (from the edge the
    # rise at 20 is 3.06: sigma2 is not bounded below), as the table fit's refits start
    starts = opt.z.copy()
    starts[:n_physical] = np.clip(starts[:n_physical], -Z_AT_BOUND, Z_AT_BOUND)
    starts = np.tile(starts, (idx.size, 1))
    _, rise = refit_batch(lm, opt, idx, ends, starts)
    method = np.where(rise < TOO_FLAT, "profile", "wald").astype(object)
    method[beyond] = "profile"
    result = ends.copy()
    walk = method == "profile"
    if walk.any():
        result = _walk(lm, opt, idx, sign, centre, ends, rise, walk, method, starts)
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


def _walk(lm, opt, idx, sign, centre, ends, rise, walk, method, starts):
    """Move the sides in ``walk`` out to a rise of 3.84, or mark them open (each refit
    from its row of ``starts``)."""
    inner = centre.copy()  # last point known below 3.84
    r_inner = np.zeros_like(rise)
    outer = np.where(rise >= CHI2_95, ends, np.nan)  # first point known above
    r_outer = np.where(rise >= CHI2_95, rise, np.nan)
    below = walk & (rise < CHI2_95)
    inner = np.where(below, ends, inner)
    r_inner = np.where(below, rise, r_inner)
    step = np.abs(ends - centre)
    for _ in range(_DOUBLINGS):
        active = walk & np.isnan(outer) & (np.abs(inner) < Z_AT_BOUND)
        if not active.any():
            break
        step = np.where(active, 2.0 * step, step)
        trial = np.clip(centre + sign * step, -Z_AT_BOUND, Z_AT_BOUND)
        _, r = refit_batch(lm, opt, idx, np.where(active, trial, ends), starts)
        above = active & (r >= CHI2_95)
        outer, r_outer = np.where(above, trial, outer), np.where(above, r, r_outer)
        stay = active & ~above
        inner, r_inner = np.where(stay, trial, inner), np.where(stay, r, r_inner)
    at_edge = walk & np.isnan(outer)
    method[at_edge] = "open"
    bisect = walk & ~at_edge
    for _ in range(MAX_BISECTIONS):
        bisect = bisect & (np.abs(np.where(bisect, outer, inner) - inner) > CROSSING_TOL)
        if not bisect.any():
            break
        mid = 0.5 * (inner + np.where(bisect, outer, inner))
        _, r = refit_batch(lm, opt, idx, np.where(bisect, mid, ends), starts)
        up = bisect & (r >= CHI2_95)
        outer, r_outer = np.where(up, mid, outer), np.where(up, r, r_outer)
        down = bisect & ~up
        inner, r_inner = np.where(down, mid, inner), np.where(down, r, r_inner)
    found = walk & ~at_edge
    return np.where(
        found, line_crossing(inner, r_inner, np.where(found, outer, inner), r_outer), ends
    )
