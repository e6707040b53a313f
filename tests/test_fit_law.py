"""idtool fit-law (issue 30, item 3): the series integrator against LSODA, recovery of
simulated LuGre series, identifiability statements, the command line and its errors.

Every fit here uses 3,001-sample series of the same laws, so the compiled programs are
shared (about 20 s of compilation on a loaded 2-core machine, then ~1-4 s a fit)."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest
from scipy.integrate import solve_ivp

import idtool
from idtool._cli import main
from idtool._model._series_force import series_force
from idtool._model._series_law import series_law
from idtool._simulate._series import LUGRE_TRUTH

TRUTH = LUGRE_TRUTH


def _lsoda_force(t, v, values):
    """LuGre force by LSODA on z (notes §1), V linear between the samples as in the
    integrator, at rtol 1e-10: an independent reference."""
    kt, fc = values["Kt"], values["Fc"]
    fs, vs = fc * values["static_ratio"], values["stribeck_velocity_m_s"]

    def g(vel):
        return (fc + (fs - fc) * np.exp(-((vel / vs) ** 2))) / kt

    def rhs(tt, z):
        vel = np.interp(tt, t, v)
        return [vel - abs(vel) * z[0] / g(vel)]

    sol = solve_ivp(
        rhs,
        (t[0], t[-1]),
        [0.0],
        method="LSODA",
        t_eval=t,
        rtol=1e-10,
        atol=1e-16,
        max_step=float(np.min(np.diff(t))),
    )
    z = sol.y[0]
    return kt * z + values["sigma1"] * (v - np.abs(v) * z / g(v)) + values["sigma2"] * v


@pytest.mark.parametrize(
    ("amplitude_m", "substeps", "tol_n"),
    [
        # presliding (3 um, below Vs throughout): LuGre's level is constant there, so
        # the update is exact and the difference is LSODA's own error
        (3e-6, 1, 1e-6),
        # sliding through the Stribeck region (the simulator's default amplitude, V up
        # to 31 Vs): second order in the piece; 1.8e-5 N measured at 4 parts per 1 ms
        # sample. The bound is 1% of the tests' 0.01 N noise sd: an error that size
        # adds 1e-4 of the noise variance, nothing an interval can show
        (1e-2, 4, 1e-4),
    ],
)
def test_integrator_matches_lsoda(amplitude_m, substeps, tol_n):
    law = series_law("lugre", with_load=False)
    t = np.arange(0.0, 2.0, 1e-3)
    w = 2 * np.pi * 1.0
    v = amplitude_m * w * np.sin(w * t)
    force, _ = series_force(law.law_at, TRUTH, t, v, 1.0, substeps=substeps)
    ref = _lsoda_force(t, v, TRUTH)
    assert np.max(np.abs(np.asarray(force) - ref)) < tol_n
    if substeps > 1:  # second order: one part per interval is ~4x worse per halving
        coarse, _ = series_force(law.law_at, TRUTH, t, v, 1.0, substeps=substeps // 2)
        assert np.max(np.abs(np.asarray(coarse) - ref)) > 2.5 * np.max(
            np.abs(np.asarray(force) - ref)
        )


def test_dahl_exact_on_displacement_steps():
    """Dahl's update is exact for any step (notes §4): on a piecewise-linear
    displacement, one piece per coarse sample gives the fine grid's force."""
    law = series_law("dahl", with_load=False)
    values = {"Fc": 1.0, "Kt": 1e5}
    t = np.linspace(0.0, 1.0, 11)
    x = 2e-5 * np.sin(2 * np.pi * t)
    fine_t = np.linspace(0.0, 1.0, 1001)
    fine_x = np.interp(fine_t, t, x)
    iv = np.diff(x) / np.diff(t)
    coarse, _ = series_force(
        law.law_at, values, t, np.zeros_like(t), 1.0, interval_velocity_m_s=iv, substeps=1
    )
    fine_iv = np.diff(fine_x) / np.diff(fine_t)
    fine, _ = series_force(
        law.law_at,
        values,
        fine_t,
        np.zeros_like(fine_t),
        1.0,
        interval_velocity_m_s=fine_iv,
        substeps=1,
    )
    assert np.allclose(np.asarray(coarse), np.asarray(fine)[::100], atol=1e-12)


