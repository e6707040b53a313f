"""Bench simulator: the pure-JAX bench model plus a load cell's imperfections -> dataset v1.

By default the noise-free force is exactly what the fit will use (:mod:`idtool._model._bench`
with the couplings of :mod:`idtool._model._coupling`): the OFF level ``mu N``, the ON level
``FR mu N`` with FR from :func:`on_friction_ratio`, the actuator-limited slopes and the
start-up ramp of :func:`mean_force_n`. On top, in NumPy (:mod:`idtool._simulate._noise`): a
random lag of the horn behind the logged ON flag, a load-cell offset, white and AR(1)
noise, mains hum (at any frequency) and ADC quantisation. Trace ``k`` draws from the
``k``-th child of ``np.random.default_rng(seed)``, so one seed gives the same bytes every
time.

Optional departures from the fit's model (:mod:`idtool._simulate._params`): pull-to-pull
scatter of FR and mu, a rate-limited first-order-lag actuator
(:class:`idtool._model._actuator.LagActuator`), a linear drift of the offset, a
truth-only coupling law (:mod:`idtool._simulate._truth_coupling`), a horn fading within
its ON windows and a creeping friction level (:mod:`idtool._simulate._plateau_drift`);
and noise of the block means drawn from a registered noise model
(:mod:`idtool._simulate._block_noise`, from the seed's child after every trace's).
Their random draws
come from one child stream of the trace's stream (``rng.spawn(1)``), which leaves the
trace's own stream untouched: with the departures off the output is bit for bit what it
was before they existed, and turning on scatter, drift, the truth-only coupling, the
fading or the creep changes none of the noise (the lag actuator and another sample rate
change the trace lengths, hence the noise).

The truth (:class:`BenchTruth`, written as ``true_parameters.json``) holds per trace its
FR, mu and OFF level as drawn, and per operating point the FR without scatter
(:func:`true_friction_ratio` gives it at any operating point).
"""

from __future__ import annotations

import dataclasses
import math
import os
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import jax
import numpy as np

from idtool._data._dataset import Dataset, dataset_from_bytes
from idtool._data._write import document, json_bytes, render_table, trace_entry, write_dataset
from idtool._errors import IdtoolError
from idtool._model._actuator import AbstractActuator
from idtool._model._bench import TraceTiming, on_contact
from idtool._simulate._block_noise import add_block_noise
from idtool._simulate._noise import ar1_noise, mains_hum, quantise, white_noise
from idtool._simulate._params import BenchParams
from idtool._simulate._plateau_drift import on_force_end_n, with_plateau_drifts
from idtool._simulate._truth import BenchTruth, OperatingPoint, OperatingPointTruth, TraceTruth

__all__ = [
    "TRUTH_FILE",
    "experiment_plan",
    "noise_free_force_n",
    "operating_point",
    "simulate_bench",
    "true_friction_ratio",
    "write_simulation",
]

TRUTH_FILE = "true_parameters.json"
MAX_SAMPLES = 5e7  # all traces together: about 1 GB of doubles in flight


# Compiled once per actuator model and padded length (below); run op by op, every length
# would recompile each op. jax.jit, not eqx.filter_jit: the latter would hold the trace's
# levels and times (Python floats) static and compile once per trace (measured: 3.0 s a
# lag bench against 1.8 s).
@jax.jit
def _actuator_force_n(actuator, time_s, off_force_n, on_force_n, timing, offset_n):
    return actuator.force_n(time_s, off_force_n, on_force_n, timing, offset_n)


# Times are padded to a multiple of this many samples before the compiled bench model, so
# traces of nearly equal length (scatter moves every trace's length) share one compilation.
# The model is elementwise in time, so the padding changes no value.
_PAD_SAMPLES = 4096


def experiment_plan(params: BenchParams) -> tuple[OperatingPoint, ...]:
    """The matrix in order: loads, then amplitudes, then ON durations, then pull speeds,
    then repeats. A trace's id names its speed [mm/s] only when there are several."""
    e = params.experiments
    speeds = e.pull_speeds_m_s
    points = []
    for load in e.normal_loads_n:
        for alpha in e.amplitude_fractions:
            for duration in e.on_durations_s:
                for v in speeds:
                    for k in range(e.repeats):
                        name = f"N{load:g}_A{alpha * 100:.4g}_T{duration:g}"
                        name += f"_V{v * 1000:.4g}" if len(speeds) > 1 else ""
                        name += f"_r{k + 1}" if e.repeats > 1 else ""
                        points.append(OperatingPoint(name, load, alpha, duration, v))
    return tuple(points)


