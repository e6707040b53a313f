"""idtool compare on fits of friction tables (issue 30, item 1): which material reduces
friction more, at the conditions every table measured.

Two simulated tables (tests/test_levels_table.simulate_table: 3 loads x 3 amplitudes x 2
speeds x 3 repeats, 3% scatter, 2% discrepancy): material A at the module's truth, B with
60% of its coupling gain (less vibration reaches the contact: less reduction).
"""

from __future__ import annotations

import json

import numpy as np
import pytest
from test_levels_table import TRUTH, simulate_table, table_csv

import idtool
from idtool._cli._main import main

WEAKER = {**TRUTH, "coupling_gain": 0.6 * TRUTH["coupling_gain"]}


def true_fr(truth: dict, n: float, a_m: float, v: float) -> float:
    coupling = idtool.PowerLimitedCoupling(
        gain=truth["coupling_gain"], power_load_n=truth["power_load_n"]
    )
    law = idtool.Dahl.at_load(truth, n)
    return float(idtool.on_friction_ratio(law, coupling, n, a_m / 6e-6, v, 22e3, 6e-6))


@pytest.fixture(scope="module")
def folders(tmp_path_factory):
    """A, B and A again (another seed) fitted and saved."""
    root = tmp_path_factory.mktemp("levels_compare")
    out = {}
    for label, seed, truth in (("A", 0, TRUTH), ("B", 1, WEAKER), ("A2", 2, TRUTH)):
        t = simulate_table(seed, truth=truth)
        csv = table_csv(t, root / f"{label}.csv")
        ds = idtool.import_levels(csv, root / f"ds-{label}", material=label, friction="force")
        # the simulator's coupling law alone: the by-design default would average in the
        # load-power law, whose wider bands leave too few conditions clear for the test
        out[label] = idtool.fit_levels(ds, coupling="power-limited").save(root / label)
    return out


@pytest.fixture(scope="module")
def a_vs_b(folders):
    return idtool.compare_fits([folders["A"], folders["B"]], seed=0)


def test_the_material_with_the_stronger_coupling_reduces_more(a_vs_b):
    """At every condition A's true FR is below B's; the comparison says A reduces more
    (probability > 0.95) wherever the truths differ by more than 4 bands' worth, never
    names B, and each fit's band holds its own truth at most conditions."""
    c = a_vs_b
    assert isinstance(c, idtool.TableComparison)
    assert c.labels == ("A", "B") and c.sources == ("covariance", "covariance")
    assert c.conditions.shape == (18, 4)  # 3 x 3 x 2, every table's
    truths = np.array(
        [[true_fr(t, n, a, v) for n, a, v, _ in c.conditions] for t in (TRUTH, WEAKER)]
    )
    assert (truths[0] < truths[1]).all()
    half = (c.band[:, :, 1] - c.band[:, :, 0]) / 2
    clear = truths[1] - truths[0] > 2 * (half[0] + half[1])
    # the test has teeth: conditions far apart (5 of 18 since the bands integrate the
    # discrepancy sd over its likelihood, 6 at REML's estimate)
    assert clear.sum() >= 5, clear.sum()
    assert (c.prob_ref_lower[0, clear] > 0.95).all()
    assert (c.prob_ref_lower[0] > 0.05).all()  # B never named the better one
    assert (c.diff_pp[0, clear] > 0).all()
    inside = (c.band[:, :, 0] <= truths) & (truths <= c.band[:, :, 1])
    assert inside.sum() >= 0.85 * inside.size, inside.sum()  # 95% bands; 36 of them
    assert c.pinned.all()


def test_a_fit_against_itself_is_undecided(folders):
    """Independent draws of one fit on both sides: each probability within 4 Monte Carlo
    standard errors of 1/2 (the two sides' streams are not the same normals)."""
    c = idtool.compare_fits([folders["A"], folders["A"]], seed=3)
    p, se = c.prob_ref_lower[0], c.prob_se[0]
    assert (np.abs(p - 0.5) < 4 * se).all(), (p, se)


def test_cli_writes_the_comparison_and_refuses_what_does_not_apply(folders, tmp_path, capsys):
    out = tmp_path / "cmp"
    argv = ["compare", str(folders["A"]), str(folders["B"]), str(folders["A2"]), "--out", str(out)]
    assert main(argv) == 0
    text = capsys.readouterr().out
    assert "reference A" in text and "A vs B" in text and "A vs A2" in text
    for name in ("compare.txt", "compare.json", "fr_by_condition.png"):
        assert (out / name).is_file(), name
    doc = json.loads((out / "compare.json").read_text())
    assert doc["kind"] == "levels" and doc["reference"] == "A"
    assert len(doc["conditions"]) == 18
    row = doc["conditions"][0]
    assert set(row["fits"]) == {"A", "B", "A2"} and set(row["against_reference"]) == {"B", "A2"}
    assert set(doc["fits"][0]["estimates"]) >= {"Kt", "mu"}
    # nothing overwritten without --force; options of trace fits refused, located
    assert main(argv) == 2
    assert "--force" in capsys.readouterr().err
    bad = ["compare", str(folders["A"]), str(folders["B"]), "--amplitude", "0.5"]
    assert main([*bad, "--out", str(tmp_path / "x")]) == 2
    err = capsys.readouterr().err
    assert "--amplitude and --targets apply to fits of bench traces" in err
    assert "Traceback" not in err and not (tmp_path / "x").exists()
    # --load moves the conditions: every load given x the tables' other values
    assert main([*argv[:3], "--load", "70", "--out", str(tmp_path / "l"), "--json"]) == 0
    doc = json.loads(capsys.readouterr().out.split("\ncompare:")[0])
    assert {r["normal_load_n"] for r in doc["conditions"]} == {70.0}
    assert len(doc["conditions"]) == 6


def test_a_table_and_a_trace_fit_are_not_compared(folders, small_fit_folder, capsys):
    argv = ["compare", str(folders["A"]), str(small_fit_folder), "--out", "unused"]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert "compare fits of one kind" in err and str(small_fit_folder) in err
