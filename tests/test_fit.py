"""The joint fit (issue 4): parameter recovery, identifiability warnings, gradients,
the two-time-scale averaging, and the ``idtool fit`` command."""

import copy
import dataclasses
import json

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from sample_helpers import small_params
from sample_helpers import truth as small_truth
from scipy.integrate import solve_ivp

import idtool
from idtool._cli._main import main
from idtool._data._blocks import padded_size, prepare_fit_data
from idtool._diagnostic import with_code
from idtool._fit._program import lm_program, prediction_at, run_lm
from idtool._fit._reml import evaluate, fit_sds
from idtool._fit._run import fit_dataset
from idtool._model._benchmodel import bench_model

PHYSICAL = ("Kt", "mu", "coupling_gain", "power_load_n")


def example_params() -> dict:
    return json.loads(idtool.example_params_path().read_text())


def truth_of(params: dict) -> dict:
    return {
        "Kt": params["contact"]["contact_stiffness_n_m"],
        "mu": params["contact"]["friction_coefficient"],
        "coupling_gain": params["coupling"]["gain"],
        "power_load_n": params["coupling"]["power_load_n"],
    }


def assert_recovered(run, truth: dict) -> None:
    est = run.chosen.estimates
    for name, value in truth.items():
        lo, hi = est[name].ci95
        assert lo <= value <= hi, f"{name}: truth {value:.4g} outside [{lo:.4g}, {hi:.4g}]"
    assert est["mu"].estimate == pytest.approx(truth["mu"], rel=0.02)


@pytest.fixture(scope="module")
def example_run(example_default_run):
    """``fit_dataset`` of the example with every default, seed 0 (the bank's,
    tests/conftest.py)."""
    return example_default_run


def test_example_dataset_recovers_its_truth(example_run):
    assert_recovered(example_run, truth_of(example_params()))
    for w in example_run.chosen.warnings:  # correlations may be flagged; nothing worse
        assert "bound" not in w and "cannot inform" not in w and "stopped" not in w, w
        assert getattr(w, "code", "") != "profile_interval", w


def test_example_fit_friction_ratios_match_the_simulator(example_run):
    truth = json.loads((idtool.example_dataset_path() / "true_parameters.json").read_text())
    true_fr = np.array([t["friction_ratio"] for t in truth["traces"]])
    r = example_run.chosen
    z = np.abs(r.friction_ratio - true_fr) / r.friction_ratio_se
    assert np.all(z < 4.0)


# the model's whitened residuals as one compiled program, read by the two tests below
# (dispatched op by op, the first call compiled each of the model's operations alone)
_residuals = jax.jit(lambda model, z, phi: model.residuals(z, phi))


def test_whitened_residuals_are_not_autocorrelated(example_run):
    r = example_run.chosen
    w = np.asarray(_residuals(r.model, jnp.asarray(r.z), r.phi))
    lag1 = np.sum(w[1:] * w[:-1]) / np.sum(w * w)
    assert abs(lag1) < 0.1  # the AR(1) model took out the correlation (raw: ~0.5-0.8)
    assert 0.2 < r.phi < 0.95


def test_prediction_from_the_fits_program_is_the_models(example_run):
    """The figures' prediction and whitened residuals come from the fit's compiled
    program run for no step and the residuals un-whitened; they must be the model's
    own ``predict`` and ``residuals`` (to round-off of the AR(1) recursion)."""
    r = example_run.chosen
    pred, w = prediction_at(r.model, r.z, r.phi)
    want_pred = jax.jit(lambda model, z: model.predict(z))(r.model, jnp.asarray(r.z))
    np.testing.assert_allclose(pred, np.asarray(want_pred), atol=1e-9)
    want = np.asarray(_residuals(r.model, jnp.asarray(r.z), r.phi))
    np.testing.assert_allclose(w, want, atol=1e-9)


