"""Bench traces prepared for fitting: block means over whole mains periods, and start values.

Averaging each trace over blocks of whole mains periods (2 x 20 ms at 50 Hz) removes the
hum exactly (a sinusoid averages to zero over its period), cuts the white noise by
sqrt(block size), and leaves a residual series whose correlation the fit models as
AR(1). The model is averaged over the same blocks (at ``sub_samples`` points inside
each block), so the comparison stays exact at the corners of the trace too.

A block must span a whole number of samples too: at 1 kHz and 60 Hz a period is 16.7
samples, so :func:`block_layout` takes the smallest number of periods, from the one
asked for, that is a whole number of samples at every trace's sample rate (3 periods =
50 samples there; 2 periods = 40 samples at 1 kHz and 50 Hz).
"""

from __future__ import annotations

import dataclasses
from typing import ClassVar

import equinox as eqx
import numpy as np

from idtool._data._dataset import Dataset, TransducerSpec
from idtool._errors import IdtoolError, Problem

__all__ = [
    "FIT_PERIODS_PER_BLOCK",
    "BlockLayout",
    "DataLabels",
    "FitData",
    "block_layout",
    "padded_size",
    "prepare_fit_data",
    "residual_hum_fraction",
]

# A block may miss a whole number of mains periods by at most this fraction of one period:
# the hum left in its mean is then below about 0.5% / periods of the hum's amplitude.
# (2 kHz at 60 Hz: 2 periods = 66.67 samples; 67 samples miss by 1% of a period and are
# refused, 3 periods = 100 samples are taken.)
PERIOD_TOLERANCE = 0.005
# Periods searched beyond the requested number before settling for the best miss:
# longer blocks would blur the ON dips (0.3 s long on the bench).
MAX_EXTRA_PERIODS = 4
# The mains periods the fit asks of each block (idtool/_fit/_run.py); the simulator's
# block-mean noise is drawn on the same blocks (idtool/_simulate/_block_noise.py).
FIT_PERIODS_PER_BLOCK = 2


class FitData(eqx.Module):
    """Block-averaged traces, flat over blocks (trace after trace), plus operating points.

    Arrays indexed by trace have length ``n_traces``; by block, ``n_blocks``.
    ``on_start_s`` / ``on_end_s`` are the logged ON window (``inf`` for none).
    A pytree: the arrays are its leaves and the block layout is static, so one compiled
    program serves every dataset of the same shape; the names and notes are
    :class:`DataLabels` (static, but equal for every dataset).
    ``op_*`` are the distinct operating points (load [N], amplitude fraction, speed
    [m/s]) and ``op_index`` each trace's row among them: repeated traces share one
    contact solve.

    The blocks: ``block_size`` samples (of the first trace; a trace at another sample
    rate has its own count spanning the same periods), ``block_s`` their real duration
    [s], ``periods_per_block`` whole periods of the ``mains_hz`` [Hz] mains, chosen from
    ``periods_requested`` on (:func:`block_layout`); ``mains_source`` says where the
    frequency came from ("argument", "rig", "detected", "default");
    ``residual_hum_fraction`` is the largest fraction of a hum's amplitude a block mean
    keeps (0 for whole periods); ``notes`` are plain sentences for the fit report.
    """

    labels: DataLabels = eqx.field(static=True)
    block_size: int = eqx.field(static=True)
    block_s: float = eqx.field(static=True)
    mains_hz: float = eqx.field(static=True)
    periods_per_block: int = eqx.field(static=True)
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
    # 1 per block; 0 for the blocks padded() appends (their residuals are zeroed)
    block_weight: np.ndarray
    # the rig's transducer block (for the sdof coupling law), None when not given
    transducer: TransducerSpec | None = eqx.field(static=True, default=None)

    @property
    def name(self) -> str:
        return self.labels.name

    @property
    def sha256(self) -> str:
        return self.labels.sha256

    @property
    def trace_ids(self) -> tuple[str, ...]:
        return self.labels.trace_ids

    @property
    def periods_requested(self) -> int:
        return self.labels.periods_requested

    @property
    def mains_source(self) -> str:
        return self.labels.mains_source

    @property
    def residual_hum_fraction(self) -> float:
        return self.labels.residual_hum_fraction

    @property
    def notes(self) -> tuple[str, ...]:
        return self.labels.notes

    @property
    def n_traces(self) -> int:
        return self.normal_load_n.shape[0]

    def padded(self, n_blocks: int) -> FitData:
        """These data with blocks appended up to ``n_blocks``, of weight 0: each at the
        last block's time, of the last trace, a trace start of its own (so no AR(1)
        term reaches across), force 0. A model multiplies its residuals by
        ``block_weight``, so the padding changes no residual sum, Jacobian or normal
        equation; datasets of similar length then share compiled programs
        (:func:`padded_size`)."""
        extra = n_blocks - self.force_n.shape[0]
        if extra < 0:
            raise ValueError(f"n_blocks = {n_blocks}: below the {self.force_n.shape[0]} blocks")
        if extra == 0:
            return self

        def pad(x: np.ndarray, value) -> np.ndarray:
            x = np.asarray(x)
            fill = np.broadcast_to(np.asarray(value, x.dtype), (extra, *x.shape[1:]))
            return np.concatenate([x, fill])

        return dataclasses.replace(
            self,
            block_trace=pad(self.block_trace, self.n_traces - 1),
            block_time_s=pad(self.block_time_s, self.block_time_s[-1]),
            sub_time_s=pad(self.sub_time_s, self.sub_time_s[-1]),
            force_n=pad(self.force_n, 0.0),
            first=pad(self.first, True),
            block_weight=pad(self.block_weight, 0.0),
        )

    @property
    def n_blocks(self) -> int:
        return int(self.force_n.size)