def _inside(fit, name, truth):
    lo, hi = fit.estimates[name].ci95
    return lo <= truth <= hi


def test_recovers_sliding_lugre():
    series = idtool.simulate_series("lugre", kind="sliding", seed=11)
    fit = idtool.fit_law(series, "lugre")
    for name, truth in TRUTH.items():
        e = fit.estimates[name]
        assert e.one_sided == "" and not e.weakly_identified, name
        # inside the 95% interval, and within 4 standard errors (a 1-in-16,000 miss)
        assert _inside(fit, name, truth), (name, e)
        assert abs(e.estimate - truth) < 4 * e.std_error, (name, e)
    assert abs(fit.noise_sd_n - 0.01) < 0.001  # the simulated noise
    assert fit.optimum.phi == 0.0  # white residuals: no whitening
    # a cell that does not lag: tested for, not fitted
    assert fit.lag_check is not None and fit.lag_check.p_value > 0.01
    assert fit.sensor_lag_s is None and "sensor_lag_s" not in fit.to_json()["nuisance"]


def test_presliding_states_what_it_cannot_inform():
    """Presliding at 3 um (max 19 um/s, far below Vs = 2 mm/s): the level is Fs
    throughout, so Fc and Fs/Fc are known only as their product, Vs not at all, and the
    viscous term (20 N s/m x 19 um/s = 0.4 mN beside 10 mN of noise) is not seen."""
    series = idtool.simulate_series("lugre", kind="presliding", seed=12)
    fit = idtool.fit_law(series, "lugre")
    kt = fit.estimates["Kt"]
    assert kt.one_sided == "" and _inside(fit, "Kt", TRUTH["Kt"])
    # sigma1 V is 5.7 mN at most here, beside 10 mN of noise: bounded on both sides on
    # some seeds, from above only on others; the truth inside either way
    assert _inside(fit, "sigma1", TRUTH["sigma1"])
    for name in ("Fc", "static_ratio", "stribeck_velocity_m_s", "sigma2"):
        e = fit.estimates[name]
        assert e.one_sided or e.weakly_identified, (name, e)
        assert np.isnan(e.std_error)  # stated, not printed with a huge SE
        assert any(w in fit.statements[name] for w in ("identified", "not bounded"))
        assert name in fit.report() and f"{name}:" in "\n".join(fit.warnings)
        assert _inside(fit, name, TRUTH[name])
    fs = fit.estimates["Fc"].estimate * fit.estimates["static_ratio"].estimate
    assert abs(fs / (TRUTH["Fc"] * TRUTH["static_ratio"]) - 1) < 0.05  # their product


def test_dahl_from_displacement_with_load():
    """The displacement input and the mu-scaled level (a normal-load column)."""
    truth = {"mu": 0.2, "Kt": 1e5}
    series = idtool.simulate_series(
        "dahl",
        truth,
        kind="sliding",
        amplitude_m=2e-4,
        normal_load_n=5.0,
        slip_input="displacement",
        seed=13,
    )
    fit = idtool.fit_law(series, "dahl")
    for name, value in truth.items():
        assert _inside(fit, name, value), fit.report()


def _write(path, text):
    path.write_text(text)
    return path


