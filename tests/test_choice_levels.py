"""The coupling laws and directions weighed by the levels model
(idtool/_fit/_choice_levels.py): the criteria, and the one mechanism of every model
choice (choice_weights) weighing the options by them."""

from __future__ import annotations

import json
import math
from types import SimpleNamespace

import numpy as np
import pytest

from idtool._fit._choice_levels import LevelsCriterion, option_bests
from idtool._fit._run import choice_table, choice_weights


def _candidate(coupling: str, bic: float) -> SimpleNamespace:
    model = SimpleNamespace(
        coupling=SimpleNamespace(name=coupling), direction=SimpleNamespace(name="along")
    )
    return SimpleNamespace(model=model, bic=bic, aic=bic - 10.0)


def test_a_criterion_is_the_levels_models_bic_and_aic():
    c = LevelsCriterion(loglik=120.0, n_levels=38, n_params=7)
    assert c.bic == pytest.approx(7 * math.log(38) - 240.0)
    assert c.aic == pytest.approx(14.0 - 240.0)


def test_the_options_are_weighed_by_the_levels_model_where_it_scored_them():
    # trace-level BIC: power-limited far ahead (the scatter read as signal); the levels
    # model puts the exponential law ahead by 1.0 and the load-power law 3.0 behind it
    candidates = {
        "pl/slope": _candidate("power-limited", 3700.0),
        "pl/lag": _candidate("power-limited", 3710.0),
        "ex/slope": _candidate("exponential", 3900.0),
        "lp/slope": _candidate("load-power", 3720.0),
        "sdof/slope": _candidate("sdof", 8300.0),
    }
    of = lambda f: f.model.coupling.name  # noqa: E731
    assert option_bests(candidates, of) == {
        "power-limited": "pl/slope",  # each option's best by the trace-level BIC
        "exponential": "ex/slope",
        "load-power": "lp/slope",
        "sdof": "sdof/slope",
    }
    criteria = {
        "pl/slope": LevelsCriterion(100.0, 38, 7),
        "ex/slope": LevelsCriterion(100.5, 38, 7),
        "lp/slope": LevelsCriterion(100.8, 38, 8),
    }  # sdof: its levels model could not be estimated
    table = choice_weights(candidates, of, criteria)
    assert list(table) == ["exponential", "power-limited", "load-power", "sdof"]
    bic = np.array([criteria[table[n].key].bic for n in list(table)[:3]])
    w = np.exp(-0.5 * (bic - bic.min()))
    np.testing.assert_allclose([table[n].bic_weight for n in list(table)[:3]], w / w.sum())
    assert [table[n].criterion for n in table] == ["levels", "levels", "levels", "traces"]
    assert table["sdof"].bic_weight == table["sdof"].aic_weight == 0.0
    assert table["sdof"].bic == 8300.0  # its trace-level BIC, said so by its criterion
    assert table["exponential"].to_dict()["criterion"] == "levels"
    # the tables of each choice read the same criteria
    assert choice_table(candidates, "coupling", criteria) == table
    # without criteria (the levels model off): the trace-level BIC, as before
    plain = choice_weights(candidates, of)
    assert list(plain) == ["power-limited", "load-power", "exponential", "sdof"]
    assert {w.criterion for w in plain.values()} == {"traces"}
    assert plain["power-limited"].bic_weight > 0.9999


# ------------------------------------------------------------------ on a scatter bench
@pytest.mark.slow
@pytest.mark.study  # two fits comparing every coupling law (~2 min); make study runs it
def test_pull_to_pull_scatter_does_not_rule_out_the_true_law():
    """Truth 12 of the laws study (benchmarks/study_plan.py --goal laws --kinds scatter,
    drawn from a fit of the paper's matrix with 3% pull-to-pull scatter): a power limit
    on the matrix's 24 pulls, the scatter the fit model does not simulate. The traces'
    BIC read the scatter as signal and gave the true law a weight of 0.000 (the
    load-power law 1.000); weighed by the levels model, it keeps a share, as the data
    cannot tell the laws apart there."""
    import warnings
    from pathlib import Path

    import idtool
    from idtool._data._select import first_traces
    from idtool._simulate._params import BenchParams
    from idtool._simulate._simulate import simulate_bench
    from idtool._study._truths import Truth, design_points, truth_params

    task = json.loads(
        (Path(__file__).parent / "data" / "laws_study_scatter_truth.json").read_text()
    )
    truth = Truth.from_dict(task["truth"])
    doc = truth_params(truth, task["base"], task["rig"], task["friction_law"], task["departure"])
    dataset, _ = simulate_bench(
        BenchParams.from_dict(doc, "the laws study's truth 12"),
        int(task["seed"]),
        design_points(task["points"]),
    )
    existing = first_traces(dataset, int(task["before"]))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        levels = idtool.fit(existing, seed=0, coupling="auto")
        traces = idtool.fit(existing, seed=0, coupling="auto", variability=False)
    assert truth.law == "power-limited"
    by_traces = traces.coupling_laws
    assert {w["criterion"] for w in by_traces.values()} == {"traces"}
    assert by_traces[truth.law]["bic_weight"] < 0.01  # the defect this module fixes
    by_levels = levels.coupling_laws
    assert by_levels[truth.law]["criterion"] == "levels"
    assert by_levels[truth.law]["bic_weight"] > 0.05
    # no law the traces put ahead is certain under the levels model
    assert max(w["bic_weight"] for w in by_levels.values()) < 0.95
