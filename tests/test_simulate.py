"""The bench simulator: bench model plus noise, written as a dataset the loader accepts."""

from __future__ import annotations

import copy
import json
import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from bench_data_helpers import folder_fingerprint

import idtool
import idtool._data._write
from idtool import BenchParams, load_bench_params, load_dataset, simulate_bench, write_simulation
from idtool._cli._main import main
from idtool._data._example import EXAMPLE_SEED, example_params_path
from idtool._errors import IdtoolError
from idtool._model._bench import TraceTiming, dahl_at_load, mean_force_n, on_friction_ratio
from idtool._model._coupling import PowerLimitedCoupling

SEED = 7


def small_params(trace_format: str = "csv") -> dict[str, Any]:
    """The example's physics on a small matrix: 2 loads x 1 amplitude x 2 ON times."""
    params = json.loads(example_params_path().read_text())
    params["experiments"].update(
        normal_loads_n=[450.0, 670.0],
        amplitude_fractions=[0.5],
        on_durations_s=[0.5, 2.5],
        sliding_before_s=2.0,
        sliding_after_s=1.5,
        sample_rate_hz=500.0,
    )
    params["output"]["trace_format"] = trace_format
    del params["description"]
    return params


@pytest.fixture(scope="module")
def simulated():
    return simulate_bench(small_params(), SEED)


@pytest.fixture(scope="module")
def example_truth() -> dict[str, Any]:
    return json.loads((idtool.example_dataset_path() / "true_parameters.json").read_text())


def _write_params(path: Path, params: dict[str, Any]) -> Path:
    path.write_text(json.dumps(params))
    return path


# --- the written dataset ---------------------------------------------------------------


@pytest.mark.parametrize("trace_format", ["csv", "parquet"])
def test_written_dataset_loads_back_identically(tmp_path, trace_format):
    dataset, truth = simulate_bench(small_params(trace_format), SEED)
    out = write_simulation(tmp_path / "sim", dataset, truth)
    loaded = load_dataset(out)
    assert loaded.sha256 == dataset.sha256 == truth.dataset_sha256
    assert loaded.warnings == ()
    assert [t.id for t in loaded.traces] == [t.id for t in truth.traces]
    for a, b in zip(loaded.traces, dataset.traces, strict=True):
        assert a.file.endswith(f".{trace_format}")
        np.testing.assert_array_equal(a.time_s, b.time_s)
        np.testing.assert_array_equal(a.force_n, b.force_n)
        np.testing.assert_array_equal(a.ultrasound_on, b.ultrasound_on)
    written = json.loads((out / "true_parameters.json").read_text())
    assert written["dataset_sha256"] == loaded.sha256 and written["seed"] == SEED


def test_same_seed_same_bytes_other_seed_other_bytes(tmp_path, capsys):
    params = _write_params(tmp_path / "p.json", small_params())
    for name, seed in (("a", 3), ("b", 3), ("c", 4)):
        args = ["simulate-bench", "--params", str(params), "--out", str(tmp_path / name)]
        assert main([*args, "--seed", str(seed)]) == 0
    assert "wrote 4 trace(s)" in capsys.readouterr().out
    a, b, c = (folder_fingerprint(tmp_path / n) for n in "abc")
    assert a == b
    traces = [k for k in a if k.startswith("traces/")]
    assert len(traces) == 4 and all(a[k] != c[k] for k in traces)


# --- the physics: OFF and ON levels, slopes, noise ----------------------------------------


def _mean_between(trace, start_s: float, end_s: float) -> float:
    inside = (trace.time_s >= start_s) & (trace.time_s <= end_s)
    assert inside.sum() > 100
    return float(trace.force_n[inside].mean())


def test_off_level_is_mu_n_plus_offset(simulated):
    dataset, truth = simulated
    mu = truth.params.contact.friction_coefficient
    for trace, true in zip(dataset.traces, truth.traces, strict=True):
        ramp_end = true.startup_s + true.off_force_n / truth.params.actuator.startup_slope_n_s
        level = _mean_between(trace, ramp_end + 0.3, trace.on_windows_s[0][0] - 0.05)
        assert level == pytest.approx(mu * trace.normal_load_n + true.load_cell_offset_n, abs=0.4)
        before = _mean_between(trace, 0.0, true.startup_s - 0.05)
        assert before == pytest.approx(true.load_cell_offset_n, abs=0.4)