def test_cli_writes_refuses_and_locates(tmp_path, capsys):
    series = idtool.simulate_series("coulomb-viscous", {"Fc": 1.0, "sigma2": 20.0}, seed=14)
    rows = "\n".join(
        f"{t:.6f},{v * 1e3:.9g},{f:.9g}"
        for t, v, f in zip(series.time_s, series.velocity_m_s, series.force_n, strict=True)
    )
    good = _write(tmp_path / "s.csv", "time [s],velocity [mm/s],force [N]\n" + rows + "\n")
    out = tmp_path / "out"
    assert main(["fit-law", str(good), "--law", "coulomb-viscous", "--out", str(out)]) == 0
    data = json.loads((out / "fit_law.json").read_text())
    assert data["law"] == "coulomb-viscous" and data["series"]["n_samples"] == 3001
    assert data["parameters"]["sigma2"]["ci95"][0] < 20.0 < data["parameters"]["sigma2"]["ci95"][1]
    assert (out / "fit_law.png").stat().st_size > 10_000 and (out / "report.txt").exists()
    assert main(["fit-law", str(good), "--law", "coulomb-viscous", "--out", str(out)]) == 2
    assert "already exists" in capsys.readouterr().err

    missing = _write(tmp_path / "m.csv", "time [s],force [N]\n0,1\n1,2\n")
    assert main(["fit-law", str(missing), "--out", str(tmp_path / "o2")]) == 2
    err = capsys.readouterr().err
    assert "no velocity column" in err and "m.csv" in err and "row 0" in err

    lines = ["time [s],velocity [m/s],force [N]"] + [f"{k},0.1,1.0" for k in range(30)]
    lines[8] = "7,0.1,abc"
    bad = _write(tmp_path / "b.csv", "\n".join(lines) + "\n")
    assert main(["fit-law", str(bad), "--out", str(tmp_path / "o3")]) == 2
    err = capsys.readouterr().err
    assert (
        "b.csv, row 8, column 'force [N]'" in err
        and "(line 9)" in err
        and "'abc' is not a number" in err
    )
    assert not (tmp_path / "o2").exists() and not (tmp_path / "o3").exists()


def test_the_simulated_departures_are_what_they_say():
    """simulate_series' measuring-chain departures (benchmarks/study_benches.py), against
    what each claims: the lagged force is a first-order sensor's steady response to a
    sine (amplitude 1/sqrt(1 + (w tau)^2), phase -atan(w tau): closed form); the
    coloured noise's lag-1 correlation 0.9; the hum a 60 Hz line of 2 noise sds; the
    drift 5 noise sds at the end."""
    from idtool._simulate._series import HUM_HZ, LAG_S

    f_hz, a_m, viscous = 200.0, 1e-4, 20.0
    w = 2 * np.pi * f_hz
    kw = dict(amplitude_m=a_m, frequency_hz=f_hz, duration_s=0.05, rate_hz=1e4, noise_n=0.0)
    # a viscous force, 20 V (Fc negligible): a pure sine
    s = idtool.simulate_series("coulomb-viscous", {"Fc": 1e-9, "sigma2": viscous},
                               departure="lag", **kw)  # fmt: skip
    wt = w * LAG_S
    steady = viscous * a_m * w / np.sqrt(1 + wt**2) * np.sin(w * s.time_s - np.arctan(wt))
    late = s.time_s > 20 * LAG_S  # the transient exp(-t / tau) gone
    # 4.4e-5 N of 2.5 N measured: the force linear between the fine grid's samples
    assert np.max(np.abs(s.force_n - steady)[late]) < 1e-4

    clean = idtool.simulate_series("lugre", kind="sliding", noise_n=0.0, seed=5)
    noise = {}
    for dep in ("coloured", "hum", "drift"):
        noise[dep] = idtool.simulate_series("lugre", kind="sliding", departure=dep,
                                            seed=5).force_n - clean.force_n  # fmt: skip
    c = noise["coloured"]
    assert np.corrcoef(c[1:], c[:-1])[0, 1] == pytest.approx(0.9, abs=0.03)
    t = clean.time_s
    hum = noise["hum"] - c
    assert np.max(np.abs(hum)) == pytest.approx(0.02, rel=0.01)
    assert abs(np.dot(hum, np.exp(2j * np.pi * HUM_HZ * t))) / t.size == pytest.approx(
        0.01, rel=0.02
    )
    drift = noise["drift"] - c
    assert drift[0] == pytest.approx(0.0, abs=1e-12) and drift[-1] == pytest.approx(0.05)
    with pytest.raises(ValueError, match="departure"):
        idtool.simulate_series("lugre", departure="wobble")


