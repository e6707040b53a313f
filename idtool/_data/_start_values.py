"""Start values for the fit read off the block-averaged traces: each trace's load-cell
offset, pull start and OFF level, the actuator's slopes and mu (robust percentiles and
medians, no fitting)."""

from __future__ import annotations

import dataclasses

import numpy as np

from idtool._data._blocks import FitData

__all__ = ["StartValues", "start_values"]


@dataclasses.dataclass(frozen=True)
class StartValues:
    """Data-driven start values for the bench nuisances and mu (per trace or shared)."""

    offset_n: np.ndarray
    pull_start_s: np.ndarray
    off_level_n: np.ndarray
    startup_slope_n_s: float
    slope_n_s: float
    friction_coefficient: float


def _crossing(t: np.ndarray, f: np.ndarray, level: float) -> float:
    above = np.nonzero(f > level)[0]
    return float(t[above[0]]) if above.size else float(t[0])


def start_values(data: FitData) -> StartValues:
    """Read the offset, pull start, OFF level and slopes off each trace (robustly)."""
    offsets, pulls, levels, up_slopes, down_slopes = [], [], [], [], []
    for i in range(data.n_traces):
        sel = data.block_trace == i
        t, f = data.block_time_s[sel], data.force_n[sel]
        lo, hi = np.percentile(f, [2, 98])
        t20, t80 = _crossing(t, f, lo + 0.2 * (hi - lo)), _crossing(t, f, lo + 0.8 * (hi - lo))
        up = 0.6 * (hi - lo) / max(t80 - t20, 1e-3)
        pull = t20 - 0.2 * (hi - lo) / up
        before = f[t < pull - 0.05]
        offset = float(np.median(before)) if before.size else float(lo)
        on0, on1 = data.on_start_s[i], data.on_end_s[i]
        steady = f[(t > t80 + 0.3) & (t < on0)]
        level = float(np.median(steady)) if steady.size else float(hi)
        if np.isfinite(on0):
            dip = (t > on0 + 0.04) & (t < min(on0 + 0.3, on1))
            if np.count_nonzero(dip) >= 3:
                down_slopes.append(-np.polyfit(t[dip], f[dip], 1)[0])
        offsets.append(offset)
        pulls.append(pull)
        levels.append(level)
        up_slopes.append(up)
    levels_n = np.array(levels) - np.array(offsets)
    loads = data.normal_load_n
    mu = float(np.sum(levels_n * loads) / np.sum(loads**2))
    positive = [s for s in down_slopes if s > 0]
    return StartValues(
        offset_n=np.array(offsets),
        pull_start_s=np.array(pulls),
        off_level_n=np.array(levels),
        startup_slope_n_s=float(np.median(up_slopes)),
        slope_n_s=float(np.median(positive)) if positive else 100.0,
        friction_coefficient=min(max(mu, 1e-3), 2.0),
    )
