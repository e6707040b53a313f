"""``posterior.nc`` as ArviZ reads it (issue 13, item 5): the model-check groups are
there and right, and ``az.loo``, ``az.compare`` and ``az.plot_ppc`` run on them.

The pointwise log-likelihoods are checked against what they claim to be, computed
another way: for the levels model, each trace's leave-one-out density from the
partitioned covariance (not the precision route of the code); for a noise-only model,
the per-trace terms plus the log prior must give the sampler's own log-posterior."""

import dataclasses
import json
import shutil
import warnings
from pathlib import Path

import arviz as az
import jax.numpy as jnp
import numpy as np
import pytest
from sample_helpers import small_params
from scipy.stats import multivariate_normal

import idtool
from idtool._cli._main import main
from idtool._posterior._groups import MAX_DRAWS, thinned_steps
from idtool._posterior._levels import _mean_and_cholesky, build_levels_target, levels_params
from idtool._posterior._prior import default_prior


def _sample(out: Path) -> Path:
    argv = ["sample", str(out), "--walkers", "20", "--steps", "160", "--no-progress", "-q"]
    assert main(argv) in (0, 3)  # 3: too short to converge; the groups are written anyway
    return out


@pytest.fixture(scope="module")
def levels(tmp_path_factory):
    """The small design (two pulls per operating point) of seed 5, the levels model."""
    root = tmp_path_factory.mktemp("levels")
    dataset, _ = idtool.simulate_bench(small_params(), seed=5)
    data = idtool.write_dataset(dataset, root / "data")
    out = root / "fit"
    # one actuator and offset model, not the BIC choice among four: the groups do not
    # depend on it, and CI time does
    fixed = ["--actuator", "slope", "--offset", "constant"]
    assert main(["fit", str(data), "--out", str(out), "-q", *fixed]) == 0
    return _sample(out)


@pytest.fixture(scope="module")
def noise_only(small_fit_folder, tmp_path_factory):
    """The bank's noise-only fit of the small design (tests/conftest.py), copied."""
    out = tmp_path_factory.mktemp("noise") / "fit"
    shutil.copytree(small_fit_folder, out)
    return _sample(out)


def test_thinning_keeps_the_last_step_and_at_most_max_draws():
    steps = thinned_steps(1889, 32)
    assert steps[-1] == 1888 and steps.size * 32 <= MAX_DRAWS
    assert np.all(np.diff(steps) == 16)  # ceil(1889 * 32 / 4000) = 16
    assert np.array_equal(thinned_steps(100, 8), np.arange(100))  # 800 draws: all


# Third-party deprecations inside arviz 0.23, not ours: compare sorts a DataFrame in
# place (pandas 3.1), plot_ppc passes a dict to matplotlib's normalize_kwargs (3.11)
@pytest.mark.filterwarnings("ignore:The inplace keyword")
@pytest.mark.filterwarnings("ignore:Passing a dict or None as alias_mapping")
def test_the_levels_posterior_has_every_group_arviz_needs(levels):
    idata = az.from_netcdf(str(levels / "posterior.nc"))
    for group in ("log_likelihood", "observed_data", "constant_data", "posterior_predictive"):
        assert group in idata.groups(), group
    post = idata.posterior
    assert post["Kt"].attrs["units"] == "N/m" and post["Kt"].attrs["description"]
    ll = idata.log_likelihood["per_trace"]
    assert ll.dims == ("chain", "draw", "trace") and ll.sizes["trace"] == 8
    # the same draws as the posterior: ArviZ's relative ESS divides the posterior's ESS
    # by the log-likelihood's draw count
    assert np.array_equal(ll["draw"].values, post["draw"].values)
    meta = json.loads(post.attrs["idtool"])
    assert meta["thinning"]["stored_steps"] == post.sizes["draw"]
    obs = idata.observed_data["log_level"]
    measured = sum(lv.endswith(" FR") for lv in obs["level"].values.tolist())
    assert obs.sizes["level"] == 8 + measured and measured >= 4  # log OFF of each, FR
    assert str(obs["level"].values[0]).endswith(" OFF")
    assert idata.posterior_predictive["log_level"].sizes["level"] == obs.sizes["level"]
    loads = idata.constant_data["normal_load_n"].values
    assert sorted(set(loads.tolist())) == [270.0, 670.0]

    # a short chain (160 steps): PSIS may say a left-out trace moves the posterior
    with warnings.catch_warnings(record=True):
        warnings.simplefilter("always")
        loo = az.loo(idata, pointwise=True)
        compared = az.compare({"a": idata, "b": idata})
    assert loo.n_data_points == 8 and np.isfinite(loo.elpd_loo)
    assert loo.warning == bool(np.any(loo.pareto_k.values > 0.7))
    assert list(compared["elpd_diff"]) == [0.0, 0.0]
    import matplotlib

    matplotlib.use("Agg")
    axes = az.plot_ppc(idata, num_pp_samples=20, random_seed=0)
    assert np.size(axes) >= 1


