"""The coupling-law family (issue 11): each law's limits, nesting in the constant law,
and BIC's choice among them on data simulated from each (the choice matrix)."""

from __future__ import annotations

import copy
import json
import math
import warnings

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import idtool
from idtool import COUPLINGS, ExponentialCoupling
from idtool._diagnostic import with_code
from idtool._predict._predict import predict_friction_ratio

A_MAX = 8.5e-5


def test_exponential_law_between_its_two_asymptotes():
    law = ExponentialCoupling(gain=0.03, saturation_load_n=300.0)
    constant = idtool.ConstantCoupling(gain=0.03)
    # small alpha N / P: the constant law, corrections -x/2 + x^2/6 (x = 1e-4 here)
    a, n = 0.1, 0.3
    x = a * n / 300.0
    small = float(law.amplitude_m(a, n, A_MAX)) / float(constant.amplitude_m(a, n, A_MAX))
    assert small == pytest.approx(1.0 - x / 2.0 + x * x / 6.0, rel=1e-13)
    # large alpha N / P: the ceiling gain A_max P / N, approached as e^-x (x = 20)
    a, n = 1.0, 6000.0
    ceiling = 0.03 * A_MAX * 300.0 / n
    assert float(law.amplitude_m(a, n, A_MAX)) == pytest.approx(ceiling, rel=1e-8)
    # at the knee alpha N = P: 1 - 1/e of the constant law's amplitude
    knee = float(law.amplitude_m(0.5, 600.0, A_MAX)) / float(
        constant.amplitude_m(0.5, 600.0, A_MAX)
    )
    assert knee == pytest.approx(1.0 - math.exp(-1.0), rel=1e-12)
    # zero amplitude or zero load: exact, and differentiable there
    assert float(law.amplitude_m(0.0, 450.0, A_MAX)) == 0.0
    assert float(law.amplitude_m(0.5, 0.0, A_MAX)) == pytest.approx(0.5 * 0.03 * A_MAX, rel=1e-15)
    slope = jax.grad(lambda a: law.amplitude_m(a, 450.0, A_MAX))(0.0)
    assert float(slope) == pytest.approx(0.03 * A_MAX, rel=1e-12)


def test_the_amplitude_grows_with_the_command_and_falls_with_the_load():
    alphas = jnp.linspace(0.0, 1.0, 51)
    for name in COUPLINGS:
        params = {p.name: p.start for p in COUPLINGS.get(name).fit_params}
        law = COUPLINGS.get(name).from_values({k: jnp.asarray(v) for k, v in params.items()})
        for n in (100.0, 450.0, 900.0):
            amp = np.asarray(law.amplitude_m(alphas, n, A_MAX))
            assert np.all(np.diff(amp) > 0.0), name
        loads = jnp.linspace(100.0, 900.0, 9)
        amp = np.asarray(law.amplitude_m(0.7, loads, A_MAX))
        assert np.all(np.diff(amp) <= 0.0), name


# at module level: both detunings below run the same programs (one per law), compiled
# once (a jit made inside the test was compiled anew for each: 2 x 5 programs)
@jax.jit
def _round_trip(coupling, law, alpha, load):
    w, speed = 2 * np.pi * 20e3, 0.025
    a = coupling.slip_amplitude_m(law, alpha, load, speed, w, A_MAX)
    cycle = idtool.prescribed_cycle_average(law, speed, a, w)
    return coupling.drive_fraction(law, a, cycle, load, w, A_MAX)


