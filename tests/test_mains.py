"""The mains frequency (issue 10, item 5): found in the traces or given, and block means
over whole mains periods at any sample rate."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest
from bench_data_helpers import make_dataset, read_json, write_json

import idtool
from idtool._data._blocks import block_layout, prepare_fit_data, residual_hum_fraction
from idtool._data._dataset import Dataset, Rig, dataset_from_bytes
from idtool._data._mains import CLEAR_STRENGTH, detect_mains_hz, resolve_mains
from idtool._data._write import document, json_bytes, render_table, trace_entry
from idtool._errors import IdtoolError
from idtool._fit._fit import fit_model

# --- simulated benches ---------------------------------------------------------------


def bench(
    mains_hz: float, hum_n: float, sample_rate_hz: float = 1000.0, seed: int = 1, **cell
) -> Dataset:
    """Two short pulls (270 and 670 N, 50%, 1 s ON) of the example bench with a hum of
    amplitude ``hum_n`` [N] at ``mains_hz`` [Hz], sampled at ``sample_rate_hz`` [Hz]."""
    params = json.loads(idtool.example_params_path().read_text())
    e = params["experiments"]
    e.update(normal_loads_n=[270.0, 670.0], amplitude_fractions=[0.5], on_durations_s=[1.0])
    e.update(sliding_before_s=1.0, sliding_after_s=1.0, sample_rate_hz=sample_rate_hz)
    params["load_cell"].update(mains_frequency_hz=mains_hz, mains_amplitude_n=hum_n, **cell)
    dataset, _ = idtool.simulate_bench(params, seed=seed)
    return dataset


def with_rig_mains(dataset: Dataset, mains_hz: float | None) -> Dataset:
    rig = dataclasses.replace(dataset.rig, mains_frequency_hz=mains_hz)
    return dataclasses.replace(dataset, rig=rig)


@pytest.fixture(scope="module")
def bench60() -> Dataset:
    return bench(60.0, 0.3, sample_rate_hz=2000.0)


@pytest.fixture(scope="module")
def quiet() -> Dataset:
    return bench(50.0, 0.0)


@pytest.mark.parametrize(("mains_hz", "rate_hz"), [(50.0, 1000.0), (60.0, 2000.0), (60.0, 1000.0)])
def test_detects_the_hum(mains_hz, rate_hz):
    line = detect_mains_hz(bench(mains_hz, 0.3, sample_rate_hz=rate_hz))
    assert line.clear and line.n_traces == 2
    assert line.strength > 3 * CLEAR_STRENGTH
    assert line.frequency_hz == pytest.approx(mains_hz, abs=0.3)  # 0.5 Hz bins, interpolated
    assert line.nominal_hz == mains_hz


def test_no_clear_line_without_hum(quiet):
    line = detect_mains_hz(quiet)
    assert not line.clear
    assert line.strength < CLEAR_STRENGTH / 2  # noise, ramps and steps: about 2


def test_the_example_dataset_hums_at_50_hz():
    example = idtool.load_dataset(idtool.example_dataset_path())
    assert resolve_mains(example, None) == (50.0, "detected", [])


# --- resolve: argument > rig > detected > 50 -------------------------------------------


def test_resolve_order(bench60, quiet):
    assert resolve_mains(bench60, None) == (60.0, "detected", [])
    assert resolve_mains(with_rig_mains(bench60, 60.0), None) == (60.0, "rig", [])
    assert resolve_mains(with_rig_mains(quiet, 60.0), None) == (60.0, "rig", [])
    hz, source, notes = resolve_mains(with_rig_mains(quiet, 60.0), 50)  # the argument wins
    assert (hz, source) == (50.0, "argument")
    assert notes == [
        "mains frequency 50 Hz as given, not 60 Hz as rig.mains_frequency_hz of dataset.json says"
    ]
    hz, source, notes = resolve_mains(quiet, None)
    assert (hz, source) == (50.0, "default")
    assert len(notes) == 1 and "assume 50 Hz" in notes[0] and "--mains-hz 60" in notes[0]


def test_a_clear_line_where_none_is_assumed_is_a_warning(bench60):
    hz, source, notes = resolve_mains(bench60, 50.0)
    assert (hz, source) == (50.0, "argument")
    assert len(notes) == 1
    assert "clear 60.0 Hz line" in notes[0] and "--mains-hz 60" in notes[0]
    # A rig that says 50 while the traces hum at 60: the same warning, naming the rig.
    _, source, notes = resolve_mains(with_rig_mains(bench60, 50.0), None)
    assert source == "rig" and "rig.mains_frequency_hz" in notes[0]
    # Blocks of whole 30 Hz periods also cancel a 60 Hz hum: no warning.
    assert resolve_mains(bench60, 30.0)[2] == []


@pytest.mark.parametrize("bad", [0.06, 0.0, -50.0, 5e4, True, "60"])
def test_an_implausible_mains_argument_is_refused(quiet, bad):
    with pytest.raises(IdtoolError, match="give it in Hz"):
        resolve_mains(quiet, bad)


# --- rig.mains_frequency_hz in dataset.json ------------------------------------------


def test_rig_field_round_trip(tmp_path):
    root = make_dataset(tmp_path / "ds")
    assert idtool.load_dataset(root).rig.mains_frequency_hz is None  # optional
    doc = read_json(root)
    doc["rig"]["mains_frequency_hz"] = 60
    write_json(root, doc)
    loaded = idtool.load_dataset(root)
    assert loaded.rig == Rig(20000.0, 85e-6, 60.0)
    assert isinstance(loaded.rig.mains_frequency_hz, float)
    assert loaded.warnings == ()


@pytest.mark.parametrize(("value", "expected"), [(0.06, "must be >= 10"), (5e4, "<= 1000")])
def test_rig_field_is_validated(tmp_path, value, expected):
    root = make_dataset(tmp_path / "ds")
    doc = read_json(root)
    doc["rig"]["mains_frequency_hz"] = value
    write_json(root, doc)
    with pytest.raises(IdtoolError) as info:
        idtool.load_dataset(root)
    (problem,) = [str(p) for p in info.value.problems]
    assert str(root / "dataset.json") in problem
    assert "rig.mains_frequency_hz" in problem and expected in problem and "not kHz" in problem


# --- blocks of whole periods at any sample rate --------------------------------------


def sine_dataset(rates_hz: tuple[float, ...], mains_hz: float, seconds: float = 2.0) -> Dataset:
    """One hum-only trace per sample rate: 100 N plus a unit sinusoid at ``mains_hz``."""
    files, entries = {}, []
    for k, rate in enumerate(rates_hz):
        t = np.arange(round(seconds * rate)) / rate
        force = 100.0 + np.sin(2 * np.pi * mains_hz * t + 0.3 + k)
        name = f"traces/s{k}.csv"
        files[name] = render_table(name, t, force, np.zeros(t.size, bool))
        entries.append(trace_entry(f"s{k}", name, 450.0, 0.0, 0.025))
    rig = Rig(20000.0, 85e-6)
    doc = json_bytes(document("sines", "none", rig, entries, None))
    return dataset_from_bytes(doc, files)


def test_block_means_of_a_60_hz_sinusoid_at_2_khz_vanish():
    data = prepare_fit_data(sine_dataset((2000.0,), 60.0), mains_hz=60.0, periods_per_block=2)
    assert (data.periods_per_block, data.periods_requested, data.block_size) == (3, 2, 100)
    assert data.block_s == pytest.approx(0.05, rel=1e-12)
    assert data.residual_hum_fraction == 0.0 and data.notes == ()
    # Whole periods cancel the sine exactly: what is left is rounding of 100 + sin in
    # doubles and of the CSV's shortest repr (~1e-14 N), far below the 0.5% of the
    # amplitude that blocks of the nearest whole samples (67) would keep.
    assert np.max(np.abs(data.force_n - 100.0)) < 1e-12
    assert residual_hum_fraction(67, 2000.0, 60.0) > 4e-3


def test_block_layout_examples():
    assert block_layout([1000.0], 50.0, 2).samples == (40,)  # today's blocks
    assert block_layout([1000.0], 60.0, 2).samples == (50,)  # 3 periods
    assert block_layout([2000.0], 60.0, 2).samples == (100,)  # 3 periods
    mixed = block_layout([2000.0, 1000.0], 60.0, 1)
    assert (mixed.periods, mixed.samples, mixed.whole) == (3, (50, 100), True)
    # 7.1 samples per period: no count from 2 to 6 periods is whole; the best is kept.
    worst = block_layout([355.0], 50.0, 2)
    assert not worst.whole and worst.period_miss > 0.005
    assert 0 < worst.residual_hum_fraction < 0.05


def test_one_kilohertz_50_hz_blocks_are_unchanged():
    example = idtool.load_dataset(idtool.example_dataset_path())
    data = prepare_fit_data(example, periods_per_block=2)
    assert (data.block_size, data.periods_per_block, data.block_s) == (40, 2, 0.04)
    f = example.traces[0].force_n
    old = f[: f.size // 40 * 40].reshape(-1, 40).mean(axis=1)  # the former computation
    assert np.array_equal(data.force_n[data.block_trace == 0], old)


def test_mixed_sample_rates(tmp_path):
    data = prepare_fit_data(sine_dataset((1000.0, 2000.0), 60.0), mains_hz=60.0)
    assert data.periods_per_block == 3 and np.max(np.abs(data.force_n - 100.0)) < 1e-12
    with pytest.raises(IdtoolError, match="different sample rates") as info:
        prepare_fit_data(sine_dataset((1000.0, 355.0), 50.0, seconds=4.0), mains_hz=50.0)
    assert "traces/s0.csv" in str(info.value) and "traces/s1.csv" in str(info.value)


def test_blocks_that_cannot_be_whole_periods_say_so():
    data = prepare_fit_data(sine_dataset((355.0,), 50.0, seconds=4.0), 50.0, 2)
    assert len(data.notes) == 1 and "stays in each block mean" in data.notes[0]
    residual = np.max(np.abs(data.force_n - 100.0))
    assert residual <= data.residual_hum_fraction + 1e-12


# --- the fit --------------------------------------------------------------------------


@pytest.fixture(scope="module")
def loud60() -> Dataset:
    """A loud 60 Hz hum (1.5 N over 0.3 N of white noise), at 1 kHz."""
    return bench(60.0, 1.5, seed=3, white_noise_std_n=0.3, correlated_noise_std_n=0.1)


@pytest.fixture(scope="module")
def fit60(loud60):
    """The fit at the resolved mains frequency (FitData, FitResult); quick: 1 start."""
    hz, source, _ = resolve_mains(loud60, None)
    data = prepare_fit_data(loud60, mains_hz=hz, periods_per_block=2, mains_source=source)
    return data, fit_model(data, coupling="constant", n_starts=1, seed=0)


def _block_sd(data, result) -> float:
    return float(np.std(np.asarray(result.model.predict(result.z)) - data.force_n))


def test_fitting_at_the_resolved_frequency_beats_forcing_50_hz(loud60, fit60):
    """Blocks of 50 Hz periods (40 samples, 2.4 periods of 60 Hz) keep about 13% of the
    hum's amplitude; blocks of 60 Hz periods (50 samples) none."""
    data, result = fit60
    assert (data.mains_hz, data.mains_source, data.block_size) == (60.0, "detected", 50)
    forced = prepare_fit_data(loud60, mains_hz=50.0, periods_per_block=2)
    at_50 = fit_model(forced, coupling="constant", n_starts=1, seed=0)
    assert _block_sd(data, result) < 0.7 * _block_sd(forced, at_50)  # measured: 0.087, 0.159 N