def test_levels_pointwise_terms_are_leave_one_trace_out_densities(levels):
    """log p(y_T | y_-T, theta) from the partitioned covariance at three stored draws:
    mean g_T + C_T,-T C_-T,-T^-1 (y_-T - g_-T), covariance C_TT - C_T,-T C_-T,-T^-1
    C_-T,T."""
    idata = az.from_netcdf(str(levels / "posterior.nc"))
    fit = idtool.load_fit(levels)
    free = fit.levels[0]
    params = levels_params(fit.model, free)
    # the dense reference: V without its blocks (as a fit saved before them)
    free = dataclasses.replace(free, cov_y=free.covariance(), cov_parts=None)
    target = build_levels_target(fit.model, free, {p.name: default_prior(p) for p in params})
    m = fit.model.data.n_traces
    rows = np.asarray(target.rows)
    owner = np.concatenate([np.arange(m), rows[m:] - m])  # the trace of each row of y
    y = np.asarray(target.y)
    for chain, draw in ((0, 0), (3, -1), (7, 40)):
        v = {
            p.name: jnp.asarray([float(idata.posterior[p.name].values[chain, draw])])
            for p in params
        }
        g, chol = (np.asarray(a)[0] for a in _mean_and_cholesky(v, target))
        cov = chol @ chol.T
        stored = idata.log_likelihood["per_trace"].values[chain, draw]
        for t in range(m):
            own, rest = owner == t, owner != t
            gain = cov[np.ix_(own, rest)] @ np.linalg.inv(cov[np.ix_(rest, rest)])
            mean = g[own] + gain @ (y[rest] - g[rest])
            c = cov[np.ix_(own, own)] - gain @ cov[np.ix_(rest, own)]
            want = multivariate_normal(mean, c).logpdf(y[own])
            assert stored[t] == pytest.approx(want, abs=1e-8), (chain, draw, t)


def test_noise_only_terms_add_up_to_the_samplers_log_posterior(noise_only):
    """The traces are independent given the shared parameters: the per-trace marginal
    log-likelihoods plus the log prior (and the transforms' Jacobians) are the
    log-posterior emcee stored, draw by draw."""
    idata = az.from_netcdf(str(noise_only / "posterior.nc"))
    meta = json.loads(idata.posterior.attrs["idtool"])
    assert meta["noise"] != "levels"
    fit = idtool.load_fit(noise_only)
    from idtool._posterior._likelihood import sampled_params
    from idtool._posterior._prior import parse_priors

    params = sampled_params(fit.model)
    priors = parse_priors(meta["priors"], params, "posterior.nc")
    lp = idata.sample_stats["lp"].values
    ll = idata.log_likelihood["per_trace"].values.sum(axis=-1)
    prior = np.zeros_like(lp)
    for p in params:
        x = idata.posterior[p.name].values
        prior += np.asarray(priors[p.name].logpdf(jnp.asarray(x)))
        prior += np.asarray(p.log_jacobian(jnp.asarray(np.vectorize(p.internal)(x))))
    np.testing.assert_allclose(ll + prior, lp, rtol=0, atol=1e-6 * np.abs(lp).max())
    pp = idata.posterior_predictive["force_n"]
    assert pp.dims == ("chain", "draw", "block") and pp.sizes["chain"] == 20
    assert pp.sizes["block"] == idata.observed_data["force_n"].sizes["block"]
    assert set(pp["draw"].values) <= set(idata.posterior["draw"].values)
    # A whole trace of block means informs the shared parameters strongly: leaving one
    # out moves the posterior, and PSIS may say so (Pareto k > 0.7) on a short chain
    with warnings.catch_warnings(record=True):
        warnings.simplefilter("always")
        loo = az.loo(idata, pointwise=True)
    assert loo.n_data_points == 8 and np.isfinite(loo.elpd_loo)
    assert loo.warning == bool(np.any(loo.pareto_k.values > 0.7))


