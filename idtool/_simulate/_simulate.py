"""Bench simulator: the pure-JAX bench model plus a load cell's imperfections -> dataset v1.

The noise-free force is exactly what the fit will use (:mod:`idtool._model._bench` with the
couplings of :mod:`idtool._model._coupling`): the OFF level ``mu N``, the ON level
``FR mu N`` with FR from :func:`on_friction_ratio`, the actuator-limited slopes and the
start-up ramp of :func:`mean_force_n`. On top, in NumPy (:mod:`idtool._simulate._noise`): a
random lag of the horn behind the logged ON flag, a load-cell offset, white and AR(1)
noise, mains hum and ADC quantisation. Trace ``k`` draws from the ``k``-th child of
``np.random.default_rng(seed)``, so one seed gives the same bytes every time.
"""

from __future__ import annotations

import dataclasses
import math
import os
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from idtool._data._dataset import Dataset, dataset_from_bytes
from idtool._data._write import document, json_bytes, render_table, trace_entry, write_dataset
from idtool._errors import IdtoolError
from idtool._model._bench import TraceTiming, dahl_at_load, mean_force_n, on_friction_ratio
from idtool._simulate._noise import ar1_noise, mains_hum, quantise, white_noise
from idtool._simulate._params import BenchParams

__all__ = [
    "TRUTH_FILE",
    "BenchTruth",
    "OperatingPoint",
    "TraceTruth",
    "experiment_plan",
    "operating_point",
    "simulate_bench",
    "write_simulation",
]

TRUTH_FILE = "true_parameters.json"
MAX_SAMPLES = 5e7  # all traces together: about 1 GB of doubles in flight

# Compiled once per trace length; run op by op, every length would recompile each op.
_mean_force_n = jax.jit(mean_force_n)


@dataclasses.dataclass(frozen=True)
class OperatingPoint:
    """One trace of the matrix: its id, load [N], amplitude fraction, ON duration [s]."""

    id: str
    normal_load_n: float
    amplitude_fraction: float
    on_duration_s: float


@dataclasses.dataclass(frozen=True)
class TraceTruth:
    """What produced one simulated trace.

    Attributes:
        friction_ratio: FR = ON level / OFF level of the contact model.
        off_force_n, on_force_n: ``mu N`` and ``FR mu N`` [N], without the offset.
        slip_amplitude_m: effective slip amplitude a from the coupling [m].
        velocity_ratio: VR = v / (a w) (None without vibration).
        dimensionless_stiffness: Lambda = Kt a / (mu N).
        load_cell_offset_n: this trace's offset [N].
        startup_s: pull start [s].
        logged_on_s, horn_on_s: ON window of the logged flag and of the horn [s]
            (None without ON).
        mains_phase_rad: phase of the hum.
        reaches_on_level: whether the force gets down to the ON level before OFF.
    """

    id: str
    normal_load_n: float
    amplitude_fraction: float
    on_duration_s: float
    friction_ratio: float
    off_force_n: float
    on_force_n: float
    slip_amplitude_m: float
    velocity_ratio: float | None
    dimensionless_stiffness: float
    load_cell_offset_n: float
    startup_s: float
    logged_on_s: tuple[float, float] | None
    horn_on_s: tuple[float, float] | None
    mains_phase_rad: float
    reaches_on_level: bool


@dataclasses.dataclass(frozen=True)
class BenchTruth:
    """The truth behind a simulated dataset (written as ``true_parameters.json``)."""

    seed: int
    params: BenchParams
    traces: tuple[TraceTruth, ...]
    dataset_sha256: str

    def to_dict(self) -> dict[str, Any]:
        """The JSON document: the identifiable parameters first, then per trace, then all."""
        from idtool._version import (
            __version__,  # here: idtool/__init__ imports this module before defining it
        )

        contact = self.params.contact
        return {
            "seed": self.seed,
            "idtool_version": __version__,
            "dataset_sha256": self.dataset_sha256,
            "friction_law": contact.friction_law,
            "friction_coefficient": contact.friction_coefficient,
            "contact_stiffness_n_m": contact.contact_stiffness_n_m,
            "coupling": self.params.to_dict()["coupling"],
            "traces": [dataclasses.asdict(t) for t in self.traces],
            "params": self.params.to_dict(),
        }