def test_fit_json_records_the_mains_and_load_fit_rebuilds_the_blocks(tmp_path, loud60, fit60):
    from idtool._fit._run import FitRun
    from idtool._workflow import Fit

    data, result = fit60
    run = FitRun(data, result, {"dahl/constant": result}, "test", 0)
    folder = Fit.from_run(loud60, run).save(tmp_path / "fit", plots=False)
    doc = json.loads((folder / "fit.json").read_text())
    noise = doc["noise"]
    assert (noise["mains_hz"], noise["mains_source"]) == (60.0, "detected")
    assert (noise["periods_per_block"], noise["periods_requested"]) == (3, 2)
    assert noise["block_s"] == pytest.approx(0.05) and noise["residual_hum_fraction"] == 0.0

    def rebuilt():
        stored = idtool.load_fit(folder).model.data
        assert np.array_equal(stored.force_n, data.force_n)
        assert np.array_equal(stored.sub_time_s, data.sub_time_s)
        return stored

    assert rebuilt().mains_source == "detected"
    # A fit.json from before these fields: block_s / mains gave the periods.
    for key in ("mains_source", "periods_per_block", "periods_requested"):
        del noise[key]
    (folder / "fit.json").write_text(json.dumps(doc))
    assert rebuilt().periods_per_block == 3
    # ... whose blocks were not whole periods (2 periods of 60 Hz at 1 kHz = 33 samples):
    noise["block_s"] = 2 / 60
    (folder / "fit.json").write_text(json.dumps(doc))
    with pytest.raises(IdtoolError, match="run 'idtool fit' again"):
        idtool.load_fit(folder)
