"""The direction of vibration compared by BIC (issue 30, item 2): ``direction="auto"``
fits every registered direction and ranks them as the coupling laws are ranked (one
mechanism, :func:`idtool._fit._run.choice_weights`); the simulator simulates any
direction. One small design (2 loads x 4 amplitudes, 8 traces:
:mod:`idtool._simulate._direction_bench`) simulated in each direction and fitted once per
module; ``benchmarks/study_directions.py`` scores it over seeds."""

from __future__ import annotations

import json
from types import SimpleNamespace

import numpy as np
import pytest

import idtool
from idtool._data._schema import schema_validator
from idtool._errors import IdtoolError
from idtool._fit._folder import FIT_JSON
from idtool._fit._run import (
    ChoiceWeight,
    choice_table,
    comparable_warning,
    model_label,
)
from idtool._model._spec import ModelSpec
from idtool._simulate._direction_bench import direction_params
from idtool._simulate._params import BenchParams
from idtool._simulate._schema import simulator_params_schema
from idtool._simulate._simulate import (
    TRUTH_FILE,
    operating_point,
    simulate_bench,
    write_simulation,
)

DIRECTIONS = ("along", "transverse", "normal")
SEED = 1
# every option of the fit but the direction held at one model: a fit per direction. The
# fit's seed 0 and 8 starts: on 8 traces the multi-start sometimes misses the true
# direction's own optimum, and then another direction wins by BIC (3 of 30 benches with 8
# starts in benchmarks/study_directions.py; with 16 starts, seed 0 misses normal's here)
FIT_OPTIONS = {
    "direction": "auto",
    "coupling": "power-limited",
    "actuator": "slope",
    "offset": "constant",
    "level": "steady",
}


# ------------------------------------------------------------------ the simulator
def test_the_simulator_vibrates_in_each_direction(tmp_path):
    frs = {}
    for d in DIRECTIONS:
        params = direction_params(d)
        assert params.contact.direction == d
        # the file names the direction unless along (the default, left out as before)
        doc = params.to_dict()
        assert doc["contact"].get("direction", "along") == d
        assert ("direction" in doc["contact"]) is (d != "along")
        assert BenchParams.from_dict(doc) == params
        frs[d] = operating_point(params, 270.0, 0.5)["friction_ratio"]
    # the same slip amplitude reduces friction least out of plane, most along
    along = direction_params("along").to_dict()
    along["contact"]["direction"] = "transverse"
    transverse = operating_point(BenchParams.from_dict(along), 270.0, 0.5)["friction_ratio"]
    assert frs["along"] < transverse < 1.0
    assert 0.4 < frs["normal"] < 0.7
    # the truth records the direction simulated
    dataset, truth = simulate_bench(direction_params("normal"), SEED)
    written = json.loads(
        (write_simulation(tmp_path / "s", dataset, truth) / TRUTH_FILE).read_text()
    )
    assert written["direction"] == "normal"
    assert written["traces"][0]["friction_ratio"] == pytest.approx(
        operating_point(truth.params, 270.0, 0.3)["friction_ratio"], rel=1e-12
    )


def test_the_schema_lists_the_registered_directions_and_refuses_others():
    field = simulator_params_schema()["properties"]["contact"]["properties"]["direction"]
    assert field["enum"] == list(idtool.DIRECTIONS.names())
    assert field["default"] == "along"
    doc = direction_params("along").to_dict()
    doc["contact"]["direction"] = "sideways"
    with pytest.raises(IdtoolError) as err:
        BenchParams.from_dict(doc)
    assert "contact.direction" in "\n".join(str(p) for p in err.value.problems)
    doc["contact"]["direction"] = "transverse"
    doc["coupling"] = {"law": "sdof", "gain": 0.03, "power_load_n": 125.0}
    with pytest.raises(IdtoolError):  # the sdof law's balance is along only
        BenchParams.from_dict(doc)


