"""Fixing parameters and the PEtab-like parameter table (issue 13, item 2): ``--fix
mu=0.3``, ``--parameters table.tsv`` and ``idtool parameters``.

Checked on what must follow: a parameter fixed at its truth costs the likelihood no more
than a chi-square(1) would (a likelihood-ratio test), one fixed off its truth costs far
more; a fixed parameter is neither estimated nor sampled nor counted in BIC, and its
value reaches the physics; bounds and scale change the transform and the default prior;
a table's prior reaches the sampler; every problem of a table is named by row and
column, with exit status 2 and nothing written."""

import json
import math

import numpy as np
import pytest
from sample_helpers import small_params, truth

import idtool
from idtool._cli._main import main
from idtool._model._benchmodel import shared_params_of
from idtool._model._settings import apply_settings
from idtool._posterior._sample import _resolve

# one actuator and offset model, noise only: what fixing changes is the point (CI time)
FAST = {"actuator": "slope", "offset": "constant", "variability": False}
CHI2_1_999 = 10.83  # 99.9% quantile of chi-square with 1 degree of freedom


@pytest.fixture(scope="module")
def dataset():
    data, _ = idtool.simulate_bench(small_params(), seed=3)
    return data


@pytest.fixture(scope="module")
def free(dataset):
    return idtool.fit(dataset, **FAST)


@pytest.fixture(scope="module")
def fixed_at_truth(dataset):
    return idtool.fit(dataset, fix={"mu": truth()["mu"]}, **FAST)


def test_a_fixed_parameter_is_not_estimated_but_reported(free, fixed_at_truth):
    mu = fixed_at_truth.estimates["mu"]
    assert mu.fixed and mu.estimate == truth()["mu"] and mu.std_error == 0.0
    assert mu.ci95 == (truth()["mu"], truth()["mu"])
    model = fixed_at_truth.model
    assert "mu" not in model.names and model.fixed == {"mu": truth()["mu"]}
    assert fixed_at_truth.result.n_params == free.result.n_params - 1
    line = next(ln for ln in fixed_at_truth.report().splitlines() if ln.split()[:1] == ["mu"])
    assert "fixed by the user" in line, line


def test_fixing_at_the_truth_costs_what_a_chi_square_allows(free, fixed_at_truth):
    # the constrained maximum cannot exceed the free one; at the truth, twice the drop
    # is chi-square(1) under the model (Wilks), so beyond its 99.9% quantile is a defect
    drop = 2.0 * (free.result.loglik - fixed_at_truth.result.loglik)
    assert -1e-3 < drop < CHI2_1_999, drop
    # the other physical parameters still find their truths
    for name in ("Kt", "coupling_gain"):
        lo, hi = fixed_at_truth.estimates[name].ci95
        assert lo <= truth()[name] <= hi, (name, lo, hi)


def test_fixing_off_the_optimum_costs_what_its_standard_error_says(dataset, free):
    # mu held 3 standard errors (Gauss-Newton) from the free optimum: twice the drop of
    # the log-likelihood (the likelihood-ratio statistic) should be ~3^2 = 9, the Wald
    # statistic, where the model is near-linear in the parameters. Far off, it is not:
    # 3% off mu (~70 standard errors) the AR(1) coefficient absorbs part of the misfit
    # as correlated noise, and the ratio falls to ~0.1.
    mu = free.estimates["mu"]
    held = mu.estimate + 3.0 * mu.std_error
    off = idtool.fit(dataset, fix={"mu": held}, **FAST)
    drop = 2.0 * (free.result.loglik - off.result.loglik)
    assert 9.0 / 1.5 < drop < 9.0 * 1.5, drop
    assert off.estimates["mu"].estimate == held


def test_the_fixed_value_reaches_the_physics(fixed_at_truth):
    model = fixed_at_truth.model
    v = model.values(np.asarray(fixed_at_truth.result.z))
    assert "mu" not in v
    law = model.law_at(v, 400.0)
    assert float(law.fc_n) == pytest.approx(truth()["mu"] * 400.0, rel=1e-12)


def test_a_saved_fit_keeps_its_settings_and_the_sampler_skips_them(fixed_at_truth, tmp_path):
    out = fixed_at_truth.save(tmp_path / "fit")
    doc = json.loads((out / "fit.json").read_text())
    assert doc["parameters"]["mu"]["fixed"] is True
    assert doc["parameter_settings"] == [
        {"name": "mu", "estimate": False, "nominal": truth()["mu"], "source": "--fix mu=0.3"}
    ]
    back = idtool.load_fit(out)
    assert back.model.fixed == {"mu": truth()["mu"]}
    assert back.estimates["mu"].fixed
    _, params, _ = _resolve(back.artefact.chosen, "ar1", None, None)  # the stored fit
    assert "mu" not in [p.name for p in params] and "Kt" in [p.name for p in params]
    page = idtool.write_report(out).read_text()
    row = page[page.index("<td>mu</td>") :].split("</tr>")[0]
    assert "fixed by the user" in row and "0.3" in row


def _table(path, rows: list[list[str]]):
    header = ["parameterId", "estimate", "nominalValue", "lowerBound", "upperBound"]
    header += ["parameterScale", "objectivePriorType", "objectivePriorParameters"]
    path.write_text("\n".join("\t".join(r) for r in [header, *rows]) + "\n")
    return path