def experiment_plan(params: BenchParams) -> tuple[OperatingPoint, ...]:
    """The matrix in order: loads, then amplitudes, then ON durations, then repeats."""
    e = params.experiments
    points = []
    for load in e.normal_loads_n:
        for alpha in e.amplitude_fractions:
            for duration in e.on_durations_s:
                for k in range(e.repeats):
                    name = f"N{load:g}_A{alpha * 100:.4g}_T{duration:g}"
                    name += f"_r{k + 1}" if e.repeats > 1 else ""
                    points.append(OperatingPoint(name, load, alpha, duration))
    return tuple(points)


def operating_point(params: BenchParams, load_n: float, alpha: float) -> dict[str, float]:
    """FR, slip amplitude [m], VR and Lambda of the contact model at one operating point."""
    c, rig = params.contact, params.rig
    v = params.experiments.pull_speed_m_s
    coupling = params.coupling.model()
    law = dahl_at_load(c.friction_coefficient, jnp.asarray(c.contact_stiffness_n_m), load_n)
    fr = on_friction_ratio(
        law,
        coupling,
        jnp.asarray(load_n),
        jnp.asarray(alpha),
        jnp.asarray(v),
        jnp.asarray(rig.vibration_frequency_hz),
        jnp.asarray(rig.max_amplitude_m),
    )
    a = float(coupling.amplitude_m(alpha, load_n, rig.max_amplitude_m))
    w = 2.0 * math.pi * rig.vibration_frequency_hz
    return {
        "friction_ratio": float(fr),
        "slip_amplitude_m": a,
        "velocity_ratio": v / (a * w) if a > 0 else math.inf,
        "dimensionless_stiffness": c.contact_stiffness_n_m * a / (c.friction_coefficient * load_n),
    }


def _total_samples(params: BenchParams, plan: tuple[OperatingPoint, ...]) -> float:
    """About how many samples the plan writes, all traces together."""
    act, e = params.actuator, params.experiments
    mu = params.contact.friction_coefficient
    seconds = sum(
        act.pull_start_s
        + mu * point.normal_load_n / act.startup_slope_n_s
        + e.sliding_before_s
        + point.on_duration_s
        + e.sliding_after_s
        for point in plan
    )
    return seconds * e.sample_rate_hz


def _simulate_trace(
    params: BenchParams, point: OperatingPoint, rng: np.random.Generator
) -> tuple[TraceTruth, np.ndarray, np.ndarray, np.ndarray]:
    """Truth, times [s], forces [N] and logged ON flags of one trace."""
    act, cell, e = params.actuator, params.load_cell, params.experiments
    fs = e.sample_rate_hz
    # Draw order is fixed so that a seed reproduces every trace.
    offset = cell.offset_mean_n + cell.offset_std_n * rng.standard_normal()
    switching = params.horn_switching
    lag_on, lag_off = np.maximum(
        switching.delay_mean_s + switching.delay_std_s * rng.standard_normal(2), 0.0
    ).tolist()
    phase = float(rng.uniform(0.0, 2.0 * np.pi))

    op = operating_point(params, point.normal_load_n, point.amplitude_fraction)
    off = params.contact.friction_coefficient * point.normal_load_n
    on_level = op["friction_ratio"] * off
    i_on = round((act.pull_start_s + off / act.startup_slope_n_s + e.sliding_before_s) * fs)
    i_off = i_on + round(point.on_duration_s * fs)
    n = i_off + round(e.sliding_after_s * fs) + 1
    time_s = np.arange(n) / fs
    flags = np.zeros(n, dtype=bool)
    flags[i_on:i_off] = True
    has_on = i_off > i_on
    logged = (float(time_s[i_on]), float(time_s[i_off])) if has_on else None
    horn = None
    if logged is not None:
        horn = (logged[0] + lag_on, max(logged[1] + lag_off, logged[0] + lag_on))
    timing = TraceTiming(
        startup_s=act.pull_start_s,
        on_start_s=horn[0] if horn else math.inf,
        on_end_s=horn[1] if horn else math.inf,
    )
    mean = _mean_force_n(
        time_s, off, on_level, timing, act.slope_n_s, act.startup_slope_n_s, offset, act.corner_n
    )
    noisy = (
        np.asarray(mean)
        + white_noise(rng, n, cell.white_noise_std_n)
        + ar1_noise(rng, n, cell.correlated_noise_std_n, cell.correlated_noise_time_s, fs)
        + mains_hum(time_s, cell.mains_amplitude_n, cell.mains_frequency_hz, phase)
    )
    truth = TraceTruth(
        id=point.id,
        normal_load_n=point.normal_load_n,
        amplitude_fraction=point.amplitude_fraction,
        on_duration_s=point.on_duration_s,
        friction_ratio=op["friction_ratio"],
        off_force_n=off,
        on_force_n=on_level,
        slip_amplitude_m=op["slip_amplitude_m"],
        velocity_ratio=op["velocity_ratio"] if math.isfinite(op["velocity_ratio"]) else None,
        dimensionless_stiffness=op["dimensionless_stiffness"],
        load_cell_offset_n=float(offset),
        startup_s=act.pull_start_s,
        logged_on_s=logged,
        horn_on_s=horn,
        mains_phase_rad=phase,
        reaches_on_level=bool(horn and act.slope_n_s * (horn[1] - horn[0]) >= off - on_level),
    )
    return truth, time_s, quantise(noisy, cell.adc_lsb_n), flags