# ------------------------------------------------------------------ the mechanism
def test_a_key_names_a_direction_other_than_along():
    along = ModelSpec("dahl", "constant", "ar1", "slope", "constant", "steady")
    assert along.key == "dahl/constant/slope/constant"  # as before the directions
    normal = ModelSpec("dahl", "constant", "ar1", "slope", "drift", "relaxing", (), "normal")
    assert normal.key == "dahl/constant/slope/drift/relaxing@normal"
    assert ModelSpec.from_key(normal.key) == normal
    # a key without a direction takes the one given (fit.json's, before keys named it)
    assert ModelSpec.from_key(along.key, direction="transverse").direction == "transverse"
    assert ModelSpec.from_key(normal.key, direction="transverse").direction == "normal"


def _candidate(coupling: str, direction: str, bic: float) -> SimpleNamespace:
    model = SimpleNamespace(
        coupling=SimpleNamespace(name=coupling), direction=SimpleNamespace(name=direction)
    )
    return SimpleNamespace(model=model, bic=bic, aic=bic - 10.0)


def test_directions_are_weighed_and_flagged_as_the_coupling_laws_are():
    candidates = {
        "a": _candidate("constant", "along", 100.0),
        "b": _candidate("power-limited", "along", 98.0),
        "c": _candidate("constant", "transverse", 99.0),
        "d": _candidate("power-limited", "transverse", 120.0),
        "e": _candidate("constant", "normal", 130.0),
    }
    directions = choice_table(candidates, "direction")
    assert list(directions) == ["along", "transverse", "normal"]  # best first
    assert [w.key for w in directions.values()] == ["b", "c", "e"]  # each one's best
    w = np.exp(-0.5 * np.array([0.0, 1.0, 32.0]))
    np.testing.assert_allclose([x.bic_weight for x in directions.values()], w / w.sum())
    warning = comparable_warning("direction", directions, "along")
    assert warning is not None and warning.code == "directions"
    assert warning.values["bic_weights"] == pytest.approx(
        {"along": directions["along"].bic_weight, "transverse": directions["transverse"].bic_weight}
    )
    assert "the directions of vibration fit comparably" in warning
    decisive = {"along": ChoiceWeight("along", "b", 0.0, 0.0, 0.99, 0.99)}
    decisive["normal"] = ChoiceWeight("normal", "e", 20.0, 20.0, 0.01, 0.01)
    assert comparable_warning("direction", decisive, "along") is None
    # the coupling laws' table and warning: the same code path, as before
    laws = choice_table(candidates, "coupling")
    law_warning = comparable_warning("coupling", laws, "power-limited")
    assert law_warning is not None and law_warning.code == "coupling_laws"
    assert law_warning.startswith("the coupling laws fit comparably (BIC weight power-limited")
    # what predictions call each model: by the choices the run compared
    m = candidates["c"].model
    assert model_label(m) == model_label(m, ("coupling",)) == "constant"
    assert model_label(m, ("direction",)) == "transverse"
    assert model_label(m, ("coupling", "direction")) == "constant@transverse"


# ------------------------------------------------------------------ the fit
@pytest.fixture(scope="module")
def auto_fits():
    """Each direction's bench (seed 1) and its ``direction="auto"`` fit."""
    out = {}
    for d in DIRECTIONS:
        dataset, truth = simulate_bench(direction_params(d), SEED)
        out[d] = truth, idtool.fit(dataset, **FIT_OPTIONS)
    return out


@pytest.mark.parametrize("direction", DIRECTIONS)
def test_auto_picks_the_simulated_direction(auto_fits, direction):
    _, fit = auto_fits[direction]
    chosen = fit.artefact.chosen
    assert chosen.model.direction.name == direction
    table = fit.directions
    assert set(table) == set(DIRECTIONS)
    assert next(iter(table)) == direction  # best first
    assert table[direction]["bic_weight"] > 0.99
    # weighed by the levels model (idtool/_fit/_choice_levels.py); an option whose levels
    # model cannot be estimated is listed with weight 0 and its trace-level criteria
    assert table[direction]["criterion"] == "levels"
    for entry in table.values():
        assert entry["criterion"] == "levels" or entry["bic_weight"] == 0.0
    assert fit.to_json()["direction"]["name"] == direction
    assert "[[Directions of vibration]]" in fit.report()
    assert not [w for w in fit.warnings if w.code == "directions"]