@dataclasses.dataclass(frozen=True, eq=False)
class DataLabels:
    """What a dataset is called and what the fit report says of its blocks: nothing
    the model computes with.

    Every ``DataLabels`` compares equal to every other and hashes alike. JAX's caches
    key a jitted call on its arguments' static fields, so with the names static a
    second dataset of the same shape (the next bench, the next seed of a study) was
    traced, lowered and compiled again (~1.7 s a Levenberg-Marquardt program); with
    them here, its programs are the first one's; so also in the fit's programs kept on
    disk, whose key shows it as :attr:`program_key`
    (:func:`idtool._fit._compiled.structure_text`).
    """

    program_key: ClassVar[str] = "DataLabels"

    name: str
    sha256: str
    trace_ids: tuple[str, ...]
    periods_requested: int
    mains_source: str
    residual_hum_fraction: float
    notes: tuple[str, ...]

    def __eq__(self, other: object) -> bool:
        return isinstance(other, DataLabels)

    def __hash__(self) -> int:
        return 0


@dataclasses.dataclass(frozen=True)
class BlockLayout:
    """How long the blocks are: whole mains periods, and samples at each sample rate.

    Attributes:
        periods: mains periods per block.
        samples: samples per block, one per entry of ``sample_rates_hz``.
        sample_rates_hz: the distinct sample rates [Hz] it was made for.
        period_miss: largest distance of a block from ``periods`` whole periods, in
            periods (0 when the samples make whole periods exactly).
        residual_hum_fraction: largest fraction of a hum's amplitude a block mean keeps.
        whole: whether ``period_miss`` is within :data:`PERIOD_TOLERANCE`.
    """

    periods: int
    samples: tuple[int, ...]
    sample_rates_hz: tuple[float, ...]
    period_miss: float
    residual_hum_fraction: float
    whole: bool