def test_another_dataset_of_about_the_same_length_runs_the_same_compiled_program(example_run):
    """A dataset's names, hash and notes are not part of the compiled programs' keys
    (DataLabels compare equal), and its blocks are padded to a bucketed count
    (padded_size): another bench with other names and other trace lengths is neither
    traced nor compiled again, its own data (not the first one's) go in, and the padding
    changes no residual."""
    dataset = idtool.load_dataset(idtool.example_dataset_path())

    def other_bench(i, tr):  # 1% more force; the last 0.1 s of every other trace cut
        keep = slice(None, -100) if i % 2 else slice(None)
        return dataclasses.replace(
            tr,
            id=f"{tr.id}_b",
            time_s=tr.time_s[keep],
            force_n=1.01 * tr.force_n[keep],
            ultrasound_on=tr.ultrasound_on[keep],
        )

    traces = tuple(other_bench(i, tr) for i, tr in enumerate(dataset.traces))
    other = dataclasses.replace(dataset, name="another bench", sha256="0" * 64, traces=traces)
    data = example_run.data
    model = bench_model(data)
    twin = bench_model(prepare_fit_data(other, mains_hz=data.mains_hz, periods_per_block=2))
    assert twin.data.trace_ids != model.data.trace_ids
    assert twin.data.n_blocks < model.data.n_blocks
    assert padded_size(twin.data.n_blocks) == padded_size(model.data.n_blocks)
    z = np.asarray(model.z0())
    mask = np.ones(z.size, bool)
    first = run_lm(model, z, mask, 0.0, 0)
    size = lm_program._cache_size()
    second = run_lm(twin, z, mask, 0.0, 0)
    assert lm_program._cache_size() == size
    assert np.asarray(second.residuals).size == twin.data.n_blocks
    # the padded program's residuals are the model's own, unpadded
    want = np.asarray(jax.jit(lambda m, z: m.residuals(z, 0.0))(twin, z))
    np.testing.assert_allclose(np.asarray(second.residuals), want, atol=1e-9)
    assert float(second.loss) == pytest.approx(0.5 * float(want @ want), rel=1e-12)
    # every force 1% larger (a constant shift would go into the offsets' centres)
    n = twin.data.n_blocks
    assert not np.allclose(np.asarray(first.residuals)[:n], np.asarray(second.residuals))


def test_the_programs_compiled_ahead_are_the_ones_the_fit_runs():
    """The fit compiles the next candidates' and the levels model's programs in a thread
    (idtool._fit._prefetch) with arguments of the types the fit's own calls take: had
    one differed (a weak type, a dtype), its program would be compiled twice."""
    jax.clear_caches()
    run = fit_dataset(idtool.load_dataset(idtool.example_dataset_path()), seed=0)
    assert len(run.candidates) == 3  # slope, lag; drifting offset on the best
    assert lm_program._cache_size() == len(run.candidates)
    assert fit_sds._cache_size() == 1
    assert evaluate._cache_size() == 2  # the grid, and one row (_reml.at_sds)


def test_short_on_windows_that_never_reach_the_on_level():
    params = example_params()
    params["experiments"]["on_durations_s"] = [0.5, 1.0]
    params["experiments"]["normal_loads_n"] = [270.0, 670.0]
    dataset, truth = idtool.simulate_bench(params, seed=7)
    reached = [t.reaches_on_level for t in truth.traces]
    assert not all(reached)  # the point of the test: several ON levels are never seen
    run = fit_dataset(dataset, seed=1)
    assert_recovered(run, truth_of(params))
    # With two loads and short windows Kt is barely identified, and the reported
    # interval must say so: either the Gauss-Newton one already spans the range
    # ("uninformed"; here since the OFF switch's corner is rounded, issue 28) or, where
    # it was far too narrow ([1.4e8, 7.3e8], missing the truth, with the corner
    # unrounded), the likelihood check sees it and reports the profile interval.
    wide = with_code(run.chosen.warnings, "profile_interval", "uninformed")
    assert "Kt" in [w.values["parameter"] for w in wide]
    lo, hi = run.chosen.estimates["Kt"].ci95
    assert hi / lo > 100.0


