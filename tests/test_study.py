"""idtool study (issue 29, items 2-3): truths drawn from a fit, simulated, fitted and
scored on a Dask LocalCluster of 2 workers; records streamed, resumed, failures kept.

One small design (sample_helpers.small_params: 8 traces), fits with one actuator and
offset model and no levels model (what the study runs is not the subject here), one
cluster for the file: its workers compile once.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
from sample_helpers import small_params

import idtool
from idtool._cli._main import main
from idtool._study._study import RECORDS, partial_folder, read_records, study, task_seed
from idtool._study._task import TIMING_KEYS

OPTIONS = {"actuator": "slope", "offset": "constant", "variability": False}


@pytest.fixture(scope="module")
def small():
    from idtool._fit._run import fit_dataset
    from idtool._workflow import Fit

    dataset, _ = idtool.simulate_bench(small_params(), seed=1)
    return Fit.from_run(dataset, fit_dataset(dataset, seed=0, **OPTIONS))


@pytest.fixture(scope="module")
def client():
    from idtool._study._dask import open_client

    with open_client(workers=2) as c:
        yield c


def _run(fit, client, out, truths, **kw):
    return study(
        fit,
        truths,
        out,
        client=client,
        params=small_params(),
        fit_options=OPTIONS,
        progress=False,
        seed=7,
        bad_truths=[3],
        **kw,
    )


def _scored(record: dict) -> dict:
    """A record without its timings and worker (what must not depend on the run)."""
    return {k: v for k, v in record.items() if k not in TIMING_KEYS}


@pytest.fixture(scope="module")
def interrupted_then_resumed(small, client, tmp_path_factory):
    out = tmp_path_factory.mktemp("study") / "s4"
    first = _run(small, client, out, 4, stop_after=2)
    partial = read_records(partial_folder(out) / RECORDS)
    assert not out.exists()  # nothing at OUT while unfinished
    second = _run(small, client, out, 4)
    return out, first, partial, second


def test_interrupted_study_resumes_without_loss(interrupted_then_resumed):
    out, first, partial, second = interrupted_then_resumed
    # stopped after 2: unfinished, the 2 records kept in OUT.partial
    assert first.summary is None and first.folder is None
    assert len(partial) == 2
    # resumed: every task once, the 2 from before unchanged (not run again)
    assert second.folder == out and not partial_folder(out).exists()
    lines = (out / RECORDS).read_text().splitlines()
    ids = [json.loads(line)["task_id"] for line in lines]
    assert sorted(ids) == [0, 1, 2, 3]  # none duplicated, none lost
    by_id = {r["task_id"]: r for r in second.records}
    for r in partial:
        assert by_id[r["task_id"]] == r
    for path in ("summary.json", "summary.txt", "study.png", "study.json"):
        assert (out / path).is_file()


def test_records_seeds_failure_and_summary(interrupted_then_resumed):
    out, _, _, s = interrupted_then_resumed
    records = {r["task_id"]: r for r in s.records}
    for i, r in records.items():
        assert r["seed"] == task_seed(7, i)
    # the bad truth (task 3, a negative Kt) failed with its located error; the rest ran
    assert "contact_stiffness_n_m" in records[3]["error"]
    ok = [r for i, r in records.items() if i != 3]
    assert all("error" not in r for r in ok)
    summary = json.loads((out / "summary.json").read_text())
    assert summary["succeeded"] == 3 and [f["task_id"] for f in summary["failed"]] == [3]
    # the coverage numbers are the records' counts
    for name in ("Kt", "mu"):
        cov = summary["parameters"][name]["coverage"]
        assert cov["n"] == 3
        assert cov["inside"] == sum(r["parameters"][name]["inside"] for r in ok)
        ranks = [r["parameters"][name]["rank"] for r in ok]
        assert sum(summary["parameters"][name]["sbc"]["counts"]) == 3
        assert all(0 <= k <= r["parameters"][name]["draws"] for k, r in zip(ranks, ok, strict=True))
    fr = summary["fr_coverage"]
    assert fr["inside"] == sum(t["inside"] for r in ok for t in r["targets"])
    assert fr["n"] == 3 * len(ok[0]["targets"])
    # each band's half-width is its interval's
    for r in ok:
        for t in r["targets"]:
            assert t["half_width"] == pytest.approx((t["ci95"][1] - t["ci95"][0]) / 2)
    assert summary["laws"]["wins"] == sum(r["law"] == r["truth"]["law"] for r in ok)


def test_same_seed_same_records(small, client, tmp_path, interrupted_then_resumed):
    """A study of 2 with the same seed: its tasks are the first 2 of the study of 4,
    run again on other workers in another order, with the same records."""
    _, _, _, four = interrupted_then_resumed
    two = _run(small, client, tmp_path / "s2", 2)
    assert [_scored(r) for r in two.records] == [_scored(r) for r in four.records[:2]]
    # not the same truths under another seed
    assert task_seed(8, 0) != task_seed(7, 0)


def test_cli_errors_are_located(tmp_path, capsys):
    (tmp_path / "done").mkdir()
    cases = [
        (["study", str(tmp_path), "--out", str(tmp_path / "done")], "--force"),
        (["study", str(tmp_path), "--out", str(tmp_path / "o"), "--truths", "0"], "--truths"),
        (["study", str(tmp_path), "--out", str(tmp_path / "o"), "--plan", "nowhere"], "plan.json"),
        (["study", str(tmp_path), "--out", str(tmp_path / "o")], "fit.json"),
        (["study", str(tmp_path), "--out", str(tmp_path / "o"), "--workers", "0"], "--workers"),
    ]
    for argv, what in cases:
        assert main(argv) == 2
        err = capsys.readouterr().err
        assert what in err and "Traceback" not in err
    assert not (tmp_path / "o").exists() and not (tmp_path / "o.partial").exists()


def test_partial_of_other_settings_refused(small, tmp_path):
    from idtool._errors import IdtoolError

    out = tmp_path / "s"
    partial = partial_folder(out)
    partial.mkdir()
    (partial / "study.json").write_text(json.dumps({"truths": 99}))
    with pytest.raises(IdtoolError, match="other settings"):
        _run(small, None, out, 2)
    assert np.array_equal(sorted(p.name for p in partial.iterdir()), ["study.json"])


def test_a_laws_plan_is_scored_by_the_weights_it_moves(small):
    """A task of a plan for the goal ``laws`` fits the existing pulls alone too (the
    first ``before`` traces of the same simulated bench): its record carries each law's
    weight before, and the summary counts the truths whose law gained weight."""
    from idtool._data._select import first_traces
    from idtool._study._study import _base_params, _rig
    from idtool._study._summary import summarise
    from idtool._study._task import run_task
    from idtool._study._truths import draw_truths

    fit = small
    data = fit.model.data
    on_s = np.asarray(data.on_end_s) - np.asarray(data.on_start_s)
    points = [
        [float(x) for x in row]
        for row in zip(
            data.normal_load_n, data.amplitude_fraction, data.pull_speed_m_s, on_s, strict=True
        )
    ]
    truth = draw_truths(fit.draws(max_draws=50, seed=0), 1, 0)[0]
    task = {
        "task_id": 0,
        "seed": 11,
        "truth": truth.to_dict(),
        "base": _base_params(small_params()),
        "rig": _rig(fit),
        "friction_law": fit.model.law.name,
        "departure": "clean",
        "points": points,
        "targets": [[670.0, 0.7, float(data.pull_speed_m_s[0])]],
        "fit_options": OPTIONS,
        "sample": False,
        "before": 6,
    }
    record = run_task(task)
    assert set(record["law_weights_before"]) == set(record["law_weights"])
    assert record["before_fit_s"] > 0
    # first_traces keeps the order, and refuses a count it cannot give
    assert [t.id for t in first_traces(fit.dataset, 6).traces] == [
        t.id for t in fit.dataset.traces[:6]
    ]
    with pytest.raises(ValueError, match="n = 9"):
        first_traces(fit.dataset, 9)

    # the summary's count, on records whose weights are known
    def rec(law, before, after):
        return {
            "task_id": 0,
            "truth": {"law": law, "values": {}},
            "law": max(after, key=after.get),
            "law_weights": after,
            "law_weights_before": before,
            "parameters": {},
            "targets": [],
            "fit_s": 1.0,
            "task_s": 1.0,
        }

    records = [
        rec("a", {"a": 0.4, "b": 0.6}, {"a": 0.9, "b": 0.1}),  # rose, now chosen
        rec("a", {"a": 0.7, "b": 0.3}, {"a": 0.6, "b": 0.4}),  # fell
        rec("b", {"a": 0.5, "b": 0.5}, {"a": 0.2, "b": 0.8}),  # rose
        rec("b", {"a": 0.02, "b": 0.98}, {"a": 0.03, "b": 0.97}),  # fell, but held >= 0.95
    ]
    laws = summarise(records, {}, 1.0)["laws"]
    assert (laws["n_before"], laws["rose"], laws["held"]) == (4, 2, 3)
    assert (laws["wins_before"], laws["wins"]) == (2, 4)
    assert laws["truth_weight_mean_before"] == pytest.approx((0.4 + 0.7 + 0.5 + 0.98) / 4)
