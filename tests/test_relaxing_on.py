"""The level models (issue 26, item 4): the relaxing ON level (a fading horn) and the
creeping level, their nesting of the steady model, their choice by BIC, what they recover
and report, and their round trip through ``fit.json``.

Fits on small benches (2 loads, 50%, ON 0.5 and 2.5 s, 400 Hz, 3 s of sliding either
side of the window): a fading horn (20% of the slip amplitude lost with time constant
1.5 s), a creeping level (0.2%/s) on three loads, and the same benches without either.
"""

from __future__ import annotations

import json

import jax.numpy as jnp
import numpy as np
import pytest
from scipy.optimize import least_squares
from test_departures import quiet, small_params

import idtool
from idtool import simulate_bench
from idtool._data._blocks import prepare_fit_data
from idtool._diagnostic import DRIFT_CODES, with_code
from idtool._fit._fit import fit_model
from idtool._fit._plateau_drift import DRIFT, MIN_RELATIVE_CHANGE
from idtool._model._bench import TraceTiming
from idtool._model._benchmodel import bench_model
from idtool._model._level_model import LEVEL_MODELS, RelaxingOnLevel, relaxed_fraction
from idtool._simulate._plateau_drift import on_level_over_time_n
from idtool._simulate._simulate import noise_free_force_n

SEED = 5
FADING = {"fade_fraction": 0.2, "fade_time_constant_s": 1.5}
CREEP_PER_S = 0.002
THREE_LOADS = {"normal_loads_n": [270.0, 450.0, 670.0], "repeats": 2}


def bench(**edits) -> dict:
    """The small bench with 3 s of OFF sliding either side of the ON window."""
    params = small_params(sliding_before_s=3.0, sliding_after_s=3.0)
    for section, values in edits.items():
        params.setdefault(section, {}).update(values)
    return params


@pytest.fixture(scope="module")
def fading():
    dataset, truth = simulate_bench(bench(horn_fading=FADING), SEED)
    return dataset, truth, idtool.fit(dataset)


@pytest.fixture(scope="module")
def clean():
    dataset, truth = simulate_bench(bench(), SEED)
    return dataset, truth, idtool.fit(dataset)


# --- the model -------------------------------------------------------------------------


def test_the_registry_lists_steady_first():
    assert LEVEL_MODELS.names() == ("steady", "relaxing", "creeping")


def test_relaxed_fraction_is_zero_before_and_frozen_after_the_window():
    timing = TraceTiming(startup_s=0.5, on_start_s=2.0, on_end_s=4.0)
    t = np.array([0.0, 1.9, 2.0, 3.0, 4.0, 6.0])
    h = np.asarray(relaxed_fraction(t, timing, 1.0))
    expected = 1.0 - np.exp(-np.array([0.0, 0.0, 0.0, 1.0, 2.0, 2.0]))  # eq. R1
    np.testing.assert_allclose(h, expected, atol=1e-15)
    none = TraceTiming(startup_s=0.5, on_start_s=np.inf, on_end_s=np.inf)
    assert np.all(np.asarray(relaxed_fraction(t, none, 1.0)) == 0.0)


def test_friction_ratio_at_start_and_steady_state():
    m = RelaxingOnLevel(on_rise=np.array([0.3, 0.3]), on_relax_time_s=1.5)
    np.testing.assert_allclose(m.friction_ratio(np.array([0.2, 0.9]), 0.0), [0.2, 0.9])
    # eq. R2, capped at 1
    np.testing.assert_allclose(m.steady_friction_ratio(np.array([0.2, 0.9])), [0.26, 1.0])
    at_tau = m.friction_ratio(np.array([0.2, 0.2]), 1.5)
    np.testing.assert_allclose(at_tau, 0.2 * (1 + 0.3 * (1 - np.exp(-1.0))))