def test_a_resumed_chain_rewrites_the_groups(levels, tmp_path):
    folder = tmp_path / "fit"
    shutil.copytree(levels, folder)
    before = az.from_netcdf(str(folder / "posterior.nc"))
    argv = ["sample", str(folder), "--resume", "--steps", "220", "--no-progress", "-q"]
    assert main(argv) in (0, 3)
    after = az.from_netcdf(str(folder / "posterior.nc"))
    assert after.log_likelihood.sizes["draw"] == after.posterior.sizes["draw"]
    # The groups are the resumed chain's, which is longer. (Not necessarily more kept
    # draws: a chain that has not converged re-estimates its burn-in from the longer
    # chain, and a longer autocorrelation time can keep fewer: 145 -> 101 in one run.)
    steps = [
        json.loads(i.posterior.attrs["idtool"])["diagnostics"]["steps"] for i in (before, after)
    ]
    assert steps[1] > steps[0]


def test_an_in_memory_posterior_gives_the_same_groups(levels):
    """``Posterior.to_arviz()`` (a notebook's route) carries the model-check groups too."""
    post = idtool.load_fit(levels).sample(walkers=16, steps=60, seed=1)
    idata = post.to_arviz()
    assert {"log_likelihood", "observed_data", "posterior_predictive"} <= set(idata.groups())
    ll = idata.log_likelihood["per_trace"]
    assert ll.sizes["trace"] == 8 and np.all(np.isfinite(ll.values))
    assert np.array_equal(ll["draw"].values, idata.posterior["draw"].values)


def test_chain_h5_says_how_its_internal_scale_maps_to_physical_units(levels):
    """Apply the formulas chain.h5 records, as a reader without idtool would, to the
    kept steps posterior.nc stores: the physical draws come back."""
    import h5py

    with h5py.File(levels / "chain.h5", "r") as f:
        settings = json.loads(f.attrs["idtool_settings"])
        chain = f["mcmc"]["chain"][:]
    idata = az.from_netcdf(str(levels / "posterior.nc"))
    burn = json.loads(idata.posterior.attrs["idtool"])["diagnostics"]["burn_in"]
    steps = idata.posterior["draw"].values
    formulas = {
        "exp(ln(lo) + (ln(hi) - ln(lo)) / (1 + exp(-z)))": lambda z, t: np.exp(
            np.log(t["lo"]) + (np.log(t["hi"]) - np.log(t["lo"])) / (1 + np.exp(-z))
        ),
        "lo + (hi - lo) (1 + tanh(z)) / 2": lambda z, t: (
            t["lo"] + (t["hi"] - t["lo"]) * (1 + np.tanh(z)) / 2
        ),
        "centre + scale z": lambda z, t: t["centre"] + t["scale"] * z,
    }
    assert [t["name"] for t in settings["transforms"]] == settings["names"]
    # the walkers' coordinates to the internal scale first: the discrepancy's funnel
    # opened (its record's formula), where the fit has one
    chain = chain[burn:][steps]
    funnel = settings.get("funnel")
    if funnel is not None:
        t = settings["transforms"][funnel["sd_index"]]
        f = np.sqrt(
            1.0 + (formulas[t["value"]](chain[..., funnel["sd_index"]], t) / funnel["delta0"]) ** 2
        )
        for j, c in zip(funnel["scaled"], funnel["centre"], strict=True):
            chain[..., j] = c + f * (chain[..., j] - c)
    # then each boxed parameter's place in its range back to the internal scale (the
    # box's record, applied after the funnel's or the ridge's map, as it says)
    box = settings.get("box")
    if box is not None:
        assert "after" in box["formula"]
        for j, k in enumerate(box["slopes"]):
            if k > 0.0:
                chain[..., j] = np.log(chain[..., j] / (1.0 - chain[..., j])) / k
    for i, t in enumerate(settings["transforms"]):
        z = chain[:, :, i].T  # (walkers, steps) as posterior.nc
        physical = formulas[t["value"]](z, t)
        np.testing.assert_allclose(physical, idata.posterior[t["name"]].values, rtol=1e-12)
        assert t["unit"] == idata.posterior[t["name"]].attrs["units"]