@pytest.mark.parametrize("detuning_n_m", [0.0, 1.5e8])
def test_drive_fraction_inverts_the_slip_amplitude(detuning_n_m):
    """``drive_fraction`` (the inverse prediction's map from slip amplitude back to the
    command) undoes ``slip_amplitude_m`` for every registered law: the kinematic ones
    through the default bisection (2^-52), the sdof one in closed form from the
    harmonics at the loaded amplitude, which its solve balances to ~1e-10 in log force
    (tests/test_coupling_sdof.py), hence 1e-9 here; detuned as well."""
    round_trip = _round_trip
    for name in COUPLINGS:
        values = {p.name: p.start for p in COUPLINGS.get(name).fit_params}
        values |= {"coupling_gain": 0.03, "loss_stiffness_n_m": 2.9e8}
        values |= {"detuning_n_m": detuning_n_m}
        values |= {"power_load_n": 300.0, "saturation_load_n": 300.0}
        cls = COUPLINGS.get(name)
        coupling = cls.from_values({p.name: jnp.asarray(values[p.name]) for p in cls.fit_params})
        for load in (100.0, 450.0, 900.0):
            law = idtool.Dahl(fc_n=0.3 * load, kt_n_m=1e9)
            for alpha in (0.05, 0.3, 0.7, 1.0):
                back = float(round_trip(coupling, law, jnp.asarray(alpha), jnp.asarray(load)))
                assert back == pytest.approx(alpha, rel=1e-9, abs=1e-12), (name, load, alpha)


def test_every_law_reduces_to_the_constant_one_where_it_says_it_nests():
    """Where a law's parameters sit at their ``nested_at`` values, its amplitude is the
    constant law's within 2e-4 for any load up to 1 kN: the nested start of
    fit_dataset lies in the constant law's basin, and the law can come as close to it
    as the data ask (a saturation 0.3% short of it at the bound cost the exponential
    law 1 log-likelihood unit on constant-law data). The sdof law's ``amplitude_m`` is
    its free amplitude: at its nested loss stiffness the friction's pull on the horn is
    checked below instead."""
    alphas, loads = np.meshgrid(np.linspace(0.05, 1.0, 20), np.linspace(50.0, 1000.0, 20))
    reference = idtool.ConstantCoupling(gain=0.02).amplitude_m(alphas, loads, A_MAX)
    for name in COUPLINGS:
        params = COUPLINGS.get(name).fit_params
        values = {p.name: p.nested_at if p.nested_at is not None else p.start for p in params}
        values["coupling_gain"] = 0.02
        law = COUPLINGS.get(name).from_values({k: jnp.asarray(v) for k, v in values.items()})
        ratio = np.asarray(law.amplitude_m(alphas, loads, A_MAX)) / np.asarray(reference)
        assert np.max(np.abs(ratio - 1.0)) <= 2e-4, name
    # the sdof law's loaded amplitude there: Fc1 / R ~ 3e-12 m against ~1e-6 m
    sdof = idtool.SdofCoupling(gain=0.02, loss_stiffness_n_m=5e13)
    for load in (270.0, 1000.0):
        contact = idtool.Dahl(fc_n=0.3 * load, kt_n_m=1e9)
        loaded = sdof.slip_amplitude_m(contact, 0.5, load, 0.025, 2 * np.pi * 20e3, A_MAX)
        assert float(loaded) == pytest.approx(0.5 * 0.02 * A_MAX, rel=2e-4)


def _bench(law: str) -> idtool.BenchParams:
    """The example bench with amplitudes that reach the saturation's knee (alpha N / P
    from 0.1 to 2.2 at P = 300 N): on the paper's 50/70% matrix every point lies past
    it, where the two saturating shapes differ by little (BIC margins of -0.3 to 4
    there: the weights then share the evidence). The constant truth gives the
    power-limited law's amplitude at 70% and 450 N."""
    p = json.loads(idtool.example_params_path().read_text())
    p["experiments"]["amplitude_fractions"] = [0.15, 0.3, 0.5, 0.7, 1.0]
    p["experiments"]["on_durations_s"] = [1.0, 2.5]
    x = 0.7 * 450.0 / 300.0
    p["coupling"] = {
        "constant": {"law": "constant", "gain": 0.03 / math.sqrt(1.0 + x * x)},
        "power_limited": {"law": "power_limited", "gain": 0.03, "power_load_n": 300.0},
        "exponential": {"law": "exponential", "gain": 0.03, "saturation_load_n": 300.0},
        # gain 0.03 (740 N over 85 um x R); the friction takes 20-60% of the amplitude
        "sdof": {"law": "sdof", "drive_force_max_n": 740.0, "loss_stiffness_n_m": 2.9e8},
    }[law]
    return idtool.BenchParams.from_dict(copy.deepcopy(p))


