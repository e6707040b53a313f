"""Predictions (issue 5) and the ``idtool sample`` / ``idtool predict`` commands."""

import dataclasses
import json
import shutil

import jax.numpy as jnp
import numpy as np
import pytest

import idtool
from idtool._cli._main import main
from idtool._fit._discrepancy import Conditioning, length_scales, operating_coordinates
from idtool._posterior._diagnostics import import_arviz
from idtool._predict._amplitude import amplitude_for_reduction
from idtool._predict._predict import _fr_draws, predict_friction_ratio


@pytest.fixture(scope="module")
def fit_folder(small_fit_folder):
    """``fits/small`` as ``idtool fit`` writes it, from the cached fit of seed 1 (the
    bank's, tests/conftest.py: read-only)."""
    return small_fit_folder


def predict_json(capsys, *args) -> dict:
    capsys.readouterr()
    assert main(["predict", *map(str, args), "--json"]) == 0
    return json.loads(capsys.readouterr().out)


def test_predict_without_a_posterior_uses_the_fit_covariance(fit_folder, capsys):
    doc = predict_json(capsys, fit_folder, "--load", 450, "--amplitude", 0.5)
    assert doc["source"] == "fit covariance" and "fit's covariance" in doc["note"]
    (p,) = doc["predictions"]
    assert set(p) >= {"normal_load_n", "amplitude_fraction", "pull_speed_m_s", "friction_ratio"}
    assert (p["normal_load_n"], p["amplitude_fraction"], p["pull_speed_m_s"]) == (450, 0.5, 0.025)
    lo, hi = p["friction_ratio"]["ci95"]
    assert 0 < lo < p["friction_ratio"]["median"] < hi < 1
    assert doc["warnings"] == []  # 450 N lies between the fitted loads
    assert main(["predict", str(fit_folder), "--load", "450", "--amplitude", "0.5"]) == 0
    assert "fit's covariance" in capsys.readouterr().out


@pytest.fixture(scope="module")
def sampled(fit_folder, tmp_path_factory):
    """``idtool sample`` on a copy of the folder (so the tests without a posterior see
    none, whatever the order they run in): short, so not converged."""
    folder = tmp_path_factory.mktemp("sampled") / "small"
    shutil.copytree(fit_folder, folder)
    argv = ["sample", str(folder), "--walkers", "20", "--steps", "60", "--no-progress"]
    assert main(argv) == 3  # outputs written, chain not converged (documented status)
    return folder


def test_sample_command_writes_the_posterior_next_to_the_fit(sampled, capsys):
    for name in ("chain.h5", "posterior.nc", "sample.json", "report_sample.txt"):
        assert (sampled / name).is_file(), name
    assert (sampled / "ppc.png").read_bytes()[:4] == b"\x89PNG"
    assert not list(sampled.glob("*.partial"))
    doc = json.loads((sampled / "sample.json").read_text())
    diag = doc["diagnostics"]
    assert not diag["converged"] and diag["steps_needed"] > 0
    assert set(diag["parameters"]["Kt"]) == {"tau", "tau_change", "ess", "ess_bulk", "rhat"}
    assert diag["stopped_by"] == "steps" and diag["rule"]
    assert 0 < diag["acceptance_fraction"]["mean"] < 1
    # this two-load fit's own levels cannot inform every physical parameter, so it keeps
    # the noise-only model, and the sampler the traces' own likelihood
    assert doc["noise"] == "ar1" and doc["priors"]["phi"]["dist"] == "uniform"
    assert 0.8 < doc["posterior_predictive"]["inside_95_band_fraction"] <= 1
    assert "NOT converged" in (sampled / "report_sample.txt").read_text()

    idata = import_arviz().from_netcdf(str(sampled / "posterior.nc"))
    post = idata.posterior
    assert {"Kt", "mu", "coupling_gain", "power_load_n", "sigma_n", "phi"} <= set(post.data_vars)
    assert post.sizes["chain"] == 20
    assert post.sizes["draw"] + idata.warmup_posterior.sizes["draw"] == 60
    assert post["Kt"].attrs["units"] == "N/m"
    assert json.loads(post.attrs["idtool"])["noise"] == "ar1"


def test_sample_command_refuses_to_restart_and_resumes(sampled, capsys):
    before = (sampled / "chain.h5").read_bytes()
    assert main(["sample", str(sampled), "--no-progress"]) == 2
    assert "--resume" in capsys.readouterr().err
    assert (sampled / "chain.h5").read_bytes() == before
    args = ["sample", str(sampled), "--resume", "--steps", "80", "--no-progress"]
    assert main([*args, "--json"]) == 3
    out, err = capsys.readouterr()
    assert json.loads(out)["diagnostics"]["converged"] is False  # sample.json, as written
    assert "did NOT converge" in err and "--resume" in err
    doc = json.loads((sampled / "sample.json").read_text())
    assert doc["diagnostics"]["steps"] == 80 and doc["timing_s"]["steps_this_run"] == 20
    assert main([*args[:-3], "--noise", "gaussian", "--steps", "90", "--no-progress"]) == 2
    assert "--noise ar1" in capsys.readouterr().err


