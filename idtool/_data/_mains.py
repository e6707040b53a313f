"""The mains frequency of a bench: found as a spectral line in the traces, or given.

The load cell picks up the mains as hum (50 Hz in Europe, 60 Hz in North America). The
fit cancels it by averaging over blocks of whole mains periods
(:func:`idtool._data._blocks.prepare_fit_data`), which works only at the right
frequency: blocks of 50 Hz periods keep a 60 Hz hum. :func:`resolve_mains` chooses the
frequency (an explicit argument, else ``rig.mains_frequency_hz``, else a clear line in
the traces, else 50 Hz) and says in plain sentences when the traces disagree with it.

:func:`detect_mains_hz` looks for the line: each trace is differenced (a ramp becomes a
constant, a step a single spike, both with smooth spectra, while a sinusoid stays a
sinusoid), cut into half-overlapping Hann-windowed segments of :data:`SEGMENT_S` (or
half the trace, so that a short trace still gives three segments to average), and its
Welch power spectrum, divided by its median in the searched band, is averaged over
traces. The strongest bin between 40 and 70 Hz is compared with the median of the
spectrum 1.5 to 8 Hz away from it: a hum is a narrow line standing far above that local
floor, while noise, ramps and steps give a floor without one.
"""

from __future__ import annotations

import dataclasses
import math
import numbers

import numpy as np

from idtool._data._dataset import Dataset
from idtool._errors import IdtoolError

__all__ = [
    "DEFAULT_MAINS_HZ",
    "MainsLine",
    "detect_mains_hz",
    "resolve_mains",
]

DEFAULT_MAINS_HZ = 50.0  # assumed when nothing else says: most of the world
SEARCH_BAND_HZ = (40.0, 70.0)  # where the 50 and 60 Hz mains lines are looked for [Hz]
LINE_HALF_WIDTH_HZ = 1.5  # a line's own bins: the peak +- this [Hz] (Hann, 4 s: +-0.5 Hz)
FLOOR_HALF_WIDTH_HZ = 8.0  # the local floor: bins up to this far from the peak [Hz]
SEGMENT_S = 4.0  # longest Welch segment [s]: 0.25 Hz resolution
MIN_TRACE_S = 2.0  # shorter traces are too coarse in frequency (1 Hz) to show a line [s]
CLEAR_STRENGTH = 10.0  # a clear line stands >= 10x (10 dB) above its local floor
# Noise alone: with at least 3 segments per trace (about 6 degrees of freedom per bin)
# the largest of the ~120 bins searched exceeds 10x the median with a chance of about
# 1e-7; measured on hum-free simulated benches, it stays below about 4x.
NOMINAL_HZ = (50.0, 60.0)
NOMINAL_TOLERANCE = 0.01  # a line within 1% of 50 or 60 Hz is that grid's hum
PLAUSIBLE_HZ = (10.0, 1000.0)  # the range dataset.json accepts for rig.mains_frequency_hz

_SOURCES = {
    "argument": "given explicitly",
    "rig": "rig.mains_frequency_hz of dataset.json",
    "detected": "the line found in the traces",
    "default": "the default",
}


@dataclasses.dataclass(frozen=True)
class MainsLine:
    """The strongest spectral line between 40 and 70 Hz in a dataset's traces.

    Attributes:
        frequency_hz: its frequency [Hz] (interpolated between bins); NaN if no trace
            could be searched.
        strength: its power over the median power 1.5 to 8 Hz away [-] (about 1 to 4:
            no line; a 0.3 N hum under 0.5 N of white noise in 12 s at 1 kHz: ~200).
        clear: whether it is a strong narrow line (strength >= :data:`CLEAR_STRENGTH`).
        n_traces: traces searched (a trace shorter than 2 s, or sampled below 160 Hz so
            that 80 Hz is above its Nyquist frequency, is skipped).
    """

    frequency_hz: float
    strength: float
    clear: bool
    n_traces: int

    @property
    def nominal_hz(self) -> float:
        """50 or 60 [Hz] if the line is within 1% of it (the grid's nominal frequency,
        which the estimate of a few seconds of data cannot beat), else ``frequency_hz``
        rounded to 0.01 Hz."""
        for hz in NOMINAL_HZ:
            if abs(self.frequency_hz - hz) <= NOMINAL_TOLERANCE * hz:
                return hz
        return round(self.frequency_hz, 2)