@pytest.mark.slow
# one law in make test (the exponential one, which also checks what is saved and
# reported); the others are the recovery study's (make study)
@pytest.mark.parametrize(
    "truth",
    [
        pytest.param("constant", marks=pytest.mark.study),
        pytest.param("power_limited", marks=pytest.mark.study),
        "exponential",
        pytest.param("sdof", marks=pytest.mark.study),
    ],
)
def test_bic_picks_the_simulated_coupling_law(truth, tmp_path):
    dataset, _ = idtool.simulate_bench(_bench(truth), seed=1)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        fit = idtool.fit(
            dataset, coupling="auto", actuator="slope", offset="constant", variability=False
        )
    laws = fit.coupling_laws
    chosen = next(iter(laws))
    assert chosen == truth.replace("_", "-")
    assert fit.model.coupling.name == chosen
    assert sum(w["bic_weight"] for w in laws.values()) == pytest.approx(1.0, rel=1e-12)
    assert laws[chosen]["bic_weight"] > 0.95
    # each saturating law nests the constant one: its likelihood is not lower (the fit
    # also starts it from the constant law's optimum; from its own multi-start alone
    # it found a basin 1180 log-likelihood units lower on constant-law data). Up to
    # 0.05: the load scales' bounds keep the laws 2e-4 off the constant one at most,
    # and each fit settles its own AR(1) coefficient (1e-3 here)
    constant = fit.run.candidates["dahl/constant/slope/constant"].loglik
    for name in ("power-limited", "exponential", "sdof"):
        assert fit.run.candidates[f"dahl/{name}/slope/constant"].loglik >= constant - 0.05
    if truth == "exponential":  # what fit.json and the report say
        fit.save(tmp_path / "fit", command=["fit"], plots=False)
        doc = json.loads((tmp_path / "fit" / "fit.json").read_text())
        assert [w["law"] for w in doc["coupling_laws"]] == list(laws)
        back = idtool.load_fit(tmp_path / "fit").coupling_laws
        assert back[chosen]["bic_weight"] == pytest.approx(laws[chosen]["bic_weight"])
        assert "[[Coupling laws]]" in fit.report()


@pytest.fixture(scope="module")
def comparable(tmp_path_factory):
    """The paper's 50/70% matrix from the exponential law (seed 2): every point lies
    past the knee, and the exponential law and the power limit fit comparably."""
    p = json.loads(idtool.example_params_path().read_text())
    p["coupling"] = {"law": "exponential", "gain": 0.03, "saturation_load_n": 125.0}
    bench = idtool.BenchParams.from_dict(p)
    dataset, _ = idtool.simulate_bench(bench, seed=2)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        fit = idtool.fit(
            dataset, coupling="auto", actuator="slope", offset="constant", variability=False
        )
    return bench, fit, fit.save(tmp_path_factory.mktemp("laws") / "fit", plots=False)


@pytest.mark.slow
def test_laws_that_fit_comparably_are_flagged(comparable):
    """Exponential-law data leave it and the power limit 0.3 BIC units apart, and the
    fit says that the laws fit comparably and that predictions average them."""
    _, fit, _ = comparable
    weights = {n: w["bic_weight"] for n, w in fit.coupling_laws.items()}
    assert min(weights["exponential"], weights["power-limited"]) > 0.2
    flagged = with_code(fit.warnings, "coupling_laws")
    assert len(flagged) == 1
    assert "exponential" in flagged[0] and "power-limited" in flagged[0]
    assert "predictions average the laws" in flagged[0]
    assert set(flagged[0].values["bic_weights"]) == {"exponential", "power-limited"}


