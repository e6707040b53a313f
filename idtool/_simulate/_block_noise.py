"""Block-mean noise drawn from a registered noise model, added to a simulated bench.

The simulator's own load-cell noise (:mod:`idtool._simulate._noise`) is drawn sample by
sample at the DAQ rate (white plus AR(1) over a correlation time), as a load cell makes
it; the block means the fit sees inherit whatever correlation that leaves. A noise
model of ``NOISE_MODELS`` says instead how the *block means* are distributed, so it is
drawn on the fit's own blocks (:func:`~idtool._data._blocks.prepare_fit_data`: whole
mains periods from each trace's first sample) and added to every sample of its block:
each block mean then moves by exactly the drawn value, and a model of any correlation
(tests/test_toy_noise.py: AR(2)) is simulated and fitted back on the same blocks.

A parameter file asks for it in its optional ``block_mean_noise`` section (the model's
registered name and its parameters, :class:`~idtool._simulate._records.BlockNoiseParams`);
:func:`idtool._simulate._simulate.simulate_bench` then adds it with
:func:`add_block_noise`, the blocks those of the fit's default mains
(:func:`~idtool._data._mains.resolve_mains`).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping

import numpy as np

from idtool._data._blocks import FIT_PERIODS_PER_BLOCK, prepare_fit_data
from idtool._data._dataset import Dataset, dataset_from_bytes
from idtool._data._mains import resolve_mains
from idtool._data._paths import DATASET_FILE
from idtool._data._write import render_dataset
from idtool._errors import Problem
from idtool._model._noise import AbstractNoise
from idtool._simulate._records import BlockNoiseParams

__all__ = ["add_block_noise", "block_noise_problems", "with_block_noise"]

# Blocks drawn to check a file's parameters: enough for a lag-2 model's whole recursion.
_CHECK_BLOCKS = 8


def with_block_noise(
    dataset: Dataset,
    noise: AbstractNoise,
    values: Mapping[str, float],
    seed: int | np.random.Generator,
    mains_hz: float = 50.0,
    periods_per_block: int = FIT_PERIODS_PER_BLOCK,
    label: str | None = None,
) -> Dataset:
    """``dataset`` with block-mean noise [N] drawn from ``noise`` at parameter ``values``
    by name (``sigma_n`` [N] and the model's others) added to its forces (module
    docstring); blocks of ``periods_per_block`` periods of ``mains_hz`` [Hz], as the fit
    cuts them (its defaults: 2 periods of the rig's mains); ``seed`` an integer or a
    generator to draw from. Checked again from its bytes (``label`` names it in errors),
    so its sha256 is that of the new traces."""
    data = prepare_fit_data(dataset, mains_hz=mains_hz, periods_per_block=periods_per_block)
    rng = np.random.default_rng(seed)
    drawn = noise.simulate(rng, {k: np.array([v], float) for k, v in values.items()}, data.first)
    block_trace = np.asarray(data.block_trace)
    traces = []
    for i, tr in enumerate(dataset.traces):
        size = round(data.block_s * tr.sample_rate_hz)  # samples per block of this trace
        per_sample = np.repeat(drawn[0, block_trace == i], size)
        force = np.array(tr.force_n, float)
        force[: per_sample.size] += per_sample
        traces.append(dataclasses.replace(tr, force_n=force))
    files = render_dataset(dataclasses.replace(dataset, traces=tuple(traces)))
    label = label or f"{dataset.name} + block noise"
    return dataset_from_bytes(files[DATASET_FILE], files, label=label)


def add_block_noise(
    dataset: Dataset, params: BlockNoiseParams, rng: np.random.Generator, label: str
) -> Dataset:
    """A simulated ``dataset`` with the block-mean noise of its parameter file's
    ``block_mean_noise`` section, drawn from ``rng`` on the blocks a default fit cuts
    (the mains of :func:`~idtool._data._mains.resolve_mains` without an argument)."""
    mains_hz, _, _ = resolve_mains(dataset, None)
    return with_block_noise(
        dataset, params.noise(), params.values(), rng, mains_hz=mains_hz, label=label
    )


def block_noise_problems(params: BlockNoiseParams, file: str) -> list[Problem]:
    """Why the noise model of a file's ``block_mean_noise`` cannot be drawn at its
    parameters (an AR model outside its stationary region, where its whitening has no
    real scale): a few blocks drawn, none finite. Empty when it can."""
    first = np.zeros(_CHECK_BLOCKS, bool)
    first[0] = True
    values = {k: np.array([v], float) for k, v in params.values().items()}
    try:
        # a model's NumPy takes the square root of a negative there: a NaN is the answer
        with np.errstate(all="ignore"):
            drawn = params.noise().simulate(np.random.default_rng(0), values, first)
        finite = bool(np.all(np.isfinite(drawn)))
    except (ValueError, ArithmeticError):
        finite = False
    if finite:
        return []
    numbers = ", ".join(f"{k} = {v:g}" for k, v in params.values().items())
    return [
        Problem(
            f"noise model '{params.model}' gives no finite noise at {numbers}: give "
            "parameters where the model is stationary (an AR model's roots outside the "
            "unit circle)",
            file,
            column="block_mean_noise",
        )
    ]