@pytest.mark.parametrize("direction", DIRECTIONS)
def test_the_truth_is_inside_the_winners_intervals(auto_fits, direction):
    truth, fit = auto_fits[direction]
    values = {
        "Kt": truth.params.contact.contact_stiffness_n_m,
        "mu": truth.params.contact.friction_coefficient,
    }
    for name, value in values.items():
        lo, hi = fit.artefact.estimates[name].ci95
        assert lo <= value <= hi, (direction, name, value, (lo, hi))


def test_the_transverse_kt_interval_spans_both_basins_of_its_profile():
    """Near the Coulomb limit (Lambda about 10) Kt's profile on the transverse bench has
    two basins, at the truth and 0.3-0.6 decades above it, a few units of -2 log L
    apart; the levels model's Gauss-Newton interval covered one: on seed 2 (this fit's
    options) [6.8e8, 9.7e8] N/m, missing the truth (4 of 10 seeds covered by the study's
    fits). The likelihood check (idtool._fit._level_profile) sees the profile flatten
    beyond the interval and widens it to its union with the profile's, over both basins:
    10 of 10."""
    dataset, truth = simulate_bench(direction_params("transverse"), 2)
    fit = idtool.fit(dataset, **(FIT_OPTIONS | {"direction": "transverse"}))
    kt = truth.params.contact.contact_stiffness_n_m
    est = fit.artefact.estimates["Kt"]
    lo, hi = est.ci95
    assert lo <= kt <= hi, (lo, hi)
    assert est.one_sided == "" and np.log10(hi / lo) < 2.0  # bounded: wider, not infinite
    checked = [
        w
        for w in fit.warnings
        if w.code == "profile_interval" and w.values["parameter"] == "Kt" and "levels model" in w
    ]
    (warning,) = checked
    wald_lo, wald_hi = warning.values["wald_ci95"]
    assert not wald_lo <= kt <= wald_hi  # the defect this check is for
    # the union of the two: widened, never narrowed
    p_lo, p_hi = warning.values["profile_ci95"]
    assert (lo, hi) == pytest.approx((min(p_lo, wald_lo), max(p_hi, wald_hi)))
    assert tuple(warning.values["ci95"]) == pytest.approx((lo, hi))


def test_directions_that_fit_comparably_are_kept_flagged_and_averaged(tmp_path):
    """A bench whose vibration is too weak to reduce friction (FR = 1): every direction
    fits it, so the comparison keeps them all by weight, warns, saves each kept one's
    state, and predictions and report.html average over them."""
    doc = direction_params("along").to_dict()
    doc["coupling"]["gain"] = 0.002
    dataset, _ = simulate_bench(BenchParams.from_dict(doc), SEED)
    fit = idtool.fit(dataset, **FIT_OPTIONS)
    a = fit.artefact
    assert len(a.alternates) >= 1
    assert set(a.alternates) | {a.chosen_label} <= set(DIRECTIONS)
    assert a.chosen_label == a.model.direction.name
    weights = {d: e["bic_weight"] for d, e in a.directions.items()}
    assert a.chosen_weight == pytest.approx(weights[a.chosen_label])
    (warning,) = [w for w in fit.warnings if w.code == "directions"]
    assert "fit comparably" in warning and "comparable" in fit.report()
    out = fit.save(tmp_path / "fit")
    saved = json.loads((out / FIT_JSON.name).read_text())
    assert list(schema_validator(FIT_JSON.schema).iter_errors(saved)) == []
    assert [e["direction"] for e in saved["directions"]] == list(a.directions)
    kept = [e for e in saved["model_weights"] if "state_file" in e]
    assert {e["model"] for e in kept} == set(a.alternates)
    assert all((out / e["state_file"]).is_file() for e in kept)
    loaded = idtool.load_fit(out)
    assert loaded.artefact.chosen_label == a.chosen_label
    assert {k: w for k, (w, _) in loaded.artefact.alternates.items()} == pytest.approx(
        {k: weights[k] for k in a.alternates}
    )
    for label, (_, alt) in loaded.artefact.alternates.items():
        assert alt.model.direction.name == label
    draws = loaded.draws(max_draws=200)
    assert set(draws.law_weights) == {a.chosen_label, *a.alternates}
    assert "directions of vibration" in draws.note
    html = idtool.write_report(out).read_text()
    assert "Directions of vibration" in html and "fits comparably" in html