def test_a_load_cell_offset_and_drift_are_fitted_not_read_as_friction():
    """A tared cell 0.2 N off that drifts by 0.1 N over the record (20 and 10 noise sds,
    a fifth and a tenth of Fc): fitted as the offset_n and drift_n nuisances, every LuGre
    truth inside its interval; without them the offset would shift the Coulomb level's
    two signs apart."""
    series = idtool.simulate_series("lugre", kind="sliding", seed=11)
    t = series.time_s
    shifted = dataclasses.replace(
        series, force_n=series.force_n + 0.2 + 0.1 * (t - t[0]) / (t[-1] - t[0])
    )
    fit = idtool.fit_law(shifted, "lugre")
    for name, truth in TRUTH.items():
        assert _inside(fit, name, truth), (name, fit.estimates[name])
    nuisance = fit.to_json()["nuisance"]
    assert nuisance["offset_n"] == pytest.approx(0.2, abs=0.01)
    assert nuisance["drift_n"] == pytest.approx(0.1, abs=0.02)
    assert abs(fit.noise_sd_n - 0.01) < 0.001


def test_a_fit_compiles_one_lm_program_per_model():
    """Every Levenberg-Marquardt call of a model runs the same number of rows (the
    multi-start's best, the profile's refits, the AR(1) refits) with the same argument
    types: one compiled program per series shape, law and model (two before, 2-5 s of
    a first 10,000-sample fit: the main solve passed one argument fewer). The models are
    two: without and with the load cell's lag, which every fit tests for."""
    from idtool._lawfit import _solve

    series = idtool.simulate_series("lugre", kind="sliding", duration_s=1.234, seed=3)
    before = _solve._lm_batch._cache_size()
    fit = idtool.fit_law(series, "lugre")
    assert _solve._lm_batch._cache_size() - before == 2
    assert all(np.isfinite(e.ci95).all() for e in fit.estimates.values())


def test_the_lag_integrates_a_first_order_sensor_exactly():
    """A Coulomb-viscous contact under a velocity ramp, ``F = Fc + c_v (v0 + a t)``,
    through the sensor ``tau y' + y = F`` from ``y(0) = F(0)``: the closed form
    ``y = F - c_v a tau (1 - exp(-t / tau))``. The integrator's update is exact for a
    force linear over each part, so only rounding separates them."""
    law = series_law("coulomb-viscous", with_load=False)
    values = {"Fc": 0.7, "sigma2": 3.0}
    t = np.linspace(0.0, 0.05, 201)
    v0, a, tau = 0.01, 2.0, 3e-3
    v = v0 + a * t
    kwargs = dict(extra_viscous_n_s_m=law.extra_viscous_n_s_m(values), substeps=3)
    # the bristle force at its level from the start (rigid Coulomb): F linear in t
    force, _ = series_force(law.law_at, values, t, v, 1.0, 0.7, **kwargs)
    lagged, _ = series_force(law.law_at, values, t, v, 1.0, 0.7, lag_s=tau, **kwargs)
    c_v = float(np.asarray(force)[1] - np.asarray(force)[0]) / (a * (t[1] - t[0]))
    expected = np.asarray(force) - c_v * a * tau * (1.0 - np.exp(-t / tau))
    assert np.max(np.abs(np.asarray(lagged) - expected)) < 1e-12
    assert np.max(np.abs(np.asarray(lagged) - np.asarray(force))) > 1e-2  # it lags