def test_long_window_reaches_fr_mu_n_and_short_does_not(simulated):
    dataset, truth = simulated
    slope = truth.params.actuator.slope_n_s
    for trace, true in zip(dataset.traces, truth.traces, strict=True):
        on_level = true.friction_ratio * true.off_force_n + true.load_cell_offset_n
        horn_start, horn_end = true.horn_on_s
        if true.on_duration_s == 2.5:
            assert true.reaches_on_level
            settled = horn_start + (true.off_force_n - true.on_force_n) / slope + 0.2
            assert _mean_between(trace, settled, horn_end - 0.02) == pytest.approx(
                on_level, abs=0.4
            )
        else:
            assert not true.reaches_on_level
            deepest = true.off_force_n - slope * (horn_end - horn_start)
            lowest = trace.force_n[trace.time_s > trace.on_windows_s[0][0]].min()
            assert lowest > on_level + 10.0
            assert lowest == pytest.approx(deepest + true.load_cell_offset_n, abs=4.0)


def test_force_is_the_bench_model_plus_noise(simulated):
    """Subtracting the bench model at the true timing leaves zero-mean noise of the set size."""
    dataset, truth = simulated
    p = truth.params
    cell = p.load_cell
    expected_std = math.sqrt(
        cell.white_noise_std_n**2
        + cell.correlated_noise_std_n**2
        + cell.mains_amplitude_n**2 / 2
        + cell.adc_lsb_n**2 / 12
    )
    for trace, true in zip(dataset.traces, truth.traces, strict=True):
        timing = TraceTiming(true.startup_s, *true.horn_on_s)
        model = mean_force_n(
            trace.time_s,
            true.off_force_n,
            true.on_force_n,
            timing,
            p.actuator.slope_n_s,
            p.actuator.startup_slope_n_s,
            true.load_cell_offset_n,
            p.actuator.corner_n,
        )
        residual = trace.force_n - np.asarray(model)
        assert abs(residual.mean()) < 0.2
        assert residual.std() == pytest.approx(expected_std, rel=0.15)


def test_friction_ratio_comes_from_the_bench_functions(simulated):
    _, truth = simulated
    p = truth.params
    for true in truth.traces:
        fr = on_friction_ratio(
            dahl_at_load(
                p.contact.friction_coefficient, p.contact.contact_stiffness_n_m, true.normal_load_n
            ),
            PowerLimitedCoupling(gain=p.coupling.gain, power_load_n=p.coupling.power_load_n),
            true.normal_load_n,
            true.amplitude_fraction,
            p.experiments.pull_speed_m_s,
            p.rig.vibration_frequency_hz,
            p.rig.max_amplitude_m,
        )
        assert true.friction_ratio == pytest.approx(float(fr), rel=1e-12)
        assert true.on_force_n == pytest.approx(true.friction_ratio * true.off_force_n)


def test_quantisation_and_logged_windows(simulated):
    dataset, truth = simulated
    lsb = truth.params.load_cell.adc_lsb_n
    switching = truth.params.horn_switching
    for trace, true in zip(dataset.traces, truth.traces, strict=True):
        steps = trace.force_n / lsb
        np.testing.assert_allclose(steps, np.round(steps), atol=1e-6)
        assert trace.on_windows_s == (true.logged_on_s,)
        for logged, horn in zip(true.logged_on_s, true.horn_on_s, strict=True):
            assert 0.0 <= horn - logged < switching.delay_mean_s + 6 * switching.delay_std_s


# --- the files: --force, nothing half-written, bad parameters -----------------------------


def test_existing_output_needs_force(tmp_path, capsys):
    params = _write_params(tmp_path / "p.json", small_params())
    out = tmp_path / "out"
    out.mkdir()
    (out / "keep.txt").write_text("mine")
    args = ["simulate-bench", "--params", str(params), "--out", str(out), "--seed", "1"]
    assert main(args) == 2
    assert "already exists" in capsys.readouterr().err
    assert folder_fingerprint(out) == {"keep.txt": folder_fingerprint(out)["keep.txt"]}
    assert main([*args, "--force"]) == 0
    assert not (out / "keep.txt").exists()
    assert load_dataset(out).sha256 == simulate_bench(small_params(), 1)[0].sha256


def test_failed_write_leaves_no_half_written_folder(tmp_path, monkeypatch, simulated):
    dataset, truth = simulated
    real_write = idtool._data._write.write_files

    def write_then_fail(folder: Path, files) -> None:
        real_write(folder, dict(list(files.items())[:1]))
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(idtool._data._write, "write_files", write_then_fail)
    with pytest.raises(OSError):
        write_simulation(tmp_path / "new", dataset, truth)
    assert sorted(p.name for p in tmp_path.iterdir()) == []

    old = tmp_path / "old"
    old.mkdir()
    (old / "dataset.json").write_text("{}")
    with pytest.raises(OSError):
        write_simulation(old, dataset, truth, force=True)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["old"]
    assert (old / "dataset.json").read_text() == "{}"