def test_zero_rise_and_zero_creep_are_the_steady_model(clean):
    """Nested: the relaxing model at rise 0 and the creeping one at rate 0 predict the
    steady model's block means exactly, whatever the time constant."""
    dataset, _, _ = clean
    data = prepare_fit_data(dataset, mains_hz=50.0, periods_per_block=2)
    steady = bench_model(data)
    z = steady.z0()
    reference = np.asarray(steady.predict(jnp.asarray(z)))
    for level in ("relaxing", "creeping"):
        model = bench_model(data, level=level)
        zz = np.array(
            [
                z[steady.names.index(p.name)]
                if p.name in steady.names
                else (model.z0()[i] if p.nested_at is None else p.internal(p.nested_at))
                for i, p in enumerate(model.params)
            ]
        )
        if level == "relaxing":
            zz[model.names.index("on_relax_time_s")] = model.params[
                model.names.index("on_relax_time_s")
            ].internal(0.7)
        np.testing.assert_allclose(np.asarray(model.predict(jnp.asarray(zz))), reference, 0, 1e-12)


def test_the_fading_bench_keeps_its_start_up():
    """Regression: the fading horn's force before its switch-on is the bench's without
    the fade (it read the OFF level from t = 0 before, with no start-up)."""
    params = quiet(bench())
    faded = quiet(bench(horn_fading=FADING))
    dataset, truth = simulate_bench(faded, SEED)
    _, plain = simulate_bench(params, SEED)
    for trace, t, p in zip(dataset.traces, truth.traces, plain.traces, strict=True):
        before = trace.time_s < t.horn_on_s[0]
        np.testing.assert_allclose(
            noise_free_force_n(truth.params, t, trace.time_s[before]),
            noise_free_force_n(plain.params, p, trace.time_s[before]),
            atol=1e-9,
        )


# --- fits --------------------------------------------------------------------------------


def effective_relaxation(truth) -> tuple[np.ndarray, float]:
    """Eq. R1 fitted to the true ON levels of the 2.5 s windows (the simulator's fading
    horn is an exponential in the slip amplitude, not in the ON level): per-trace rises
    and the shared time constant [s] that describe the truth best."""
    curves = []
    for t in truth.traces:
        on0, on1 = t.horn_on_s
        if on1 - on0 > 2.0:
            s = np.linspace(0.0, on1 - on0, 101)
            level = on_level_over_time_n(truth.params, t, on0 + s)
            curves.append((s, level / level[0]))

    def resid(x):
        tau, rises = x[0], x[1:]
        return np.concatenate(
            [y - (1 + r * (1 - np.exp(-s / tau))) for (s, y), r in zip(curves, rises, strict=True)]
        )

    out = least_squares(resid, np.r_[1.5, np.full(len(curves), 0.3)])
    return out.x[1:], float(out.x[0])


def test_fading_horn_chooses_the_relaxing_on_level_and_recovers_it(fading):
    dataset, truth, fit = fading
    assert fit.model.level.name == "relaxing"
    assert "relaxing" in fit.run.reason and "steady" in fit.run.reason
    keys = list(fit.run.candidates)  # law/coupling/actuator/offset[/level unless steady]
    assert any(k.endswith("/relaxing") for k in keys)
    assert any(len(k.split("/")) == 4 for k in keys)
    rises, tau = effective_relaxation(truth)
    # the truth's exponential in the amplitude is a slower one in the ON level (FR grows
    # faster than 1 / a as the amplitude fades): measured tau_eff 2.13 s for a 1.5 s fade,
    # rises 0.38 and 0.45; eq. R1 fits the truth's curve to 0.34% of the level, not exactly
    assert 1.8 < tau < 2.5 and np.all((rises > 0.3) & (rises < 0.5))
    est = fit.estimates["on_relax_time_s"]
    # measured 2.05 s [1.62, 2.58]: inside its 95% interval, widened by a tenth of tau_eff
    # for eq. R1's error in shape
    assert est.ci95[0] - 0.1 * tau < tau < est.ci95[1] + 0.1 * tau, (est, tau)
    long = [i for i, t in enumerate(truth.traces) if t.horn_on_s[1] - t.horn_on_s[0] > 2.0]
    for i, r in zip(long, rises, strict=True):
        e = fit.estimates[f"on_rise[{dataset.traces[i].id}]"]
        # measured 0.347 [0.288, 0.406] and 0.420 [0.389, 0.452] against 0.377 and 0.448:
        # inside, the interval widened by 0.01 for the shape error (3x its 0.34%)
        assert e.ci95[0] - 0.01 < r < e.ci95[1] + 0.01, (e, r)
    # the cold-horn FR, read at the window's start: the truth's at the commanded amplitude
    for i, t in enumerate(truth.traces):
        assert fit.result.friction_ratio[i] == pytest.approx(t.friction_ratio, abs=0.02)