# one compiled program per law and coupling type and direction (the sdof law's solve is a
# loop, slow op by op)
_contact_at = jax.jit(on_contact, static_argnames=("direction",))


def operating_point(
    params: BenchParams, load_n: float, alpha: float, speed_m_s: float | None = None
) -> dict[str, float]:
    """FR, slip amplitude [m], VR and Lambda of the contact model at one operating point.

    ``load_n`` [N], ``alpha`` the amplitude fraction [-], ``speed_m_s`` the pull speed
    [m/s] (default: the experiments' first). Without pull-to-pull scatter.
    """
    c, rig = params.contact, params.rig
    v = params.experiments.pull_speeds_m_s[0] if speed_m_s is None else speed_m_s
    coupling = params.coupling.coupling(rig.max_amplitude_m)
    law = c.law_at(load_n)
    w = 2.0 * math.pi * rig.vibration_frequency_hz
    fr, a = (
        float(x)
        for x in _contact_at(
            law,
            coupling,
            load_n,
            alpha,
            v,
            rig.vibration_frequency_hz,
            rig.max_amplitude_m,
            direction=c.direction_model,
        )
    )
    return {
        "friction_ratio": float(fr),
        "slip_amplitude_m": a,
        "velocity_ratio": v / (a * w) if a > 0 else math.inf,
        "dimensionless_stiffness": float(law.stiffness_n_m())
        * a
        / (c.friction_coefficient * load_n),
    }


def true_friction_ratio(
    params: BenchParams,
    load_n: float,
    amplitude_fraction: float,
    speed_m_s: float | None = None,
) -> float:
    """The true FR [-] at any operating point, without pull-to-pull scatter.

    ``load_n`` [N], ``amplitude_fraction`` [-] in [0, 1], ``speed_m_s`` the pull speed
    [m/s] (default: the experiments' first). This is the curve a fit should recover, also at
    operating points the experiments did not measure (the truth-only coupling included).
    """
    return operating_point(params, load_n, amplitude_fraction, speed_m_s)["friction_ratio"]


def _total_samples(params: BenchParams, plan: tuple[OperatingPoint, ...]) -> float:
    """About how many samples the plan writes, all traces together."""
    e, actuator = params.experiments, params.actuator.actuator()
    mu = params.contact.friction_coefficient
    seconds = sum(
        params.actuator.pull_start_s
        + actuator.startup_duration_s(mu * point.normal_load_n)
        + e.sliding_before_s
        + point.on_duration_s
        + e.sliding_after_s
        for point in plan
    )
    return seconds * e.sample_rate_hz


def _timing(trace: TraceTruth) -> TraceTiming:
    """The trace's pull start and the horn's (physical) ON window [s]; infinite without
    an ON window."""
    horn = trace.horn_on_s
    return TraceTiming(
        startup_s=trace.startup_s,
        on_start_s=horn[0] if horn else math.inf,
        on_end_s=horn[1] if horn else math.inf,
    )


def noise_free_force_n(params: BenchParams, trace: TraceTruth, time_s: np.ndarray) -> np.ndarray:
    """The force [N] a trace was made from before noise, hum and quantisation.

    The actuator's response (:meth:`idtool._model._actuator.AbstractActuator.force_n`)
    to the trace's OFF and ON levels at the horn's (physical) ON window, plus the
    load-cell offset and its drift.
    """
    time_s = np.asarray(time_s, dtype=np.float64)
    n = time_s.size
    padded = np.pad(time_s, (0, -n % _PAD_SAMPLES), mode="edge")
    force = np.asarray(
        _actuator_force_n(
            params.actuator.actuator(),
            padded,
            trace.off_force_n,
            trace.on_force_n,
            _timing(trace),
            trace.load_cell_offset_n,
        )
    )[:n]
    force = with_plateau_drifts(params, trace, time_s, force)
    if trace.offset_drift_n_s != 0.0:  # skipped at 0 so the default output is unchanged
        force = force + trace.offset_drift_n_s * time_s
    return force