def test_predict_from_the_posterior_on_a_grid(sampled, capsys):
    doc = predict_json(capsys, sampled, "--load", "270,670", "--amplitude", "0.5,0.7")
    assert doc["source"] == "posterior" and "NOT converged" in doc["note"]
    grid = [(p["normal_load_n"], p["amplitude_fraction"]) for p in doc["predictions"]]
    assert grid == [(270, 0.5), (270, 0.7), (670, 0.5), (670, 0.7)]
    for p in doc["predictions"]:
        fr, red = p["friction_ratio"], p["reduction_percent"]
        assert fr["ci95"][0] <= fr["median"] <= fr["ci95"][1]
        assert red["median"] == pytest.approx(100 * (1 - fr["median"]))
    # more load, less reduction (paper, Section 3.6)
    fr = {g: p["friction_ratio"]["median"] for g, p in zip(grid, doc["predictions"], strict=True)}
    assert fr[(270, 0.5)] < fr[(670, 0.5)]
    doc = predict_json(capsys, sampled, "--load", 900, "--amplitude", 0.5)
    assert "outside the fitted range" in doc["warnings"][0]


def test_amplitude_for_a_target_reduction_and_out_of_reach(sampled, capsys):
    doc = predict_json(capsys, sampled, "--load", 450, "--target-reduction", 50)
    (inv,) = doc["inverse"]
    assert inv["reachable"] and inv["probability_reachable"] == 1.0
    lo, hi = inv["amplitude_fraction"]["ci95"]
    alpha = inv["amplitude_fraction"]["median"]
    assert 0 < lo <= alpha <= hi <= 1
    # forward check: at that amplitude the median reduction is the target
    draws = idtool.load_fit(sampled).draws(500)
    (p,) = predict_friction_ratio(draws, [450.0], [alpha], [0.025])
    assert p.median == pytest.approx(0.5, abs=0.01)

    doc = predict_json(capsys, sampled, "--load", 450, "--target-reduction", 99)
    (inv,) = doc["inverse"]
    assert not inv["reachable"] and inv["amplitude_fraction"]["median"] is None
    assert "out of reach" in inv["statement"] and inv["max_reduction_percent"]["median"] < 99
    (api,) = amplitude_for_reduction(draws, 99.0, [450.0], [0.025])
    assert not api.reachable and np.isinf(api.amplitude[0])


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--load", "450"], "--amplitude, --target-reduction"),
        (["--load", "450", "--amplitude", "1.5"], "(0, 1]"),
        (["--load", "-1", "--amplitude", "0.5"], "--load -1"),
        (["--load", "450", "--target-reduction", "120"], "(0, 100)"),
    ],
)
def test_predict_bad_input_exits_2(fit_folder, capsys, args, message):
    assert main(["predict", str(fit_folder), *args]) == 2
    err = capsys.readouterr().err
    assert message in err and "Traceback" not in err


def test_sample_and_predict_on_a_folder_without_a_fit(tmp_path, capsys):
    for cmd in (
        ["sample", str(tmp_path)],
        ["predict", str(tmp_path), "--load", "1", "--amplitude", "1"],
    ):
        assert main(cmd) == 2
        assert "fit.json" in capsys.readouterr().err


def test_the_discrepancy_is_conditioned_on_every_measured_row(fit_folder):
    """``Draws.kriging`` evaluates the model once per distinct operating point (8 traces
    at 4 points here): its weights ``P^T S^-1 (y - g)`` equal those from the model
    evaluated at the rows, each point's value read from a row measured there."""
    fit = idtool.load_fit(fit_folder)
    d = fit.model.data
    op = np.asarray(d.op_index)
    x = np.asarray(operating_coordinates(d.op_load_n[op], d.op_alpha[op], d.op_speed_m_s[op]))
    assert x.shape[0] == 8 and np.unique(x, axis=0).shape[0] == 4
    draws = fit.draws(max_draws=50)
    v = {k: jnp.asarray(a) for k, a in draws.values.items()}
    rows = (d.op_load_n[op], d.op_alpha[op], d.op_speed_m_s[op])
    g = np.log(np.asarray(_fr_draws(draws.model, v, *(jnp.asarray(r) for r in rows))))
    # the measured log FR: the model's at the first draw, plus 1% of noise (seeded)
    y = g[0] + 0.01 * np.random.default_rng(0).standard_normal(8)
    sds = {"discrepancy_fr": np.full(draws.n, 0.03), "scatter_fr": np.full(draws.n, 0.01)}
    c = Conditioning(x, y, 1e-4 * np.eye(8), length_scales(d))
    draws = dataclasses.replace(draws, sds=sds, conditioning=c)
    # the model at each distinct point, taken from a row measured there (rows of one
    # point share their inputs): kriging's own evaluation must be the same, in the
    # order of Conditioning.points
    points, where = np.unique(x, axis=0, return_inverse=True)
    first = [int(np.flatnonzero(np.ravel(where) == k)[0]) for k in range(points.shape[0])]
    np.testing.assert_array_equal(c.points, points)
    weights, s_inv = c.weights(g[:, first], sds["discrepancy_fr"], sds["scatter_fr"])
    np.testing.assert_allclose(draws.kriging[2], weights, rtol=1e-9, atol=0)
    np.testing.assert_array_equal(draws.kriging[3], s_inv)
