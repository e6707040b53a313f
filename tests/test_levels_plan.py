"""``idtool plan`` on a friction table's fit (issue 30, item 1; issue 29's goals on a
table): the linearised plan agrees with the fit's own band now, and after its rows
with what refitting the table with those rows simulated achieves; the planned rows
beat a uniform choice; the operator's sheet is a table ``idtool import-levels`` reads
once its OFF and ON are filled in."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest
from test_levels_table import TRUTH, simulate_table, table_csv

import idtool
from idtool._cli._main import EXIT_BAD_INPUT, main

pytestmark = pytest.mark.slow

# beyond the table's loads (20-100 N): where a band is wide and rows pay
TARGET = (150.0, 6e-6, 0.08)


def true_fr(n: float, a_m: float, v: float) -> float:
    coupling = idtool.PowerLimitedCoupling(
        gain=TRUTH["coupling_gain"], power_load_n=TRUTH["power_load_n"]
    )
    law = idtool.Dahl.at_load(TRUTH, n)
    return float(idtool.on_friction_ratio(law, coupling, n, a_m / 6e-6, v, 22e3, 6e-6))


def with_rows(table: idtool.LevelsTable, rows, seed: int) -> idtool.LevelsTable:
    """``table`` and the planned ``rows`` simulated at the truth as simulate_table does
    (3% scatter, 2% discrepancy per condition, 2% OFF scatter)."""
    rng = np.random.default_rng(1000 + seed)
    keys = sorted({(r.normal_load_n, r.amplitude_m, r.sliding_speed_m_s) for r in rows})
    d = dict(zip(keys, rng.normal(0.0, 0.02, len(keys)), strict=True))
    new = {"n": [], "a": [], "v": [], "off": [], "on": []}
    for r in rows:
        key = (r.normal_load_n, r.amplitude_m, r.sliding_speed_m_s)
        off = TRUTH["mu"] * key[0] * np.exp(rng.normal(0.0, 0.02))
        on = off * true_fr(*key) * np.exp(d[key] + rng.normal(0.0, 0.03))
        for name, x in zip(new, (*key, off, on), strict=False):
            new[name].append(x)
    k = len(rows)
    add = {
        "normal_load_n": new["n"], "amplitude_m": new["a"], "sliding_speed_m_s": new["v"],
        "off": new["off"], "on": new["on"], "amplitude_fraction": [np.nan] * k,
        "vibration_frequency_hz": [22e3] * k, "off_se": [np.nan] * k, "on_se": [np.nan] * k,
        "time_s": [np.nan] * k,  # the table records no times
    }  # fmt: skip
    fields = {
        f.name: np.concatenate([getattr(table, f.name), np.asarray(add[f.name], float)])
        for f in dataclasses.fields(table)
        if f.name in add
    }
    repeat = (*table.repeat, *(f"p{i}" for i in range(k)))
    return dataclasses.replace(table, **fields, repeat=repeat)


def half_width(fit, n, a, v) -> float:
    p = fit.predict(n, v, amplitude_m=a)
    return float(np.squeeze(p.mean_band[1] - p.mean_band[0])) / 2


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_the_plan_expects_what_its_rows_achieve(seed):
    """Now: the plan's half-width is the fit's band (the same linear model; a pinned
    target). After its 6 rows, simulated at the truth and the table refitted (the sds
    re-estimated): the achieved half-width within 30% of the expected (issue 29's
    target; measured 2-13% off on seeds 0-3), narrower than before, and the truth
    inside the new band."""
    table = simulate_table(seed)
    # one model (the plan's linear model is the best model's; the default by-design fit
    # averages its predictions over two, checked in the test below)
    fit = idtool.fit_levels(table, coupling="power-limited", seed=seed)
    plan = fit.plan("band", 6, at=[TARGET], half_width=0.005)
    # (to 1e-3: the planner's weak prior on theta, sd 7 internal units, which the fit's
    # covariance has not: 1e-4 on seed 0). Where the table leaves a parameter one-sided
    # (seed 0's power_load_n, not bounded above: P -> inf is the constant law, and every
    # alpha N of the table lies below it), predict widens the band to its interval's end
    # and the linear model cannot: the plan says so and its band is the narrower
    loose = [n for n, e in fit.estimates.items() if e.one_sided or e.weakly_identified]
    if loose:
        assert any("not bounded on both sides" in n for n in plan.notes), plan.notes
        assert plan.values[0] <= half_width(fit, *TARGET) * (1 + 1e-3)
    else:
        assert plan.values[0] == pytest.approx(half_width(fit, *TARGET), rel=1e-3)
    assert len(plan.rows) == 6 and all(np.diff(plan.values) <= 1e-12)
    assert plan.values[-1] <= plan.uniform[-1]
    refit = idtool.fit_levels(
        with_rows(table, plan.rows, seed), coupling="power-limited", seed=seed
    )
    achieved = half_width(refit, *TARGET)
    assert achieved == pytest.approx(plan.values[-1], rel=0.3), (achieved, plan.values)
    assert achieved < half_width(fit, *TARGET)
    p = refit.predict(TARGET[0], TARGET[2], amplitude_m=TARGET[1])
    assert p.mean_band[0] <= true_fr(*TARGET) <= p.mean_band[1]


def test_the_parameters_goal_beats_a_uniform_choice_and_cannot_go_below_nothing():
    fit = idtool.fit_levels(simulate_table(0))
    plan = fit.plan("parameters", 6, grid=4)
    # the default fit of a table at two speeds compares two coupling laws: the plan says
    # it plans on the best one
    assert len(fit.ranking) == 2 and fit.alternates
    assert any(
        n.startswith(f"planned on the best model ({fit.ranking[0].name}") for n in plan.notes
    )
    assert plan.unit == "relative sd" and not plan.met
    assert all(np.diff(plan.values) <= 1e-12) and plan.values[-1] < plan.values[0]
    assert plan.values[-1] < plan.uniform[-1]
    # the linear model's now is the fit's: the largest relative sd of its estimates
    # (Wald, where both sides are Wald)
    wald = [e.std_error / e.estimate for e in fit.estimates.values() if np.isfinite(e.std_error)]
    assert plan.values[0] >= max(wald) * 0.99
    with pytest.raises(idtool.IdtoolError, match="band goal needs its conditions"):
        fit.plan("band")
    with pytest.raises(idtool.IdtoolError, match="choose one of band, parameters"):
        fit.plan("laws")


def test_the_command_line_writes_a_sheet_that_imports(tmp_path, capsys):
    table = simulate_table(0)
    table_csv(table, tmp_path / "t.csv")
    idtool.import_levels(tmp_path / "t.csv", tmp_path / "ds", material="m", friction="force")
    assert main(["fit", str(tmp_path / "ds"), "--out", str(tmp_path / "fit")]) == 0
    out = tmp_path / "plan"
    argv = ["plan", str(tmp_path / "fit"), "--at", "150,1.0", "--speeds", "0.08", "--pulls",
            "4", "--grid", "4x4", "--out", str(out)]  # fmt: skip
    assert main(argv) == 0
    text = capsys.readouterr().out
    assert "goal band" in text and "150 N, 6 um, 80 mm/s" in text
    doc = json.loads((out / "plan.json").read_text())
    assert doc["kind"] == "levels" and len(doc["rows"]) == 4
    assert main(argv) == EXIT_BAD_INPUT  # the folder exists: --force
    assert "--force" in capsys.readouterr().err
    # the sheet, OFF and ON filled in, is a table import-levels reads
    sheet = (out / "plan.csv").read_text().splitlines()
    filled = [sheet[0]] + [row.rstrip(",") + ",45.0,20.0" for row in sheet[1:]]
    (tmp_path / "filled.csv").write_text("\n".join(filled) + "\n")
    more = idtool.import_levels(
        tmp_path / "filled.csv", tmp_path / "ds2", material="m", friction="force"
    )
    assert more.n_rows == 4 and np.allclose(more.normal_load_n, 150.0)
    assert main(["plan", str(tmp_path / "fit"), "--next-pull", "--at", "150,1", "--out",
                 str(tmp_path / "p2")]) == EXIT_BAD_INPUT  # fmt: skip
    assert "applies to bench traces" in capsys.readouterr().err