def test_fading_horn_is_still_reported_when_modelled(fading):
    """The relaxing model takes the drift out of the residuals; the report still says
    the ON level rises (code drift_modelled), with its size and time constant."""
    _, _, fit = fading
    (w,) = with_code(fit.warnings, "drift_modelled")
    assert w.startswith(DRIFT) and "horn may be fading" in w and "cold horn" in w
    modelled = fit.result.plateau_drift["modelled"]
    assert modelled.kind == "ON" and modelled.median_rise > MIN_RELATIVE_CHANGE["ON"]
    assert not with_code(fit.warnings, "drift_on")  # nothing left in the residuals


def test_the_steady_model_still_warns_on_the_fading_bench(fading):
    dataset, _, _ = fading
    fit = idtool.fit(dataset, level="steady")
    assert fit.model.level.name == "steady"
    (w,) = with_code(fit.warnings, "drift_on")
    assert "The fit holds each level constant" in w


def test_clean_bench_keeps_the_steady_levels_without_trying_the_others(clean):
    _, _, fit = clean
    assert fit.model.level.name == "steady"
    assert all(len(k.split("/")) == 4 for k in fit.run.candidates)  # no /level: steady
    assert not with_code(fit.warnings, *DRIFT_CODES)


def test_bic_prefers_steady_levels_on_a_clean_bench(clean):
    """Fitted outright (not left to the trigger), the relaxing and creeping models lose
    to the steady one on BIC on a clean bench: they only add parameters."""
    dataset, _, _ = clean
    data = prepare_fit_data(dataset, mains_hz=50.0, periods_per_block=2)
    steady = fit_model(data, actuator="slope")
    for level in ("relaxing", "creeping"):
        richer = fit_model(data, actuator="slope", start_from=steady, level=level)
        assert richer.loglik >= steady.loglik - 1e-6  # nested
        assert richer.bic > steady.bic, level


def test_creeping_level_is_chosen_and_recovered():
    dataset, _ = simulate_bench(
        bench(experiments=THREE_LOADS, contact={"level_creep_per_s": CREEP_PER_S}), SEED
    )
    fit = idtool.fit(dataset)
    assert fit.model.level.name == "creeping"
    rate = fit.estimates["level_creep_per_s"]
    assert rate.ci95[0] < CREEP_PER_S < rate.ci95[1], rate
    (w,) = with_code(fit.warnings, "drift_modelled")
    assert "the friction level rises by 0.2" in w and "creeping" in w


def test_fit_json_round_trip(fading, tmp_path):
    _, _, fit = fading
    folder = fit.save(tmp_path / "fit", plots=False)  # report.txt is written all the same
    doc = json.loads((folder / "fit.json").read_text())
    assert doc["level"] == {
        "name": "relaxing",
        "parameters": ["on_relax_time_s"],
        "trace_parameters": ["on_rise"],
    }
    assert doc["plateau_drift"]["modelled"]["model"] == "relaxing"
    for tr in doc["traces"]:
        steady = tr["friction_ratio_steady"]
        fr0 = tr["friction_ratio"]["estimate"]
        assert steady["estimate"] == pytest.approx(min(fr0 * (1 + steady["on_rise"]), 1.0))
        assert tr["on_rise"]["estimate"] == steady["on_rise"]
    stored = idtool.load_fit(folder)
    assert stored.model.level.name == "relaxing"
    for name in ("Kt", "mu", "on_relax_time_s"):
        assert stored.estimates[name].estimate == pytest.approx(fit.estimates[name].estimate)
    pa, pb = fit.predict(560.0, 0.6), stored.predict(560.0, 0.6)
    assert pa[0].median == pytest.approx(pb[0].median, rel=1e-9)
    (note,) = with_code(pb.warnings, "drift_modelled")  # the predictions say which FR
    assert "cold horn" in note and "steady state" in note
    text = (folder / "report.txt").read_text()
    assert "at the window's start" in text and "at steady state" in text