@pytest.mark.parametrize(
    ("edit", "fragments"),
    [
        (
            lambda p: p["contact"].__setitem__("friction_coefficient", -0.3),
            ["contact.friction_coefficient", "> 0"],
        ),
        (
            lambda p: p["experiments"].__setitem__("amplitude_fractions", [50]),
            ["experiments.amplitude_fractions[0]", "divide by 100"],
        ),
        (lambda p: p["coupling"].pop("power_load_n"), ["coupling.power_load_n", "missing"]),
        (
            lambda p: p["load_cell"].__setitem__("white_noise_std", 0.5),
            ["load_cell.white_noise_std", "did you mean 'white_noise_std_n'"],
        ),
        (lambda p: p["output"].__setitem__("trace_format", "xlsx"), ["output.trace_format"]),
    ],
)
def test_bad_parameters_are_located(tmp_path, capsys, edit, fragments):
    params = small_params()
    edit(params)
    path = _write_params(tmp_path / "p.json", params)
    out = tmp_path / "out"
    assert main(["simulate-bench", "--params", str(path), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "Traceback" not in err and str(path) in err
    assert all(f in err for f in fragments), err
    assert not out.exists()
    with pytest.raises(IdtoolError):
        simulate_bench(params, 0)


@pytest.mark.parametrize("content", [None, "{ nope", "[]"])
def test_unreadable_parameter_file(tmp_path, capsys, content):
    path = tmp_path / "p.json"
    if content is not None:
        path.write_text(content)
    assert main(["simulate-bench", "--params", str(path), "--out", str(tmp_path / "o")]) == 2
    assert "p.json" in capsys.readouterr().err


def test_unwritable_output_exits_2(tmp_path, capsys):
    params = _write_params(tmp_path / "p.json", small_params())
    (tmp_path / "file").write_text("")
    out = tmp_path / "file" / "sim"
    assert main(["simulate-bench", "--params", str(params), "--out", str(out)]) == 2
    assert "nothing was written" in capsys.readouterr().err


def test_oversized_matrix_is_refused():
    params = small_params()
    params["experiments"]["sample_rate_hz"] = 1e9
    with pytest.raises(IdtoolError, match="sample_rate_hz"):
        simulate_bench(params, 0)


def test_negative_seed_is_refused():
    with pytest.raises(IdtoolError, match="seed"):
        simulate_bench(small_params(), -1)


def test_params_round_trip():
    document = json.loads(example_params_path().read_text())
    params = load_bench_params(example_params_path())
    assert params.to_dict() == document
    assert BenchParams.from_dict(copy.deepcopy(document)) == params


# --- the shipped example ------------------------------------------------------------------


def test_example_is_reproduced_by_its_command(example_truth):
    dataset, truth = simulate_bench(load_bench_params(example_params_path()), EXAMPLE_SEED)
    shipped = load_dataset(idtool.example_dataset_path())
    for a, b in zip(dataset.traces, shipped.traces, strict=True):
        assert a.id == b.id
        np.testing.assert_array_equal(a.time_s, b.time_s)
        np.testing.assert_array_equal(a.force_n, b.force_n)
        np.testing.assert_array_equal(a.ultrasound_on, b.ultrasound_on)
    for new, old in zip(truth.to_dict()["traces"], example_truth["traces"], strict=True):
        assert new["friction_ratio"] == pytest.approx(old["friction_ratio"], rel=1e-9)


def test_example_truth_matches_the_paper(example_truth):
    assert example_truth["friction_law"] == "dahl"
    assert example_truth["coupling"]["law"] == "power_limited"
    fr = {
        (t["normal_load_n"], t["amplitude_fraction"]): t["friction_ratio"]
        for t in example_truth["traces"]
    }
    assert 0.40 <= fr[(670.0, 0.5)] <= 0.42  # the paper's ~58-60% reduction
    for alpha in (0.5, 0.7):
        assert fr[(270.0, alpha)] < fr[(450.0, alpha)] < fr[(670.0, alpha)]  # more load, less
    assert abs(fr[(450.0, 0.5)] - fr[(450.0, 0.7)]) < 0.03  # the power limit
    for t in example_truth["traces"]:
        assert 1.0 <= t["dimensionless_stiffness"] <= 30.0  # Kt identifiable
        if t["normal_load_n"] == 670.0:
            assert t["reaches_on_level"] == (t["on_duration_s"] >= 2.0)  # paper Figure 2
