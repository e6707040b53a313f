"""The posterior and report.html of a friction table's fit (kind: levels, issue 30):
``idtool sample`` and ``LevelsFit.sample`` on the table's likelihood through the bench
sampler's machinery, predictions from the draws, ``idtool report``, and the commands
that do not apply to a table yet."""

from __future__ import annotations

import dataclasses
import json
import subprocess
import sys

import matplotlib
import numpy as np
import pytest
from test_levels_table import TRUTH, dong_dapino, simulate_table

import idtool
from idtool._cli._main import EXIT_BAD_INPUT, EXIT_NOT_CONVERGED, main

matplotlib.use("Agg")

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def dd_fit(tmp_path_factory):
    """The published two-row summary, imported and fitted with the command line."""
    tmp = tmp_path_factory.mktemp("levels_sample")
    ds = tmp / "ds"
    idtool.import_levels(
        dong_dapino(tmp), ds, material="steel pin on disc", friction="coefficient",
        source="Dong & Dapino (assumed load and amplitude)",
    )  # fmt: skip
    assert main(["fit", str(ds), "--out", str(tmp / "fit")]) == 0
    return tmp / "fit"


def test_cli_sample_writes_resumes_and_refuses_to_overwrite(dd_fit, capsys):
    # plumbing: a fixed, short chain (not converged: exit 3, outputs written)
    argv = ["sample", str(dd_fit), "--steps", "60", "--no-progress"]
    assert main(argv) == EXIT_NOT_CONVERGED
    out = capsys.readouterr()
    assert "did NOT converge" in out.err and "Traceback" not in out.err
    for name in ("chain.h5", "posterior.nc", "sample.json", "report_sample.txt"):
        assert (dd_fit / name).is_file(), name
    doc = json.loads((dd_fit / "sample.json").read_text())
    assert doc["kind"] == "levels" and doc["diagnostics"]["steps"] == 60
    assert set(doc["summary"]) >= {"Kt", "mu", "coupling_gain", "discrepancy_fr"}
    assert main(argv) == EXIT_BAD_INPUT  # chain.h5 exists
    assert "--resume" in capsys.readouterr().err
    assert main([*argv[:3], "80", "--no-progress", "--resume"]) == EXIT_NOT_CONVERGED
    capsys.readouterr()
    assert json.loads((dd_fit / "sample.json").read_text())["diagnostics"]["steps"] == 80
    # the same seed and length from scratch gives the chain the resumed one is
    fresh = idtool.load_levels_fit(dd_fit)
    assert fresh.posterior is not None and fresh.posterior.diagnostics["steps"] == 80
    assert main([*argv[:3], "80", "--no-progress", "--force"]) == EXIT_NOT_CONVERGED
    capsys.readouterr()
    again = idtool.load_levels_fit(dd_fit)
    np.testing.assert_array_equal(again.posterior.draws["Kt"], fresh.posterior.draws["Kt"])
    # predictions and the figure from the draws
    p = again.predict(10.0, [0.0203, 0.087], amplitude_m=5e-6)
    assert p.pinned.all() and np.all(p.mean_band[0] <= p.fr) and np.all(p.fr <= p.mean_band[1])
    assert (dd_fit / "fr_vs_speed.png").is_file()
    assert main(["sample", str(dd_fit), "--noise", "gaussian"]) == EXIT_BAD_INPUT
    assert "--noise applies to traces only" in capsys.readouterr().err


def test_report_has_its_sections_and_figures(dd_fit, capsys):
    if not (dd_fit / "posterior.nc").is_file():
        assert main(["sample", str(dd_fit), "--steps", "40", "--no-progress", "--force"]) in (0, 3)
    assert main(["report", str(dd_fit)]) == 0
    capsys.readouterr()
    page = (dd_fit / "report.html").read_text()
    for text in (
        "Answer", "Friction ratio against sliding speed", "What to measure next",
        "every physical parameter within a 5% relative sd", "Estimates", "posterior median",
        "Data", "Convergence", "Provenance", "Sign-off", "IDT-",
        "cannot pin a 2-parameter coupling law", "data:image/png;base64",
    ):  # fmt: skip
        assert text in page, text
    assert (dd_fit / "figures" / "fr_vs_speed.png").is_file()
    assert (dd_fit / "report.md").is_file()


def test_plan_refuses_the_laws_goal_on_a_table_and_compare_reads_it(dd_fit, tmp_path):
    # idtool plan on tables: tests/test_levels_plan.py; the laws goal is the traces'
    run = subprocess.run(
        [sys.executable, "-m", "idtool._cli._main", "plan", str(dd_fit), "--goal", "laws",
         "--out", str(tmp_path / "p")],
        capture_output=True, text=True,
    )  # fmt: skip
    assert run.returncode == EXIT_BAD_INPUT, run.stderr
    assert "Traceback" not in run.stderr
    assert "--goal laws plans pulls of bench traces" in run.stderr
    assert not (tmp_path / "p").exists()
    with pytest.raises(idtool.IdtoolError, match="friction table"):
        idtool.load_fit(dd_fit)
    # compare reads table fits (tests/test_levels_compare.py): the two-row summary
    # against itself, at its two conditions
    out = tmp_path / "c"
    assert main(["compare", str(dd_fit), str(dd_fit), "--out", str(out), "--no-figures"]) == 0
    doc = json.loads((out / "compare.json").read_text())
    assert doc["kind"] == "levels" and len(doc["conditions"]) == 2


def two_repeats(table: idtool.LevelsTable) -> idtool.LevelsTable:
    """``table``'s rows of the first two repeats (36 of 54: the default run converges
    in about half the time, 80 s against 160 s on 2 cores)."""
    keep = np.array([r in ("0", "1") for r in table.repeat])
    fields = {}
    for f in dataclasses.fields(table):
        v = getattr(table, f.name)
        fields[f.name] = v[keep] if isinstance(v, np.ndarray) and v.shape == keep.shape else v
    fields["repeat"] = tuple(r for r, k in zip(table.repeat, keep, strict=True) if k)
    return idtool.LevelsTable(**fields)


@pytest.mark.study
def test_default_sample_converges_and_covers_the_truth_of_a_simulated_table():
    """The default run (until converged) on a simulated table: the truth of Kt and mu
    inside the posterior's 95% intervals, the bands from the draws."""
    fit = idtool.fit_levels(two_repeats(simulate_table(0)))
    post = fit.sample()
    assert post.converged, post.diagnostics["messages"]
    # sheared along Kt's profile with the load scale redrawn (idtool._levels._sample):
    # 10,824 steps; 17,694 on the box's coordinates alone
    assert post.diagnostics["steps"] < 15_000, post.diagnostics["steps"]
    summary = post.summary()
    for name in ("Kt", "mu"):
        lo, hi = summary[name]["ci95"]
        assert lo < TRUTH[name] < hi, (name, lo, hi)
    p = fit.predict(50.0, [0.02, 0.08], amplitude_m=4e-6)
    assert np.all(p.next_band[1] - p.next_band[0] > p.mean_band[1] - p.mean_band[0])
    print("steps", post.diagnostics["steps"], "timing", post.timing)
