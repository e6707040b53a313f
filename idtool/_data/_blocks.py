"""Bench traces prepared for fitting: block means over one mains period, and start values.

Averaging each trace over blocks of one mains period (20 ms at 50 Hz) removes the hum
exactly (a sinusoid averages to zero over its period), cuts the white noise by
sqrt(block size), and leaves a residual series whose correlation the fit models as
AR(1). The model is averaged over the same blocks (at ``sub_samples`` points inside
each block), so the comparison stays exact at the corners of the trace too.
"""

from __future__ import annotations

import dataclasses

import equinox as eqx
import numpy as np

from idtool._data._dataset import Dataset
from idtool._errors import IdtoolError, Problem

__all__ = ["FitData", "StartValues", "prepare_fit_data", "start_values"]


class FitData(eqx.Module):
    """Block-averaged traces, flat over blocks (trace after trace), plus operating points.

    Arrays indexed by trace have length ``n_traces``; by block, ``n_blocks``.
    ``on_start_s`` / ``on_end_s`` are the logged ON window (``inf`` for none).
    A pytree: the arrays are its leaves (so one compiled program serves every dataset
    of the same shape), the names and block layout are static.
    ``op_*`` are the distinct operating points (load [N], amplitude fraction, speed
    [m/s]) and ``op_index`` each trace's row among them: repeated traces share one
    contact solve.
    """

    name: str = eqx.field(static=True)
    sha256: str = eqx.field(static=True)
    trace_ids: tuple[str, ...] = eqx.field(static=True)
    block_size: int = eqx.field(static=True)
    block_s: float = eqx.field(static=True)
    mains_hz: float = eqx.field(static=True)
    normal_load_n: np.ndarray
    amplitude_fraction: np.ndarray
    pull_speed_m_s: np.ndarray
    on_start_s: np.ndarray
    on_end_s: np.ndarray
    vibration_frequency_hz: np.ndarray  # () [Hz]
    max_amplitude_m: np.ndarray  # () [m]
    block_trace: np.ndarray
    block_time_s: np.ndarray
    sub_time_s: np.ndarray
    force_n: np.ndarray
    first_block: np.ndarray
    first: np.ndarray  # (blocks,) True at each trace's first block
    op_index: np.ndarray
    op_load_n: np.ndarray
    op_alpha: np.ndarray
    op_speed_m_s: np.ndarray

    @property
    def n_traces(self) -> int:
        return len(self.trace_ids)

    @property
    def n_blocks(self) -> int:
        return int(self.force_n.size)


def prepare_fit_data(
    dataset: Dataset, mains_hz: float = 50.0, periods_per_block: int = 1, sub_samples: int = 4
) -> FitData:
    """Cut every trace into blocks of ``periods_per_block`` mains periods and average them."""
    problems = []
    loads, alphas, speeds, starts, ends = [], [], [], [], []
    block_time, sub_time, force = [], [], []
    block_sizes = []
    for tr in dataset.traces:
        bs = max(1, round(periods_per_block * tr.sample_rate_hz / mains_hz))
        block_sizes.append(bs)
        nb = tr.time_s.size // bs
        if nb < 10:
            problems.append(
                Problem(f"only {nb} blocks of {bs} samples: the trace is too short", tr.file)
            )
            continue
        if len(tr.on_windows_s) > 1:
            problems.append(
                Problem(
                    f"{len(tr.on_windows_s)} ultrasound ON windows; the bench model has one "
                    "per pull: split the trace into one file per ON window",
                    tr.file,
                    column="ultrasound_on",
                )
            )
            continue
        t = tr.time_s[: nb * bs].reshape(nb, bs)
        f = tr.force_n[: nb * bs].reshape(nb, bs)
        # Model points: centres of sub_samples equal groups of samples in each block.
        idx = np.clip(((np.arange(sub_samples) + 0.5) * bs / sub_samples).astype(int), 0, bs - 1)
        block_time.append(t.mean(axis=1))
        sub_time.append(t[:, idx])
        force.append(f.mean(axis=1))
        (on0, on1) = tr.on_windows_s[0] if tr.on_windows_s else (np.inf, np.inf)
        loads.append(tr.normal_load_n)
        alphas.append(tr.amplitude_fraction)
        speeds.append(tr.pull_speed_m_s)
        starts.append(on0)
        ends.append(on1)
    if problems:
        raise IdtoolError(f"{dataset.name}: traces cannot be fitted", problems)
    counts = np.array([b.size for b in force])
    first_block = np.concatenate([[0], np.cumsum(counts)[:-1]]).astype(int)
    first = np.zeros(int(counts.sum()), bool)
    first[first_block] = True
    ops = np.stack([loads, alphas, speeds], axis=1).astype(float)
    unique, op_index = np.unique(ops, axis=0, return_inverse=True)
    return FitData(
        name=dataset.name,
        sha256=dataset.sha256,
        trace_ids=tuple(tr.id for tr in dataset.traces),
        normal_load_n=np.array(loads, float),
        amplitude_fraction=np.array(alphas, float),
        pull_speed_m_s=np.array(speeds, float),
        on_start_s=np.array(starts, float),
        on_end_s=np.array(ends, float),
        vibration_frequency_hz=np.asarray(float(dataset.rig.vibration_frequency_hz)),
        max_amplitude_m=np.asarray(float(dataset.rig.max_amplitude_m)),
        block_trace=np.concatenate([np.full(n, i) for i, n in enumerate(counts)]),
        block_time_s=np.concatenate(block_time),
        sub_time_s=np.concatenate(sub_time),
        force_n=np.concatenate(force),
        first_block=first_block,
        first=first,
        op_index=op_index.ravel(),
        op_load_n=unique[:, 0],
        op_alpha=unique[:, 1],
        op_speed_m_s=unique[:, 2],
        block_size=block_sizes[0],
        block_s=periods_per_block / mains_hz,
        mains_hz=float(mains_hz),
    )


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