def _reaches_on_level(actuator: AbstractActuator, trace: TraceTruth) -> bool:
    """Whether the force gets down to the ON level before the horn switches OFF."""
    if trace.horn_on_s is None:
        return False
    return actuator.reaches_level(trace.off_force_n, trace.on_force_n, _timing(trace))


def _simulate_trace(
    params: BenchParams,
    point: OperatingPoint,
    op: OperatingPointTruth,
    rng: np.random.Generator,
) -> tuple[TraceTruth, np.ndarray, np.ndarray, np.ndarray]:
    """Truth, times [s], forces [N] and logged ON flags of one trace (``op``: its
    operating point)."""
    act, cell, e = params.actuator, params.load_cell, params.experiments
    actuator = act.actuator()
    fs = e.sample_rate_hz
    # The departures draw from a child of the trace's stream: spawning draws nothing from
    # ``rng``, so the draws below (and all the noise) are those of a simulation without
    # departures. Three normals always, so turning one departure on changes no other's.
    z_ratio, z_mu, z_drift = rng.spawn(1)[0].standard_normal(3).tolist()
    # Draw order is fixed so that a seed reproduces every trace.
    offset = cell.offset_mean_n + cell.offset_std_n * rng.standard_normal()
    switching = params.horn_switching
    lag_on, lag_off = np.maximum(
        switching.delay_mean_s + switching.delay_std_s * rng.standard_normal(2), 0.0
    ).tolist()
    phase = float(rng.uniform(0.0, 2.0 * np.pi))

    scatter = params.scatter
    mu = params.contact.friction_coefficient * math.exp(scatter.friction_coefficient_sd * z_mu)
    ratio = min(op.friction_ratio * math.exp(scatter.friction_ratio_sd * z_ratio), 1.0)
    drift = cell.offset_drift_sd_n_s * z_drift
    off = mu * point.normal_load_n
    on_level = ratio * off
    startup_end = act.pull_start_s + actuator.startup_duration_s(off)
    # The logged ON window is planned from the nominal OFF level, so scatter changes the
    # levels but neither the timing nor the trace length (hence none of the noise draws).
    nominal_off = params.contact.friction_coefficient * point.normal_load_n
    planned_startup_end = act.pull_start_s + actuator.startup_duration_s(nominal_off)
    i_on = round((planned_startup_end + e.sliding_before_s) * fs)
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
    truth = TraceTruth(
        id=point.id,
        normal_load_n=point.normal_load_n,
        amplitude_fraction=point.amplitude_fraction,
        on_duration_s=point.on_duration_s,
        friction_ratio=ratio,
        off_force_n=off,
        on_force_n=on_level,
        slip_amplitude_m=op.slip_amplitude_m,
        velocity_ratio=op.velocity_ratio,
        dimensionless_stiffness=op.dimensionless_stiffness,
        load_cell_offset_n=float(offset),
        startup_s=act.pull_start_s,
        logged_on_s=logged,
        horn_on_s=horn,
        mains_phase_rad=phase,
        reaches_on_level=False,
        friction_coefficient=mu,
        operating_point_friction_ratio=op.friction_ratio,
        offset_drift_n_s=drift,
        startup_end_s=startup_end,
        level_creep_per_s=params.contact.level_creep_per_s,
        pull_speed_m_s=point.pull_speed_m_s,
    )
    truth = dataclasses.replace(
        truth,
        reaches_on_level=_reaches_on_level(actuator, truth),
        on_force_end_n=on_force_end_n(params, truth),
    )
    noisy = (
        noise_free_force_n(params, truth, time_s)
        + white_noise(rng, n, cell.white_noise_std_n)
        + ar1_noise(rng, n, cell.correlated_noise_std_n, cell.correlated_noise_time_s, fs)
        + mains_hum(time_s, cell.mains_amplitude_n, cell.mains_frequency_hz, phase)
    )
    return truth, time_s, quantise(noisy, cell.adc_lsb_n), flags