def test_a_spurious_multistart_basin_does_not_win():
    """Small two-load designs (tests/sample_helpers.py) have a second basin at Kt ~ 8e7
    whose loss is close to the true one's (RSS 94.8 against 91.5 for seed 0). Ranked
    with the nuisances held at their start values it came first on several seeds; the
    joint multi-start finds the true basin (10 of 10 seeds when measured)."""
    for seed in (0, 3):
        dataset, _ = idtool.simulate_bench(small_params(), seed=seed)
        run = fit_dataset(dataset, seed=0)
        assert len(run.chosen.optima) >= 2
        assert_recovered(run, {k: v for k, v in small_truth().items() if k in PHYSICAL})


def test_the_multistart_finds_the_basin_where_its_starts_crawl():
    """Truth 2 of the laws study (tests/data/laws_study_crawling_starts.json: the paper's
    24 pulls plus 10 planned at 10-20% amplitude, exponential coupling, 3.9% pull-to-pull
    scatter), simulated with seed 1002. From 8 unscreened starts every run was still
    crawling after its 20 steps, and the lowest of them led to Kt at its bound (1e13 N/m,
    2.2e4 x the truth; log-likelihood -4412 against -2833), as on 3 of the seeds
    1000-1005; the starts screened by their loss at the start reach the optimum that the
    truth's own start reaches (or a better one) on all 6."""
    import warnings
    from pathlib import Path

    from idtool._model._settings import ParameterSetting
    from idtool._simulate._params import BenchParams
    from idtool._simulate._simulate import simulate_bench
    from idtool._study._truths import Truth, design_points, truth_params

    task = json.loads(
        (Path(__file__).parent / "data" / "laws_study_crawling_starts.json").read_text()
    )
    truth = Truth.from_dict(task["truth"])
    doc = truth_params(truth, task["base"], task["rig"], task["friction_law"], task["departure"])
    dataset, _ = simulate_bench(
        BenchParams.from_dict(doc, "the laws study's truth 2"),
        int(task["seed"]),
        design_points(task["points"]),
    )
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        run = fit_dataset(dataset, seed=0, coupling=truth.law, variability=False)
        at_truth = tuple(ParameterSetting(n, nominal=float(v)) for n, v in truth.values.items())
        reference = fit_dataset(
            dataset, seed=0, coupling=truth.law, variability=False, settings=at_truth
        )
    fit = run.chosen
    # at least the likelihood of the optimum the truth's own start reaches (both -2833.4
    # here; the unscreened multi-start fell 1,578 short)
    assert fit.loglik >= reference.chosen.loglik - 0.5
    assert not with_code(fit.warnings, "bound")
    assert 0.5 < fit.estimates["Kt"].estimate / truth.values["Kt"] < 2.0


def test_single_load_warns_that_the_coupling_cannot_be_told_apart():
    params = example_params()
    params["experiments"]["normal_loads_n"] = [450.0]
    params["experiments"]["on_durations_s"] = [1.0, 2.5]
    dataset, _ = idtool.simulate_bench(params, seed=3)
    # one actuator and offset model (the data's), no levels model: the warning (the
    # coupling's shape against one load) and the choice of the constant law are rules
    # of the fit on the coupling alone, whatever nuisance models it compares
    one = {"actuator": "slope", "offset": "constant", "variability": False}
    limited = fit_dataset(dataset, coupling="power-limited", seed=0, **one)
    assert any("cannot be told apart" in w for w in limited.chosen.warnings)
    auto = fit_dataset(dataset, coupling="auto", seed=0, **one)
    assert auto.chosen.model.coupling.name == "constant"
    assert "one normal load" in auto.reason


def test_loss_gradient_matches_finite_differences(example_run):
    model = example_run.chosen.model
    z = jnp.asarray(example_run.chosen.z) + 0.01  # off the optimum: a non-zero gradient

    def loss(zz):
        return 0.5 * jnp.sum(model.residuals(zz, 0.5) ** 2)

    grad = np.asarray(jax.jit(jax.grad(loss))(z))
    f = jax.jit(loss)
    for i in (0, 1, 2, 3, 4, model.n_shared, model.n_shared + 2 * model.data.n_traces):
        h = 1e-6
        fd = (float(f(z.at[i].add(h))) - float(f(z.at[i].add(-h)))) / (2 * h)
        assert grad[i] == pytest.approx(fd, rel=1e-4, abs=1e-6), model.names[i]


