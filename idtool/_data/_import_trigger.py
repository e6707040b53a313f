"""ON flags from the horn's trigger channel: a Schmitt trigger, then a debouncer.

The trigger is a voltage at a low level (OFF) or a high level (ON), with noise, slow
edges and contact bounce. The state switches ON when the voltage rises above
``threshold + hysteresis / 2`` and OFF when it falls below ``threshold - hysteresis / 2``;
in between it holds, so noise near the threshold cannot chatter. Then every ON or OFF
run shorter than the debounce time is a bounce or a glitch: inside a state it is
ignored; at an edge the burst of bounces goes to the new state, so the edge is the first
sample that left the old one (where the contact first closed or opened).
"""

from __future__ import annotations

import dataclasses
import itertools

import numpy as np

from idtool._errors import Problem

__all__ = ["TriggerSettings", "debounce", "schmitt", "trigger_flags", "trigger_levels"]

HYSTERESIS_FRACTION = 0.2  # default hysteresis, of the swing between the two levels
MIN_SWING_V = 0.5  # smaller swings are not a logic signal (give --threshold to insist)
MIN_SEPARATION = 10.0  # the levels must stand this many noise sds apart


@dataclasses.dataclass(frozen=True)
class TriggerSettings:
    """How a trigger channel [V] becomes ON flags.

    Attributes:
        threshold_v: switching threshold [V]; None: midway between the two levels.
        hysteresis_v: width of the band around it [V]; None: 20% of the swing.
        debounce_s: ON or OFF pulses shorter than this [s] are ignored (0: none).
        active_low: the horn is ON while the trigger is low.
        max_on_windows: more ON windows than this in one trace is an error.
    """

    threshold_v: float | None = None
    hysteresis_v: float | None = None
    debounce_s: float = 0.005
    active_low: bool = False
    max_on_windows: int = 10


def trigger_levels(volts: np.ndarray) -> tuple[float, float, float]:
    """Low and high level [V] and the noise sd about them [V]: the two groups of
    values that best explain the spread (Otsu's split of the histogram), their medians
    and the larger of their robust sds (1.4826 median absolute deviations)."""
    lo, hi = float(volts.min()), float(volts.max())
    if hi == lo:
        return lo, hi, 0.0
    counts, edges = np.histogram(volts, bins=256)
    centres = 0.5 * (edges[:-1] + edges[1:])
    w0 = np.cumsum(counts)[:-1].astype(float)  # samples below each candidate split
    w1 = volts.size - w0
    s0 = np.cumsum(counts * centres)[:-1]
    s1 = float(np.sum(counts * centres)) - s0
    ok = (w0 > 0) & (w1 > 0)
    mean0 = np.divide(s0, w0, out=np.zeros_like(s0), where=ok)
    mean1 = np.divide(s1, w1, out=np.zeros_like(s1), where=ok)
    between = np.where(ok, w0 * w1 * (mean0 - mean1) ** 2, 0.0)  # Otsu's criterion
    split = edges[int(np.argmax(between)) + 1]
    low_part, high_part = volts[volts < split], volts[volts >= split]
    low, high = float(np.median(low_part)), float(np.median(high_part))
    noise = max(1.4826 * float(np.median(np.abs(p - np.median(p)))) for p in (low_part, high_part))
    return low, high, noise


def schmitt(volts: np.ndarray, on_above: float, off_below: float) -> np.ndarray:
    """ON after a sample above ``on_above`` until one below ``off_below`` (OFF before
    the first sample outside the band)."""
    event = np.full(volts.size, -1, dtype=np.int8)
    event[volts > on_above] = 1
    event[volts < off_below] = 0
    last = np.maximum.accumulate(np.where(event >= 0, np.arange(volts.size), 0))
    return event[last] == 1


def debounce(flags: np.ndarray, time_s: np.ndarray, min_s: float) -> tuple[np.ndarray, int]:
    """``flags`` without ON or OFF runs shorter than ``min_s`` [s], and how many runs
    were changed. A run lasts from its first sample to the first sample after it (the
    last one a median step). All runs short: all OFF."""
    if min_s <= 0.0 or flags.size == 0:
        return flags.copy(), 0
    starts = np.flatnonzero(np.concatenate([[True], flags[1:] != flags[:-1]]))
    ends = np.concatenate([starts[1:], [flags.size]])
    step = float(np.median(np.diff(time_s)))
    padded = np.concatenate([time_s, [time_s[-1] + step]])
    stable = np.flatnonzero(padded[ends] - padded[starts] >= min_s - 1e-6 * step)
    value = flags[starts]
    if stable.size == 0:
        return np.zeros_like(flags), int(value.sum())
    new = value.copy()
    new[: stable[0]] = value[stable[0]]
    new[stable[-1] + 1 :] = value[stable[-1]]
    for a, b in itertools.pairwise(stable):
        # the same state on both sides: glitches; different: bounces of the edge after a
        new[a + 1 : b] = value[b]
    return np.repeat(new, ends - starts), int(np.sum(new != value))


