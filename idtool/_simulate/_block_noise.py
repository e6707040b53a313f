"""Block-mean noise drawn from a registered noise model, added to a simulated bench.

The simulator's own load-cell noise (:mod:`idtool._simulate._noise`) is drawn sample by
sample at the DAQ rate (white plus AR(1) over a correlation time), as a load cell makes
it; the block means the fit sees inherit whatever correlation that leaves. A noise
model of ``NOISE_MODELS`` says instead how the *block means* are distributed, so it is
drawn on the fit's own blocks (:func:`~idtool._data._blocks.prepare_fit_data`: whole
mains periods from each trace's first sample) and added to every sample of its block:
each block mean then moves by exactly the drawn value, and a model of any correlation
(tests/test_toy_noise.py: AR(2)) is simulated and fitted back on the same blocks.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping

import numpy as np

from idtool._data._blocks import prepare_fit_data
from idtool._data._dataset import Dataset, dataset_from_bytes
from idtool._data._paths import DATASET_FILE
from idtool._data._write import render_dataset
from idtool._model._noise import AbstractNoise

__all__ = ["with_block_noise"]


def with_block_noise(
    dataset: Dataset,
    noise: AbstractNoise,
    values: Mapping[str, float],
    seed: int,
    mains_hz: float = 50.0,
    periods_per_block: int = 2,
) -> Dataset:
    """``dataset`` with block-mean noise [N] drawn from ``noise`` at parameter ``values``
    by name (``sigma_n`` [N] and the model's others) added to its forces (module
    docstring); blocks of ``periods_per_block`` periods of ``mains_hz`` [Hz], as the fit
    cuts them (its defaults: 2 periods of the rig's mains). Checked again from its bytes,
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
    return dataset_from_bytes(files[DATASET_FILE], files, label=f"{dataset.name} + block noise")