def test_a_table_sets_bounds_scale_start_and_prior(dataset, tmp_path):
    kt = truth()["Kt"]
    table = _table(
        tmp_path / "params.tsv",
        [
            ["mu", "0", "0.3", "", "", "", "", ""],
            ["Kt", "1", f"{2 * kt:g}", f"{kt / 10:g}", f"{kt * 10:g}", "lin", "", ""],
            ["coupling_gain", "1", "", "", "", "", "logNormal", f"{math.log(0.03)};0.5"],
        ],
    )
    fit = idtool.fit(dataset, parameters=table, **FAST)
    spec = next(p for p in fit.model.shared_params if p.name == "Kt")
    assert (spec.kind, spec.lo, spec.hi, spec.start_box) == ("tanh", kt / 10, kt * 10, None)
    lo, hi = fit.estimates["Kt"].ci95
    assert kt / 10 <= lo <= kt <= hi <= kt * 10  # found from the given start, inside
    _, _, priors = _resolve(fit.result, "ar1", None, None)
    # the table's prior (PEtab's logNormal: mean and sd of the log), the default one
    # following the new bounds (uniform on a lin scale), and no prior for the fixed mu
    gain = priors["coupling_gain"]
    assert (gain.dist, gain.a, gain.b) == ("lognormal", pytest.approx(0.03, rel=1e-12), 0.5)
    assert priors["Kt"] == idtool.Prior("uniform", kt / 10, kt * 10)
    assert "mu" not in priors


def test_every_problem_of_a_table_is_located(tmp_path):
    path = tmp_path / "bad.csv"
    path.write_text(
        "parameterId,estimate,nominalValue,lowerBound,upperBound,unit,colour\n"
        "mu,maybe,0.3,,,1,red\n"
        "Kt,0,,,,N/mm,blue\n"
        "coupling_gain,1,abc,,,1,green\n"
    )
    with pytest.raises(idtool.IdtoolError) as err:
        idtool.read_parameter_table(path)
    text = str(err.value)
    assert "row 0, column 'colour': unknown column" in text
    assert "row 1, column 'estimate': 'maybe': give 1 (estimate) or 0 (fix)" in text
    assert "row 2, column 'unit': Kt is in N/m" in text
    assert "row 3, column 'nominalValue': 'abc' is not a number" in text
    laplace = _table(tmp_path / "laplace.tsv", [["mu", "1", "", "", "", "", "laplace", "0;1"]])
    with pytest.raises(idtool.IdtoolError, match="row 1, column 'objectivePriorType'"):
        idtool.read_parameter_table(laplace)
    no_value = _table(tmp_path / "novalue.tsv", [["mu", "0", "", "", "", "", "", ""]])
    with pytest.raises(idtool.IdtoolError, match="row 1: mu: a fixed parameter needs its value"):
        idtool.read_parameter_table(no_value)


def test_settings_that_fit_no_model_are_refused_before_fitting(dataset, tmp_path, capsys):
    with pytest.raises(idtool.IdtoolError, match=r"no shared parameter .Mu.*they have Kt, mu"):
        idtool.fit(dataset, fix={"Mu": 0.3}, **FAST)
    with pytest.raises(idtool.IdtoolError, match=r"fixed value 5 lies outside \[0.001, 3\]"):
        idtool.fit(dataset, fix={"mu": 5.0}, **FAST)
    table = _table(tmp_path / "t.tsv", [["Kt", "1", "", "-1", "1e9", "log", "", ""]])
    with pytest.raises(idtool.IdtoolError, match=r"t.tsv, row 1: Kt: a log scale needs a positive"):
        idtool.fit(dataset, parameters=table, **FAST)
    # the command line: exit 2, the message, no traceback, nothing written
    data = idtool.write_dataset(dataset, tmp_path / "data")
    out = tmp_path / "fit"
    assert main(["fit", str(data), "--out", str(out), "--fix", "mu=abc"]) == 2
    assert main(["fit", str(data), "--out", str(out), "--parameters", str(table)]) == 2
    err = capsys.readouterr().err
    assert "--fix mu=abc: give NAME=VALUE" in err and "Traceback" not in err
    assert "a log scale needs a positive lowerBound" in err
    assert not out.exists()


def test_the_parameters_command_writes_a_table_that_reads_back(tmp_path, capsys):
    path = tmp_path / "p.tsv"
    assert main(["parameters", "--coupling", "exponential", "-o", str(path)]) == 0
    settings = idtool.read_parameter_table(path)
    names = [s.name for s in settings]
    assert names == [
        "Kt",
        "mu",
        "coupling_gain",
        "saturation_load_n",
        "slope_n_s",
        "startup_slope_n_s",
    ]
    # every row as written keeps idtool's own range and transform
    every = shared_params_of(
        idtool.FRICTION_LAWS.get("dahl"),
        idtool.COUPLINGS.get("exponential"),
        idtool.ACTUATORS.get("slope"),
    )
    assert apply_settings(every, settings) == every
    assert main(["parameters", "-o", str(path)]) == 2  # exists: --force
    assert "exists" in capsys.readouterr().err