def _welch(force_n: np.ndarray, sample_rate_hz: float) -> tuple[np.ndarray, np.ndarray]:
    """Frequencies [Hz] and Welch power spectrum of the differenced force (Hann window,
    segments of :data:`SEGMENT_S` or half the trace, half overlap)."""
    x = np.diff(np.asarray(force_n, float))
    n = min(round(SEGMENT_S * sample_rate_hz), x.size // 2)
    window = np.hanning(n)
    step = max(1, n // 2)
    power = np.zeros(n // 2 + 1)
    count = 0
    for start in range(0, x.size - n + 1, step):
        segment = x[start : start + n]
        power += np.abs(np.fft.rfft((segment - segment.mean()) * window)) ** 2
        count += 1
    return np.fft.rfftfreq(n, 1.0 / sample_rate_hz), power / count


def detect_mains_hz(dataset: Dataset) -> MainsLine:
    """Find the mains hum of ``dataset``: the strongest narrow line in 40-70 Hz.

    Every trace's spectrum (see the module notes) is normalised by its median in the band
    searched, so that loud traces do not outvote quiet ones, and averaged over traces
    on a common 0.125 Hz grid. Returns the line's frequency [Hz], its strength against
    the local spectral floor, and whether it is clear.
    """
    lo = SEARCH_BAND_HZ[0] - FLOOR_HALF_WIDTH_HZ
    hi = SEARCH_BAND_HZ[1] + FLOOR_HALF_WIDTH_HZ
    grid_hz = np.arange(lo, hi + 1e-9, 1.0 / (2.0 * SEGMENT_S))
    pooled = np.zeros_like(grid_hz)
    used = 0
    for tr in dataset.traces:
        fs = float(tr.sample_rate_hz)
        if tr.duration_s < MIN_TRACE_S or fs / 2.0 <= hi or tr.n_samples < 16:
            continue
        freq_hz, power = _welch(tr.force_n, fs)
        spectrum = np.interp(grid_hz, freq_hz, power)
        floor = float(np.median(spectrum))
        if not floor > 0:
            continue  # a constant trace: nothing to see
        pooled += spectrum / floor
        used += 1
    if used == 0:
        return MainsLine(math.nan, 1.0, False, 0)
    pooled /= used
    band = np.nonzero((grid_hz >= SEARCH_BAND_HZ[0]) & (grid_hz <= SEARCH_BAND_HZ[1]))[0]
    k = int(band[np.argmax(pooled[band])])
    distance = np.abs(grid_hz - grid_hz[k])
    near = (distance > LINE_HALF_WIDTH_HZ) & (distance <= FLOOR_HALF_WIDTH_HZ)
    floor = float(np.median(pooled[near]))
    strength = float(pooled[k] / floor) if floor > 0 else math.inf
    # The peak between bins: a parabola through the log power of the three bins around it.
    frequency = float(grid_hz[k])
    if 0 < k < grid_hz.size - 1 and np.all(pooled[k - 1 : k + 2] > 0):
        a, b, c = np.log(pooled[k - 1 : k + 2])
        curvature = a - 2.0 * b + c
        if curvature < 0:
            frequency += 0.5 * (a - c) / curvature * (grid_hz[1] - grid_hz[0])
    return MainsLine(float(frequency), strength, bool(strength >= CLEAR_STRENGTH), used)


def _is_harmonic(line_hz: float, mains_hz: float) -> bool:
    """Whether a line at ``line_hz`` is (within 1%) a whole multiple of ``mains_hz``
    [Hz]: blocks of whole periods of ``mains_hz`` then cancel it too."""
    ratio = line_hz / mains_hz
    return round(ratio) >= 1 and abs(ratio - round(ratio)) <= NOMINAL_TOLERANCE * ratio


def _check_given(mains_hz: object) -> float:
    """``mains_hz`` as a float [Hz] if it is a plausible mains frequency."""
    ok = isinstance(mains_hz, numbers.Real) and not isinstance(mains_hz, bool)
    if not ok or not (PLAUSIBLE_HZ[0] <= float(mains_hz) <= PLAUSIBLE_HZ[1]):  # type: ignore[arg-type]
        raise IdtoolError(
            f"mains frequency {mains_hz!r}: give it in Hz, between {PLAUSIBLE_HZ[0]:g} and "
            f"{PLAUSIBLE_HZ[1]:g} (50 in Europe, 60 in North America)"
        )
    return float(mains_hz)  # type: ignore[arg-type]


def resolve_mains(dataset: Dataset, mains_hz: float | None) -> tuple[float, str, list[str]]:
    """The mains frequency [Hz] the fit should average over, where it came from, and
    plain sentences for the fit report.

    The order: ``mains_hz`` if given (source "argument"), else
    ``dataset.rig.mains_frequency_hz`` ("rig"), else the line :func:`detect_mains_hz`
    finds if it is clear ("detected"), else 50 Hz ("default", with a note). A clear line
    that is not at the chosen frequency (or a multiple of it) gives a warning: its hum
    would leak into the block means.

    Raises:
        IdtoolError: ``mains_hz`` is not a number between 10 and 1000.
    """
    warnings: list[str] = []
    line = detect_mains_hz(dataset)
    rig_hz = dataset.rig.mains_frequency_hz
    if mains_hz is not None:
        hz, source = _check_given(mains_hz), "argument"
        if rig_hz is not None and not math.isclose(hz, rig_hz, rel_tol=1e-9):
            warnings.append(
                f"mains frequency {hz:g} Hz as given, not {rig_hz:g} Hz as "
                "rig.mains_frequency_hz of dataset.json says"
            )
    elif rig_hz is not None:
        hz, source = float(rig_hz), "rig"
    elif line.clear:
        hz, source = line.nominal_hz, "detected"
    else:
        hz, source = DEFAULT_MAINS_HZ, "default"
        seen = (
            f"the strongest line between {SEARCH_BAND_HZ[0]:g} and {SEARCH_BAND_HZ[1]:g} Hz is "
            f"{line.strength:.2g} times its local floor, not a clear hum"
            if line.n_traces
            else "no trace is long enough or sampled fast enough to show one"
        )
        warnings.append(
            f"mains frequency not given and no clear mains line in the traces ({seen}): "
            f"the block means assume {DEFAULT_MAINS_HZ:g} Hz mains; if the bench runs on "
            "60 Hz, set rig.mains_frequency_hz in dataset.json or give --mains-hz 60"
        )
    if line.clear and not _is_harmonic(line.frequency_hz, hz):
        warnings.append(
            f"the traces show a clear {line.frequency_hz:.1f} Hz line ({line.strength:.0f} "
            f"times the spectral floor) but the block means assume {hz:g} Hz mains "
            f"({_SOURCES[source]}): the hum leaks into the fit; if it is the mains, fit "
            f"with --mains-hz {line.nominal_hz:g} or set rig.mains_frequency_hz"
        )
    return hz, source, warnings
