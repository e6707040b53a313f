"""A friction table that records when each row was measured (``time_s``): the format,
the import, and the horn drift the fit then fits (idtool/_levels/_model.py).

A horn whose output falls over a campaign whose rows were measured in a random order
moves Kt out of its interval in the transverse direction (5 of 8 simulated tables
inside, benchmarks/study_benches.py); with the rows' times the fit fits the drift."""

from __future__ import annotations

import json

import numpy as np
import pytest

import idtool
from idtool._cli._main import main
from idtool._levels._model import levels_model
from idtool._simulate._table import GAIN_DRIFT, ROW_INTERVAL_S, TABLE_TRUTH, table_friction_ratio
from tests.test_levels_table import table_csv

# the simulator's gain, 1 - GAIN_DRIFT (tau + 1/2), relative to the campaign's middle
TRUE_DRIFT = -GAIN_DRIFT / (1.0 - GAIN_DRIFT / 2.0)


def test_times_are_read_in_their_unit_and_kept_through_the_dataset(tmp_path, capsys):
    """``time (min)`` in the CSV -> ``time_s`` [s] in dataset.json and back; the
    campaign position runs from -1/2 (first row) to 1/2 (last); ``idtool validate``
    lists them."""
    table = idtool.simulate_table(0, departure="gain-drift", record_times=True)
    assert table.has_times
    data = tmp_path / "data"
    idtool.import_levels(table_csv(table, tmp_path / "t.csv"), data, material="m")
    back = idtool.load_levels(data)
    np.testing.assert_allclose(back.time_s, table.time_s, rtol=1e-12, atol=1e-9)
    doc = json.loads((data / "dataset.json").read_text())
    assert all("time_s" in row for row in doc["rows"])
    tau = back.campaign_position
    assert tau.min() == -0.5 and tau.max() == 0.5
    assert np.ptp(back.time_s) == ROW_INTERVAL_S * (table.n_rows - 1)
    assert main(["validate", str(data)]) == 0
    said = capsys.readouterr().out
    assert "time [min]" in said and "measured over 4.42 h" in said  # 53 x 5 min
    # a table without times: none written, no drift in its model
    plain = idtool.simulate_table(0, departure="gain-drift")
    assert not plain.has_times and not np.any(plain.campaign_position)
    assert "horn_drift" not in levels_model(plain).names
    assert levels_model(back).names[-1] == "horn_drift"
    # the drawn times leave the table's numbers as they were without them
    np.testing.assert_array_equal(plain.on, table.on)


def test_a_time_on_some_rows_only_is_a_located_error(tmp_path):
    table = idtool.simulate_table(0, record_times=True)
    csv = table_csv(table, tmp_path / "t.csv")
    lines = csv.read_text().splitlines()
    lines[3] = lines[3].rsplit(",", 1)[0] + ","  # row 3's time left empty
    csv.write_text("\n".join(lines) + "\n")
    with pytest.raises(idtool.IdtoolError) as err:
        idtool.import_levels(csv, tmp_path / "data", material="m")
    located = [(p.row, p.column) for p in err.value.problems]
    assert (3, "time (min)") in located, err.value.problems
    assert not (tmp_path / "data").exists()  # nothing half-written
    # the dataset.json form: the first row without one named
    doc = table.to_document()
    del doc["rows"][4]["time_s"]
    path = tmp_path / "doc"
    path.mkdir()
    (path / "dataset.json").write_text(json.dumps(doc))
    with pytest.raises(idtool.IdtoolError) as err:
        idtool.load_levels(path)
    assert [p.column for p in err.value.problems] == ["rows[4].time_s"]
    assert "give every row's measurement time, or none" in err.value.problems[0].message


@pytest.mark.parametrize("direction", ["along", "transverse"])
def test_the_drift_model_is_the_simulators_gain_at_each_rows_time(direction):
    """The model's FR of every row at the truth and the true drift against the
    simulator's own FR at that row's gain (``table_friction_ratio(gain_scale=...)``,
    the power limit's gain scaled, where the model scales the reference amplitude: the
    same for every table coupling, each proportional to it): to 1e-10. At zero drift
    it is the model without times."""
    table = idtool.simulate_table(
        2, direction=direction, departure="gain-drift", record_times=True,
        scatter_fr=0.0, discrepancy=0.0, scatter_mu=0.0,
    )  # fmt: skip
    model = levels_model(table, coupling="power-limited", direction=direction)
    # the fit's gain is the campaign's middle's
    middle = {**TABLE_TRUTH, "coupling_gain": TABLE_TRUTH["coupling_gain"] * (1 - GAIN_DRIFT / 2)}
    theta = model.internal(**middle, horn_drift=TRUE_DRIFT)
    fr = np.exp(np.asarray(model.log_levels(theta))[table.n_rows :])
    gain = 1.0 - GAIN_DRIFT * (table.campaign_position + 0.5)
    truth = [
        table_friction_ratio(n, a, v, direction=direction, gain_scale=g)
        for n, a, v, g in zip(
            table.normal_load_n, table.amplitude_m, table.sliding_speed_m_s, gain, strict=True
        )
    ]
    np.testing.assert_allclose(fr, truth, rtol=1e-10)
    np.testing.assert_allclose(fr, table.friction_ratio, rtol=1e-10)  # no noise drawn
    assert np.ptp(np.log(fr)) > 0.1  # the drift moves FR: not a vacuous comparison
    untimed = idtool.LevelsTable(**{**table.__dict__, "time_s": np.full(table.n_rows, np.nan)})
    plain = levels_model(untimed, coupling="power-limited", direction=direction)
    np.testing.assert_allclose(
        np.asarray(model.log_levels(model.internal(**TABLE_TRUTH, horn_drift=0.0))),
        np.asarray(plain.log_levels(plain.internal(**TABLE_TRUTH))),
        rtol=0.0, atol=1e-13,
    )  # fmt: skip


def test_a_timed_drifting_table_holds_kt_and_the_drift(tmp_path):
    """Transverse vibration, the horn's gain falling 15% over the campaign, rows in a
    random order (seed 0). Without the times Kt was stated [4.8e6, 2.0e7] N/m against
    2e6 (the drift read as Kt); imported with a ``time (min)`` column and fitted with
    the defaults, Kt's interval holds 2e6, the drift's holds the truth (-0.162), and a
    saved fit loads with the same estimates."""
    table = idtool.simulate_table(
        0, direction="transverse", departure="gain-drift", record_times=True
    )
    data = tmp_path / "data"
    idtool.import_levels(table_csv(table, tmp_path / "t.csv"), data, material="m")
    fit = idtool.fit_levels(data, direction="transverse", seed=0)
    kt, drift = fit.estimates["Kt"], fit.estimates["horn_drift"]
    assert kt.ci95[0] <= TABLE_TRUTH["Kt"] <= kt.ci95[1], kt.statement
    assert drift.ci95[0] <= TRUE_DRIFT <= drift.ci95[1], drift.statement
    assert not drift.one_sided and drift.ci95[1] < 0  # the fall is resolved, both sides
    mu = fit.estimates["mu"]
    assert mu.ci95[0] <= TABLE_TRUTH["mu"] <= mu.ci95[1]
    assert "horn_drift" in fit.report()
    back = idtool.load_levels_fit(fit.save(tmp_path / "fit"))
    for name in ("Kt", "mu", "horn_drift"):
        assert back.estimates[name].ci95 == pytest.approx(fit.estimates[name].ci95, rel=1e-9)