def test_cycle_average_matches_brute_force_fast_dynamics():
    """The two time scales: simulate the 20 kHz Dahl contact in time over a short
    window (LSODA, the raw sgn ODE) from the OFF state; after a few cycles its running
    mean is the cycle-averaged ON level the bench model uses."""
    mu, kt, load, alpha, speed = 0.3, 1e9, 450.0, 0.5, 0.025
    coupling = idtool._model._coupling.PowerLimitedCoupling(gain=0.03, power_load_n=125.0)
    a = float(coupling.amplitude_m(alpha, load, 85e-6))
    w = 2 * np.pi * 20e3
    fc = mu * load
    law = idtool.Dahl(fc_n=fc, kt_n_m=kt)
    fr = float(
        idtool._model._bench.on_friction_ratio(law, coupling, load, alpha, speed, 20e3, 85e-6)
    )

    def rhs(t, y):
        v = speed + a * w * np.cos(w * t)
        return [kt * v * (1 - np.sign(v) * y[0] / fc), y[0]]

    cycles = 40
    t_end = cycles * 2 * np.pi / w
    sol = solve_ivp(
        rhs,
        [0, t_end],
        [fc, 0.0],
        method="LSODA",
        rtol=1e-9,
        atol=1e-9,
        max_step=t_end / cycles / 200,
        dense_output=True,
    )
    t1 = 20 * 2 * np.pi / w  # transient gone after a few cycles
    mean = (sol.sol(t_end)[1] - sol.sol(t1)[1]) / (t_end - t1)
    assert mean / fc == pytest.approx(fr, abs=2e-4)


def test_fit_command_writes_fit_json_and_refuses_to_overwrite(tmp_path, capsys):
    params = example_params()
    params["experiments"]["normal_loads_n"] = [270.0, 670.0]
    params["experiments"]["on_durations_s"] = [2.0]
    dataset, _ = idtool.simulate_bench(params, seed=11)
    data_dir = idtool.write_dataset(dataset, tmp_path / "data")
    out = tmp_path / "fits" / "small"
    assert main(["fit", str(data_dir), "--out", str(out), "--seed", "4"]) == 0
    doc = json.loads((out / "fit.json").read_text())
    for name in PHYSICAL:
        p = doc["parameters"][name]
        assert set(p) >= {"estimate", "std_error", "ci95", "unit"}
        assert p["ci95"][0] <= p["estimate"] <= p["ci95"][1]
    assert doc["parameters"]["Kt"]["unit"] == "N/m" and doc["parameters"]["mu"]["unit"] == "1"
    assert doc["law"] == "dahl" and doc["coupling"] == "power-limited"
    assert doc["dataset"]["sha256"] == dataset.sha256
    assert doc["seed"] == 4 and "idtool fit" in doc["command"]
    assert {"aic", "bic", "n_data", "idtool_version"} <= set(doc)
    for png in ("traces.png", "residuals.png"):
        assert (out / png).read_bytes()[:4] == b"\x89PNG"
    out_text, progress = capsys.readouterr()
    assert "[[Physical parameters]]" in out_text
    # progress on stderr, a line per stage: each candidate, intervals, levels model
    assert "idtool fit: [" in progress and "fitting dahl/power-limited/slope/constant" in progress
    assert "scatter and the model discrepancy" in progress

    before = (out / "fit.json").read_bytes()
    assert main(["fit", str(data_dir), "--out", str(out)]) == 2
    assert "--force" in capsys.readouterr().err
    assert (out / "fit.json").read_bytes() == before
    assert sorted(p.name for p in out.parent.iterdir()) == ["small"]  # no leftovers

    # --json: fit.json on stdout and nothing else, for scripts
    assert main(["fit", str(data_dir), "--out", str(out), "--force", "--json", "-q"]) == 0
    printed, progress = capsys.readouterr()
    assert json.loads(printed) == json.loads((out / "fit.json").read_text())
    assert progress == ""  # --quiet: no progress either