def padded_size(n_blocks: int) -> int:
    """The block count a fit's compiled programs take for ``n_blocks`` blocks: rounded
    up to a multiple of 1/8 of the largest power of two below it (at least 16), so at
    most 12.5% padding from 128 blocks on. Two benches' traces rarely have the same
    length (the pull's start-up lasts mu N / slope: another mu, other lengths), and
    every length was a program compiled anew (~1.2 s per candidate model, cold)."""
    quantum = max(16, 2 ** max(int(n_blocks).bit_length() - 4, 0))
    return -(-int(n_blocks) // quantum) * quantum


def residual_hum_fraction(block_samples: int, sample_rate_hz: float, mains_hz: float) -> float:
    """Largest block mean of a unit-amplitude sinusoid at ``mains_hz`` [Hz] sampled at
    ``sample_rate_hz`` [Hz], over blocks of ``block_samples`` samples (any phase) [-].

    The mean of ``sin(theta k + phase)`` over ``n`` samples has amplitude
    ``|sin(n theta / 2)| / (n |sin(theta / 2)|)`` (the Dirichlet kernel): 0 for whole
    periods, 1 when the hum aliases onto a constant.
    """
    half = np.pi * mains_hz / sample_rate_hz
    denominator = block_samples * abs(np.sin(half))
    if denominator < 1e-12 * block_samples:
        return 1.0
    return float(abs(np.sin(block_samples * half)) / denominator)


def block_layout(
    sample_rates_hz: tuple[float, ...] | list[float], mains_hz: float, periods_per_block: int
) -> BlockLayout:
    """The smallest number of mains periods, from ``periods_per_block`` on, whose
    blocks are whole numbers of samples at every sample rate [Hz] (to within
    :data:`PERIOD_TOLERANCE` of a period).

    Searched up to ``periods_per_block + MAX_EXTRA_PERIODS``; if no count fits, the one
    missing whole periods least (``whole`` is then False and the residual hum says how
    much of the hum stays in the block means).
    """
    rates = tuple(float(r) for r in np.unique(np.asarray(sample_rates_hz, float)))
    best: BlockLayout | None = None
    for periods in range(periods_per_block, periods_per_block + MAX_EXTRA_PERIODS + 1):
        exact = [periods * fs / mains_hz for fs in rates]  # samples of whole periods
        samples = tuple(max(1, round(x)) for x in exact)
        miss = max(
            abs(n - x) * mains_hz / fs for n, x, fs in zip(samples, exact, rates, strict=True)
        )
        layout = BlockLayout(
            periods=periods,
            samples=samples,
            sample_rates_hz=rates,
            period_miss=float(miss),
            residual_hum_fraction=0.0
            if miss < 1e-9  # whole periods: 0, not the sine's rounding error
            else max(
                residual_hum_fraction(n, fs, mains_hz) for n, fs in zip(samples, rates, strict=True)
            ),
            whole=bool(miss <= PERIOD_TOLERANCE),
        )
        if layout.whole:
            return layout
        if best is None or layout.period_miss < best.period_miss:
            best = layout
    assert best is not None
    return best


def _layout_note(layout: BlockLayout, mains_hz: float, requested: int) -> str | None:
    """A sentence for the fit report when the blocks are not whole mains periods."""
    if layout.whole:
        return None
    rates = ", ".join(
        f"{n} samples at {fs:g} Hz"
        for n, fs in zip(layout.samples, layout.sample_rates_hz, strict=True)
    )
    return (
        f"no block of {requested} to {requested + MAX_EXTRA_PERIODS} periods of the "
        f"{mains_hz:g} Hz mains is a whole number of samples; the blocks ({rates}) miss "
        f"{layout.periods} whole periods by up to {layout.period_miss:.3f} of a period, so up "
        f"to {100 * layout.residual_hum_fraction:.2g}% of the hum's amplitude stays in each "
        "block mean"
    )


def _rate_groups(dataset: Dataset) -> str:
    """'1000 Hz: a.csv, b.csv; 2000 Hz: c.csv' for a message."""
    groups: dict[str, list[str]] = {}
    for tr in dataset.traces:
        groups.setdefault(f"{tr.sample_rate_hz:g} Hz", []).append(tr.file)
    return "; ".join(f"{rate}: {', '.join(files)}" for rate, files in groups.items())


def prepare_fit_data(
    dataset: Dataset,
    mains_hz: float = 50.0,
    periods_per_block: int = 1,
    sub_samples: int = 4,
    *,
    mains_source: str = "argument",
) -> FitData:
    """Cut every trace into blocks of whole mains periods and average them.

    ``mains_hz`` [Hz] is the mains frequency; each block spans the smallest number of
    its periods, from ``periods_per_block`` on, that is also a whole number of samples
    (:func:`block_layout`); traces at different sample rates get blocks of the same
    periods. ``mains_source`` is recorded in the :class:`FitData` (where ``mains_hz``
    came from). At 1 kHz and 50 Hz, 2 periods are 40 samples, as they always were.

    Raises:
        IdtoolError: a trace is too short or has several ON windows; ``mains_hz`` or
            ``periods_per_block`` is not positive.
    """
    if not (np.isfinite(mains_hz) and mains_hz > 0):
        raise IdtoolError(f"mains frequency {mains_hz!r} Hz: give a positive number (50 or 60)")
    if isinstance(periods_per_block, bool) or int(periods_per_block) != periods_per_block:
        raise IdtoolError(f"periods_per_block = {periods_per_block!r}: give a whole number >= 1")
    periods_per_block = int(periods_per_block)
    if periods_per_block < 1:
        raise IdtoolError(f"periods_per_block = {periods_per_block}: give a whole number >= 1")
    layout = block_layout([tr.sample_rate_hz for tr in dataset.traces], mains_hz, periods_per_block)
    if len(layout.sample_rates_hz) > 1 and not layout.whole:
        raise IdtoolError(
            f"{dataset.name}: the traces have different sample rates ({_rate_groups(dataset)}) "
            f"and no block of {periods_per_block} to {periods_per_block + MAX_EXTRA_PERIODS} "
            f"periods of the {mains_hz:g} Hz mains is a whole number of samples at all of "
            "them: resample the traces to one sample rate"
        )
    size_of = dict(zip(layout.sample_rates_hz, layout.samples, strict=True))
    problems = []
    loads, alphas, speeds, starts, ends = [], [], [], [], []
    block_time, sub_time, force = [], [], []
    block_sizes, block_durations = [], []
    for tr in dataset.traces:
        bs = size_of[float(tr.sample_rate_hz)]
        block_sizes.append(bs)
        block_durations.append(bs / tr.sample_rate_hz)
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
    labels = DataLabels(
        name=dataset.name,
        sha256=dataset.sha256,
        trace_ids=tuple(tr.id for tr in dataset.traces),
        periods_requested=periods_per_block,
        mains_source=mains_source,
        residual_hum_fraction=layout.residual_hum_fraction,
        notes=tuple(n for n in [_layout_note(layout, mains_hz, periods_per_block)] if n),
    )
    return FitData(
        labels=labels,
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
        block_weight=np.ones(int(counts.sum())),
        block_size=block_sizes[0],
        # The real duration (samples / rate) of the first trace's blocks, to 12 digits:
        # the rate is one over a median time step, exact to about 1e-15 only.
        block_s=float(f"{block_durations[0]:.12g}"),
        mains_hz=float(mains_hz),
        periods_per_block=layout.periods,
        transducer=dataset.rig.transducer,
    )