def _operating_point_truths(
    params: BenchParams, plan: tuple[OperatingPoint, ...]
) -> dict[tuple[float, float, float], OperatingPointTruth]:
    """The contact model at each distinct (load, amplitude, speed) of the plan, in plan
    order."""
    out: dict[tuple[float, float, float], OperatingPointTruth] = {}
    for point in plan:
        v = point.pull_speed_m_s
        key = (point.normal_load_n, point.amplitude_fraction, v)
        if key not in out:
            op = operating_point(params, *key)
            vr, lam = op["velocity_ratio"], op["dimensionless_stiffness"]
            out[key] = OperatingPointTruth(
                normal_load_n=key[0],
                amplitude_fraction=key[1],
                pull_speed_m_s=v,
                friction_ratio=op["friction_ratio"],
                slip_amplitude_m=op["slip_amplitude_m"],
                velocity_ratio=vr if math.isfinite(vr) else None,
                dimensionless_stiffness=lam if math.isfinite(lam) else None,
            )
    return out


def simulate_bench(
    params: Mapping[str, Any] | BenchParams,
    seed: int,
    traces: Sequence[OperatingPoint] | None = None,
) -> tuple[Dataset, BenchTruth]:
    """Simulate the experiment matrix of ``params`` with random seed ``seed``, or the
    ``traces`` instead of the matrix (any loads [N], amplitudes, ON durations
    [s] and speeds [m/s], one trace each, with unique ids; the simulation study's fitted
    design plus planned pulls, :mod:`idtool._study`).

    Returns the dataset exactly as :func:`idtool.load_dataset` would read it back from
    :func:`write_simulation`'s folder (same arrays, same sha256), and the truth.

    Raises:
        IdtoolError: ``params`` breaks the simulator parameter schema.
    """
    if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
        raise IdtoolError(f"seed {seed!r}: give an integer >= 0")
    p = params if isinstance(params, BenchParams) else BenchParams.from_dict(params)
    plan = experiment_plan(p) if traces is None else tuple(traces)
    if len({point.id for point in plan}) != len(plan):
        raise IdtoolError("the simulated traces' ids must be unique")
    samples = _total_samples(p, plan)
    if samples > MAX_SAMPLES:
        raise IdtoolError(
            f"the experiment matrix needs {samples:.3g} samples (more than {MAX_SAMPLES:.0e}): "
            "lower experiments.sample_rate_hz, the durations or the matrix"
        )
    suffix = ".parquet" if p.output.trace_format == "parquet" else ".csv"
    points = _operating_point_truths(p, plan)
    files: dict[str, bytes] = {}
    entries, truths = [], []
    root = np.random.default_rng(seed)
    for point, rng in zip(plan, root.spawn(len(plan)), strict=True):
        op = points[(point.normal_load_n, point.amplitude_fraction, point.pull_speed_m_s)]
        truth, time_s, force_n, flags = _simulate_trace(p, point, op, rng)
        file = f"traces/{point.id}{suffix}"
        files[file] = render_table(file, time_s, force_n, flags)
        entries.append(
            trace_entry(
                point.id,
                file,
                point.normal_load_n,
                point.amplitude_fraction,
                point.pull_speed_m_s,
            )
        )
        truths.append(truth)
    description = p.description or (
        f"Simulated by idtool simulate-bench with seed {seed}; "
        f"the true parameters are in {TRUTH_FILE}."
    )
    doc = json_bytes(document(p.name, p.material, p.rig, entries, description))
    label = f"simulated dataset (seed {seed})"
    dataset = dataset_from_bytes(doc, files, label=label)
    if p.block_mean_noise is not None:
        # the root's next child: no trace's stream, so the rest of the noise is unchanged
        dataset = add_block_noise(dataset, p.block_mean_noise, root.spawn(1)[0], label)
    return dataset, BenchTruth(seed, p, tuple(truths), dataset.sha256, tuple(points.values()))


def write_simulation(
    out: str | os.PathLike[str], dataset: Dataset, truth: BenchTruth, *, force: bool = False
) -> Path:
    """Write a simulated dataset and its ``true_parameters.json`` as folder ``out``.

    All or nothing (:func:`idtool._atomic.atomic_output_dir`); an existing ``out`` is
    replaced only with ``force``.
    """
    extra = {TRUTH_FILE: json_bytes(truth.to_dict())}
    return write_dataset(dataset, out, force=force, extra_files=extra)