def test_fit_command_on_bad_data_writes_nothing(tmp_path, capsys):
    bad = tmp_path / "bad"
    bad.mkdir()
    (bad / "dataset.json").write_text("{not json")
    out = tmp_path / "fits" / "x"
    assert main(["fit", str(bad), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "dataset.json" in err and "Traceback" not in err
    assert not out.exists()


def test_same_seed_same_fit():
    params = example_params()
    params["experiments"]["normal_loads_n"] = [270.0, 670.0]
    params["experiments"]["on_durations_s"] = [2.0]
    dataset, _ = idtool.simulate_bench(params, seed=5)
    a = fit_dataset(dataset, seed=2)
    b = fit_dataset(copy.deepcopy(dataset), seed=2)
    np.testing.assert_array_equal(a.chosen.z, b.chosen.z)
    model = bench_model(a.data)
    assert model.names == a.chosen.model.names


def small_dataset(seed: int, **experiments):
    params = example_params()
    params["experiments"]["normal_loads_n"] = [270.0, 670.0]
    params["experiments"]["on_durations_s"] = [2.0]
    params["experiments"].update(experiments)
    return idtool.simulate_bench(params, seed=seed)


def test_profile_likelihood_agrees_with_the_gauss_newton_interval():
    dataset, _ = small_dataset(21)
    # the profile is of the traces' likelihood: compare it with the noise-only fit
    run = fit_dataset(dataset, seed=0, profile=True, variability=False)
    for name in PHYSICAL:
        prof = run.profiles[name]
        est = run.chosen.estimates[name]
        assert prof.ci95[0] < est.estimate < prof.ci95[1]
        assert prof.delta.min() == pytest.approx(0.0, abs=0.05)  # refits reach the optimum
        # Near-linear problem: the profile and Wald widths agree to within a factor 1.5.
        ratio = (prof.ci95[1] - prof.ci95[0]) / (est.ci95[1] - est.ci95[0])
        assert 1 / 1.5 < ratio < 1.5, (name, ratio)


def test_lugre_fit_runs_and_ranks_against_dahl():
    dataset, _ = small_dataset(22)
    run = fit_dataset(dataset, seed=0, compare_laws=True, actuator="slope", offset="constant")
    assert set(run.candidates) == {
        "dahl/power-limited/slope/constant",
        "lugre/power-limited/slope/constant",
    }
    lugre = run.candidates["lugre/power-limited/slope/constant"]
    assert {"static_ratio", "stribeck_velocity_m_s"} <= set(lugre.model.physical_names)
    # The data come from Dahl: LuGre's two extra parameters cannot win by BIC.
    assert run.chosen.model.law.name == "dahl"


def test_multistart_points_are_seeded_and_evenly_spread():
    from scipy.stats import qmc

    from idtool._fit._fit import quasi_random

    a, b = quasi_random(64, 4, seed=1), quasi_random(64, 4, seed=1)
    np.testing.assert_array_equal(a, b)
    assert not np.array_equal(a, quasi_random(64, 4, seed=2))
    assert a.shape == (64, 4) and np.all((a >= 0.0) & (a < 1.0))
    # Every coordinate covers [0, 1) evenly: the largest gap (around the circle) stays
    # below 3/n (measured 1.9/n; 64 uniform random points leave about 5/n).
    for column in a.T:
        ring = np.sort(column)
        gaps = np.diff(np.concatenate([ring, ring[:1] + 1.0]))
        assert gaps.max() < 3.0 / 64
    # Quasi-random: the centred L2 discrepancy is far below that of random points
    # (measured 0.003 against 0.018 on average).
    rng = np.random.default_rng(0)
    random = np.mean([qmc.discrepancy(rng.random((64, 4))) for _ in range(20)])
    assert qmc.discrepancy(a) < 0.5 * random
