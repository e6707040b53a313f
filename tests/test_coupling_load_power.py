"""The default coupling law (load-power), the truth-only ceiling law of the departures,
and parameters the data bound on one side only (issue 26, item 3)."""

from __future__ import annotations

import json
import warnings

import numpy as np
import pytest

import idtool
from idtool._diagnostic import with_code
from idtool._fit._intervals import refit_with_fixed
from idtool._simulate._truth_coupling import TanhCeilingCoupling

A_MAX = 8.5e-5
ALPHAS = np.linspace(0.05, 1.0, 20)
LOADS = np.array([50.0, 270.0, 450.0, 670.0, 1000.0])


def test_load_power_is_the_power_limit_times_a_power_of_the_load():
    alphas, loads = np.meshgrid(ALPHAS, LOADS)
    limit = np.asarray(
        idtool.PowerLimitedCoupling(gain=0.03, power_load_n=125.0).amplitude_m(alphas, loads, A_MAX)
    )
    for beta in (0.0, 0.7, -0.4):
        law = idtool.LoadPowerCoupling(gain=0.03, load_exponent=beta, power_load_n=125.0)
        amp = np.asarray(law.amplitude_m(alphas, loads, A_MAX))
        # beta = 0 is the power limit itself (it nests it); else (450 N / N)^beta times it
        np.testing.assert_allclose(amp / limit, (450.0 / loads) ** beta, rtol=1e-13)
    assert "load-power" in idtool.COUPLINGS.names()


def test_the_ceiling_law_between_its_asymptotes():
    law = TanhCeilingCoupling(gain=0.03, ceiling_load_n=30.0)
    for load in LOADS:
        c = np.sqrt(30.0 / load)
        # small alpha: the constant law, tanh(x) = x - x^3 / 3 (x = 1e-4 / c)
        small = float(law.amplitude_m(1e-4, load, A_MAX)) / (0.03 * 1e-4 * A_MAX)
        assert small == pytest.approx(1.0 - (1e-4 / c) ** 2 / 3.0, rel=1e-12)
        # full command far above the ceiling: gain A_max c, falling as N^-1/2
        if 1.0 / c > 10.0:
            assert float(law.amplitude_m(1.0, load, A_MAX)) == pytest.approx(
                0.03 * A_MAX * c, rel=1e-8
            )


def _constant_law_bench() -> idtool.Dataset:
    """The example's design with a coupling that does not saturate (the constant law at
    a third of the example's gain): a power limit fitted to it (the constant law is its
    limit P -> infinity) has a profile flat above ~1e4 N up to the top of its load scale's
    range, and the data bound that scale from below only."""
    p = json.loads(idtool.example_params_path().read_text())
    p["coupling"] = {"law": "constant", "gain": 0.012}
    dataset, _ = idtool.simulate_bench(idtool.BenchParams.from_dict(p), seed=3)
    return dataset


def test_a_parameter_the_data_bound_on_one_side_is_stated_one_sided(tmp_path):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        fit = idtool.fit(
            _constant_law_bench(),
            coupling="power-limited",
            actuator="slope",
            offset="constant",
            variability=False,
        )
    # the constant law's Kt and gain, in the basin where P is large (a multi-start that
    # lost it ended at log L -1348 with Kt 9.7e7 N/m and P at its bound; here -823.6)
    for name, truth in (("Kt", 1e9), ("coupling_gain", 0.012)):
        lo, hi = fit.estimates[name].ci95
        assert lo <= truth <= hi, (name, lo, hi)
    p = fit.estimates["power_load_n"]
    # wherever in the flat top the optimum lies (here 1.9e4 N), the interval runs to the
    # range's top (within its Z_AT_BOUND edge, 1%) and the data set its lower end only:
    # from the profile, not from the Gauss-Newton curvature (whose lower end, 1.05 N, lay
    # where -2 log L rises 1.8e7)
    assert p.one_sided == "lower"
    assert p.ci95[1] == pytest.approx(1e5, rel=0.02) and 1e3 < p.ci95[0] < 1e5
    assert not with_code(fit.warnings, "uninformed")
    assert p.statement.startswith(f"> {p.ci95[0]:.4g}")
    assert f"> {p.ci95[0]:.4g}" in fit.report()
    # the stated end is where the profile likelihood rises by 3.84 (the walk ends on a
    # bracket 1/64 of its last step wide, interpolated: within 20% of the rise)
    run = fit.run.chosen
    i = run.model.names.index("power_load_n")
    rise, _ = refit_with_fixed(run, i, float(run.model.params[i].internal(p.ci95[0])))
    assert 3.84 / 1.2 < rise < 3.84 * 1.2
    # what fit.json records, and a loaded fit reads
    fit.save(tmp_path / "fit", command=["fit"], plots=False)
    doc = json.loads((tmp_path / "fit" / "fit.json").read_text())
    assert doc["parameters"]["power_load_n"]["one_sided"] == "lower"
    assert "one_sided" not in doc["parameters"]["mu"]
    back = idtool.load_fit(tmp_path / "fit").estimates["power_load_n"]
    assert back.one_sided == "lower" and back.statement == p.statement


@pytest.mark.slow
def test_the_default_law_recovers_a_coupling_that_falls_with_the_load():
    """Data whose small-signal coupling falls as (450 N / N)^0.5 on top of the power
    limit: the load-power law's fit covers the exponent, Kt and mu, and its report says
    what Kt rests on."""
    p = json.loads(idtool.example_params_path().read_text())
    p["coupling"] = {"law": "load_power", "gain": 0.03, "load_exponent": 0.5, "power_load_n": 200.0}
    dataset, _ = idtool.simulate_bench(idtool.BenchParams.from_dict(p), seed=5)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        fit = idtool.fit(dataset, coupling="load-power")
    assert fit.model.coupling.name == "load-power"
    truth = {
        "load_exponent": 0.5,
        "Kt": p["contact"]["contact_stiffness_n_m"],
        "mu": p["contact"]["friction_coefficient"],
    }
    for name, value in truth.items():
        lo, hi = fit.estimates[name].ci95
        assert lo <= value <= hi, (name, value, lo, hi)
    assert "Kt is read through the load-power coupling law" in fit.report()