def test_the_lag_matches_the_simulators_sensor_on_a_sliding_lugre_series():
    """The fit's lag (on the integrator's parts) against the simulator's (a NumPy loop
    on a grid 8 times finer, then decimated), noise-free: within 5e-4 N of a 0.17 N lag
    effect (0.05 of the tests' noise sd; filtering the samples instead, the force taken
    linear between them, erred by 5.4e-3 N at the reversals' kinks)."""
    from idtool._simulate._series import LAG_S

    clean = idtool.simulate_series("lugre", kind="sliding", noise_n=1e-12, seed=1)
    lag = idtool.simulate_series("lugre", kind="sliding", departure="lag", noise_n=1e-12, seed=1)
    law = series_law("lugre", with_load=False)
    values = {k: TRUTH[k] for k in law.names}
    kwargs = dict(extra_viscous_n_s_m=law.extra_viscous_n_s_m(values), substeps=4)
    t, v = clean.time_s, clean.velocity()
    model, _ = series_force(law.law_at, values, t, v, 1.0, lag_s=LAG_S, **kwargs)
    assert np.max(np.abs(lag.force_n - clean.force_n)) > 0.1
    assert np.max(np.abs(np.asarray(model) - lag.force_n)) < 5e-4


@pytest.mark.parametrize("lag_s", [0.5e-3, 0.05e-3])
def test_a_lagging_load_cell_is_fitted_not_read_as_bristle_dynamics(lag_s, monkeypatch):
    """A load cell of 0.5 ms (and 0.05 ms) at 1 kHz: without the lag the fit read it as
    a stiffer contact (Kt 1.8x its truth at 0.5 ms, 3% low at 0.05 ms: 3 standard
    errors) and missed Kt on 8 of 8 series. The likelihood ratio keeps the lag, every
    truth lies inside its interval, the lag is found to 20%, and the report says so."""
    import idtool._simulate._series as simulated

    monkeypatch.setattr(simulated, "LAG_S", lag_s)
    series = idtool.simulate_series("lugre", kind="sliding", departure="lag", seed=1004)
    fit = idtool.fit_law(series, "lugre")
    assert fit.lag_check is not None and fit.lag_check.p_value < 1e-3
    assert fit.sensor_lag_s == pytest.approx(lag_s, rel=0.2 if lag_s > 1e-4 else 0.5)
    for name, truth in TRUTH.items():
        assert _inside(fit, name, truth), (name, fit.estimates[name])
    assert fit.to_json()["nuisance"]["sensor_lag_s"] == fit.sensor_lag_s
    assert any("load cell lags" in w for w in fit.warnings)
    assert "sensor lag         = " in fit.report()


def test_a_lagging_cell_under_presliding_leaves_the_damping_unbounded_not_wrong():
    """A presliding loop through a 0.5 ms load cell: the lag is the damping
    ``-tau Kt dz/dt`` there (-50 N s/m), which the likelihood ratio cannot tell from
    sigma1, so the lag is not kept and sigma1 and sigma2 share the rest. The optimum put
    sigma1 deep in its sigmoid's tail (z = -13.7, at its range's floor), where the
    profile's refits had no gradient to move it, and sigma2 was stated [167, 390] N s/m
    against 20. From the range's edge the refits hand the damping back to sigma1 (the
    rise at 20 is 3.06): sigma2 is stated not bounded below, its truth inside."""
    series = idtool.simulate_series("lugre", kind="presliding", departure="lag", seed=1000)
    fit = idtool.fit_law(series, "lugre")
    assert fit.sensor_lag_s is None
    s2 = fit.estimates["sigma2"]
    assert s2.one_sided and _inside(fit, "sigma2", TRUTH["sigma2"]), s2.statement
    for name in ("Kt", "sigma1"):
        assert _inside(fit, name, TRUTH[name]), fit.estimates[name].statement