def simulate_bench(
    params: Mapping[str, Any] | BenchParams, seed: int
) -> tuple[Dataset, BenchTruth]:
    """Simulate the experiment matrix of ``params`` with random seed ``seed``.

    Returns the dataset exactly as :func:`idtool.load_dataset` would read it back from
    :func:`write_simulation`'s folder (same arrays, same sha256), and the truth.

    Raises:
        IdtoolError: ``params`` breaks the simulator parameter schema.
    """
    if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
        raise IdtoolError(f"seed {seed!r}: give an integer >= 0")
    p = params if isinstance(params, BenchParams) else BenchParams.from_dict(params)
    plan = experiment_plan(p)
    samples = _total_samples(p, plan)
    if samples > MAX_SAMPLES:
        raise IdtoolError(
            f"the experiment matrix needs {samples:.3g} samples (more than {MAX_SAMPLES:.0e}): "
            "lower experiments.sample_rate_hz, the durations or the matrix"
        )
    suffix = ".parquet" if p.output.trace_format == "parquet" else ".csv"
    files: dict[str, bytes] = {}
    entries, truths = [], []
    for point, rng in zip(plan, np.random.default_rng(seed).spawn(len(plan)), strict=True):
        truth, time_s, force_n, flags = _simulate_trace(p, point, rng)
        file = f"traces/{point.id}{suffix}"
        files[file] = render_table(file, time_s, force_n, flags)
        entries.append(
            trace_entry(
                point.id,
                file,
                point.normal_load_n,
                point.amplitude_fraction,
                p.experiments.pull_speed_m_s,
            )
        )
        truths.append(truth)
    description = p.description or (
        f"Simulated by idtool simulate-bench with seed {seed}; "
        f"the true parameters are in {TRUTH_FILE}."
    )
    doc = json_bytes(document(p.name, p.material, p.rig, entries, description))
    dataset = dataset_from_bytes(doc, files, label=f"simulated dataset (seed {seed})")
    return dataset, BenchTruth(seed, p, tuple(truths), dataset.sha256)


def write_simulation(
    out: str | os.PathLike[str], dataset: Dataset, truth: BenchTruth, *, force: bool = False
) -> Path:
    """Write a simulated dataset and its ``true_parameters.json`` as folder ``out``.

    All or nothing (:func:`idtool._atomic.atomic_output_dir`); an existing ``out`` is
    replaced only with ``force``.
    """
    extra = {TRUTH_FILE: json_bytes(truth.to_dict())}
    return write_dataset(dataset, out, force=force, extra_files=extra)