@pytest.mark.slow
def test_predictions_average_the_laws_and_cover_what_one_law_misses(comparable):
    """Below the tested loads the two saturating laws part: the chosen law's band
    misses the truth (exponential-law data), the BIC-weighted average covers it, and
    says that the laws disagree there; at the tested loads they agree."""
    from idtool._simulate._simulate import operating_point

    bench, fit, _ = comparable
    weights = {n: w["bic_weight"] for n, w in fit.coupling_laws.items()}
    draws = fit.draws(max_draws=2000)
    kept = {n: w for n, w in weights.items() if w >= 1e-3}  # the constant law: ~1e-200
    total = sum(kept.values())
    assert draws.law_weights == pytest.approx({n: w / total for n, w in kept.items()})
    for component in draws.components:  # each law's share of the draws, to rounding
        share = draws.law_weights[component.model.coupling.name]
        assert abs(component.n - 2000 * share) <= 1.0
    chosen = draws.components[0]
    for load in (60.0, 150.0):
        truth = operating_point(bench, load, 0.5)["friction_ratio"]
        averaged = fit.predict(load, 0.5)
        lo, hi = averaged[0].ci95
        assert lo <= truth <= hi, (load, truth, lo, hi)
        alone = predict_friction_ratio(chosen, [load], [0.5], [0.025])[0]
        if chosen.model.coupling.name != "exponential":
            assert not alone.ci95[0] <= truth <= alone.ci95[1], (load, truth, alone.ci95)
        laws = dict(averaged[0].by_law)
        # every law the average keeps (the load-power law nests the power limit and
        # pays BIC's ln(n) for its one more parameter: its weight is small, not nil)
        assert set(laws) == set(kept) >= {"exponential", "power-limited"}
        assert with_code(averaged.warnings, "coupling_laws")
        assert averaged.to_dict()["rows"][0]["by_coupling_law"] == laws
    tested = fit.predict(450.0, 0.5)
    assert not with_code(tested.warnings, "coupling_laws")


@pytest.mark.slow
def test_a_saved_fit_keeps_the_laws_it_averages(comparable):
    _, fit, folder = comparable
    doc = json.loads((folder / "fit.json").read_text())
    files = {w["law"]: w.get("state_file") for w in doc["coupling_laws"]}
    chosen = fit.model.coupling.name
    kept = {w["law"] for w in doc["coupling_laws"] if w["bic_weight"] >= 1e-3}
    others = kept - {chosen}
    assert {"exponential", "power-limited"} - {chosen} <= others
    assert files[chosen] is None and files["constant"] is None  # chosen: fit_state.npz
    for other in others:
        assert (folder / files[other]).is_file()
    back = idtool.load_fit(folder)
    assert set(back.artefact.alternates) == others
    a, b = fit.predict(60.0, 0.5)[0], back.predict(60.0, 0.5)[0]
    assert (a.median, a.ci95, a.by_law) == (b.median, b.ci95, b.by_law)


def test_a_law_starts_from_each_law_it_nests():
    """With --coupling auto each law is also started from the optimum of every law fitted
    before whose parameters are a subset of its own (the load-power law from the power
    limit's: a load-power truth at Kt 1.9e10 N/m was fitted at Kt's bound, BIC 13,182,
    against 7,425 from the power limit's optimum, and lost to the exponential law at
    BIC weight 1.0)."""
    from idtool._fit._run import nested_couplings, nesting_order

    every = idtool.COUPLINGS.names()
    order = nesting_order(every)  # each law after those it nests
    for law in every:
        assert all(order.index(n) < order.index(law) for n in nested_couplings(law, every))
    assert nested_couplings("load-power", every) == ["constant", "power-limited"]
    assert nested_couplings("power-limited", every) == ["constant"]
    assert nested_couplings("exponential", every) == ["constant"]
    assert nested_couplings("constant", every) == []
    # the nested law's parameter where the richer one reduces to it
    exponent = {p.name: p for p in idtool.COUPLINGS.get("load-power").fit_params}
    assert exponent["load_exponent"].nested_at == 0.0