def _edge_rows(flags: np.ndarray) -> np.ndarray:
    """0-based rows where an ON window starts."""
    return np.flatnonzero(flags & ~np.concatenate([[False], flags[:-1]]))


def trigger_flags(
    time_s: np.ndarray, volts: np.ndarray, settings: TriggerSettings, file: str, column: str
) -> tuple[np.ndarray | None, str, list[Problem]]:
    """ON flags from the trigger ``volts`` [V], a note on how they were found (for the
    trace's notes), and the problems: a channel that never switches, is ON at the
    start or at the end, or switches more often than ``settings.max_on_windows``."""

    def fail(message: str, row: int | None = None) -> tuple[None, str, list[Problem]]:
        return None, "", [Problem(message, file=file, row=row, column=column)]

    sign = -1.0 if settings.active_low else 1.0  # work on a channel that is high when ON
    low, high, noise = trigger_levels(sign * volts)
    swing = high - low
    if settings.threshold_v is None:
        if swing < MIN_SWING_V or swing < MIN_SEPARATION * noise:
            return fail(
                f"the trigger never switches: its values ({volts.min():.3g} to "
                f"{volts.max():.3g} V) look like one level with noise; check that --trigger "
                "names the horn's trigger channel, or give --threshold to insist"
            )
        threshold = 0.5 * (low + high)
    else:
        threshold = sign * settings.threshold_v
    band = HYSTERESIS_FRACTION * swing if settings.hysteresis_v is None else settings.hysteresis_v
    on_at, off_at = threshold + band / 2, threshold - band / 2
    up, down = ("above", "below") if sign > 0 else ("below", "above")
    raw = schmitt(sign * volts, on_at, off_at)
    if not raw.any():
        extreme = volts.max() if sign > 0 else volts.min()
        return fail(
            f"the trigger never switches ON: it never goes {up} {sign * on_at:.3g} V "
            f"(threshold {sign * threshold:.3g} V and half the hysteresis; it reaches "
            f"{extreme:.3g} V): check --threshold and --hysteresis, or --active-low"
        )
    flags, ignored = debounce(raw, time_s, settings.debounce_s)
    edges = _edge_rows(flags)
    if edges.size == 0:
        return fail(
            f"the trigger only gives pulses shorter than --debounce "
            f"({settings.debounce_s * 1e3:g} ms): shorten --debounce or check the channel"
        )
    if flags[0]:
        what = "never switches OFF" if flags.all() else "is ON from the first sample"
        return fail(
            f"the trigger {what} ({volts[0]:.3g} V at the start; ON {up} "
            f"{sign * on_at:.3g} V): a trace must start with the horn OFF; if the horn is "
            "ON while the trigger is low, pass --active-low, else check --threshold",
            1,
        )
    if flags[-1]:
        return fail(
            f"the trigger switches ON here (t = {time_s[edges[-1]]:.6g} s) and never OFF "
            "again before the end of the trace: record until after the horn is off, check "
            "--threshold, or give the ON state as a 0/1 column with --on",
            int(edges[-1]) + 1,
        )
    if edges.size > settings.max_on_windows:
        debounced = (
            f"after ignoring pulses shorter than {settings.debounce_s * 1e3:g} ms"
            if settings.debounce_s > 0
            else "without --debounce"
        )
        return fail(
            f"the trigger switches ON {edges.size} times, more than --max-windows "
            f"{settings.max_on_windows}, {debounced}: if it bounces, give a longer --debounce "
            "(and --hysteresis if it is noisy); if the pull really has that many ON "
            "windows, raise --max-windows",
            int(edges[settings.max_on_windows]) + 1,
        )
    note = (
        f"ON from '{column}' {up} {sign * on_at:.4g} V, OFF {down} {sign * off_at:.4g} V "
        f"(levels {sign * low:.4g} and {sign * high:.4g} V"
    )
    if settings.debounce_s > 0:
        note += f"; {ignored} pulse(s) shorter than {settings.debounce_s * 1e3:g} ms ignored"
    return flags, note + ")", []