@pytest.mark.parametrize("law", ["lugre", "dahl", "coulomb-viscous", "dahl-viscous"])
@pytest.mark.parametrize("lag", [False, True])
def test_the_fits_jacobian_is_forward_mode_through_the_whole_model(law, lag):
    """The fit's Jacobian (:meth:`Model.linearised`) takes forward derivatives through
    the integration in the parameters the state depends on only (LuGre without a lag:
    5 of 9; the damping, viscous terms and the cell's zero enter the output equation
    alone, paper eq. 3), then the output by the chain rule. Against ``jax.jacfwd`` of
    the residuals in every parameter, at a point off the starts (AR(1)-whitened): equal
    to rounding. A law whose state read sigma1 or sigma2 would fail here."""
    import jax
    import jax.numpy as jnp

    from idtool._lawfit._problem import make_problem

    series = idtool.simulate_series("lugre", kind="sliding", duration_s=0.5, seed=3)
    problem = make_problem(series, law, lag=lag)
    model, data = problem.model, problem.data
    rng = np.random.default_rng(0)
    start = np.array([p.internal(p.start) for p in problem.params])
    z = jnp.asarray(start + 0.3 * rng.standard_normal(start.size))
    r, j = jax.jit(lambda zz: model.linearised(data, zz, 0.4))(z)
    want_r = jax.jit(lambda zz: model.residuals(data, zz, 0.4))(z)
    want_j = jax.jit(jax.jacfwd(lambda zz: model.residuals(data, zz, 0.4)))(z)
    assert np.max(np.abs(np.asarray(r - want_r))) < 1e-12
    assert np.max(np.abs(np.asarray(j - want_j))) < 1e-10 * np.max(np.abs(np.asarray(want_j)))
    assert len(model.state_index) < len(problem.params)


def test_the_integrator_composes_the_piece_updates_in_order():
    """The integrator composes each interval's affine piece maps before the scan
    (:func:`piece_map`); the same updates applied one piece at a time in a NumPy loop
    (notes §4, ``fb <- s L + (fb - s L) exp(-Kt |du| / L)``, the benchmark's reference)
    give the same LuGre bristle force through reversals and the Stribeck region."""
    from benchmarks.bench_fit_law import numpy_force

    series = idtool.simulate_series("lugre", kind="sliding", duration_s=1.0, seed=5)
    t, v = series.time_s, series.velocity()
    law = series_law("lugre", with_load=False)
    values = {k: TRUTH[k] for k in law.names}
    force, _ = series_force(law.law_at, values, t, v, 1.0, substeps=4)
    p = [TRUTH[k] for k in ("Fc", "Kt", "static_ratio", "stribeck_velocity_m_s")]
    want = numpy_force([*p, TRUTH["sigma1"], TRUTH["sigma2"]], t, v)
    assert np.sum(np.diff(np.sign(v)) != 0) >= 2  # through reversals
    assert np.max(np.abs(np.asarray(force) - want)) < 1e-12 * np.max(np.abs(want))


def test_the_multi_start_stops_starts_that_cannot_win():
    """The main solve stops a start once its Gauss-Newton model cannot beat the best
    converged start by the refits' tolerance (``_dominated``). On a sliding LuGre series
    every start run to its end reaches the same optimum in more steps: the same loss to
    0.01 of a residual variance, and the same point to 0.02 standard errors (each run
    stops within sqrt(MAIN_DECREMENT) = 0.01 of them; 0.002 measured)."""
    from idtool._lawfit import _solve
    from idtool._lawfit._problem import batch_loss, make_problem, start_grid

    series = idtool.simulate_series("lugre", kind="sliding", duration_s=3.0, seed=7)
    problem = make_problem(series, "lugre")
    lm = _solve._lm(problem)
    grid = start_grid(problem)
    loss = np.asarray(batch_loss(problem.model, problem.data, grid))
    rows = grid[np.argsort(loss)[: lm.width]]
    held = np.zeros(rows.shape, bool)
    runs = {}
    for multistart in (True, False):
        z, rss, steps, *_ = lm(rows, 0.0, held, rows, _solve.MAIN_DECREMENT, 200, multistart)
        k = int(np.argmin(rss))
        runs[multistart] = (z[k], rss[k], int(np.max(steps)))
    opt, _ = _solve.solve(problem)
    variance = opt.sigma2
    assert abs(runs[True][1] - runs[False][1]) < 0.01 * variance
    se = np.sqrt(np.diag(opt.cov_z))
    tol = 2 * np.sqrt(_solve.MAIN_DECREMENT)
    assert np.max(np.abs(runs[True][0] - runs[False][0]) / se) < tol
    assert runs[True][2] < runs[False][2]  # 19 against 41 measured
