"""The levels model (idtool/_fit/_variability.py): pull-to-pull scatter, model
discrepancy, their REML estimates, the lack-of-fit test, and the two prediction bands."""

from __future__ import annotations

import dataclasses
import json
import math
import warnings

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import idtool
from idtool._diagnostic import with_code
from idtool._fit import _reml as reml
from idtool._fit._discrepancy import Conditioning, correlation, discrepancy_moments
from idtool._fit._free_levels import (
    INFORMED_ON,
    UNINFORMED_NUISANCE,
    _free_step,
    _gauss_newton,
    _linearise,
    _linearise_at,
)
from idtool._fit._level_design import discrepancy_conditioning
from idtool._fit._program import u_normal_equations
from idtool._posterior._groups import _levels_terms, trace_rows
from idtool._posterior._levels import (
    SD_PRIOR,
    _mean_and_cholesky,
    _quad_and_logdet_blocks,
    _quadratic,
    build_levels_target,
    levels_params,
    replicate_in_blocks,
)
from idtool._predict._predict import Draws, with_variability
from idtool._simulate._departures import departure_params
from idtool._simulate._simulate import true_friction_ratio


@pytest.fixture(scope="module")
def example_fits(example_default_run):
    """``idtool.fit`` of the example, with and without the levels model (the first
    from the bank's run, tests/conftest.py, in a Fit of this module's own)."""
    ds = idtool.load_dataset(idtool.example_dataset_path())
    return idtool.Fit.from_run(ds, example_default_run), idtool.fit(ds, variability=False)


def test_neg_log_lik_is_the_gaussian_density_with_theta_profiled():
    """Independent check of the levels likelihood: the dense multivariate normal
    log-density of the GLS residual (numpy), and REML's extra log det(G^T C^-1 G)."""
    rng = np.random.default_rng(0)
    n, k = 12, 3
    a = rng.normal(size=(n, n))
    v = 0.01 * (a @ a.T / n + np.eye(n))
    kinds = np.zeros((n, 2))
    kinds[:5, 0] = kinds[5:, 1] = 1.0
    op = np.array([0, 0, 1, 1, 2, 2, 3])
    zz = np.zeros((n, n))
    zz[5:, 5:] = op[:, None] == op[None, :]
    g, r = rng.normal(size=(n, k)), rng.normal(size=n)
    tau2 = np.array([0.02, 0.03, 0.05]) ** 2
    c = v + np.diag(kinds[:, 0] * tau2[0] + kinds[:, 1] * tau2[1]) + tau2[2] * zz
    ci = np.linalg.inv(c)
    beta = np.linalg.solve(g.T @ ci @ g, g.T @ ci @ r)
    e = r - g @ beta
    ml = 0.5 * (e @ ci @ e + np.linalg.slogdet(c)[1])
    args = (jnp.asarray(r), jnp.asarray(g), jnp.asarray(v), jnp.asarray(kinds), jnp.asarray(zz))
    got, step = reml.neg_log_lik(jnp.asarray(tau2), *args, False)
    np.testing.assert_allclose(float(got), ml, rtol=1e-10)
    np.testing.assert_allclose(np.asarray(step), beta, rtol=1e-8)
    restricted, _ = reml.neg_log_lik(jnp.asarray(tau2), *args, True)
    np.testing.assert_allclose(float(restricted) - ml, 0.5 * np.linalg.slogdet(g.T @ ci @ g)[1])


def test_clean_example_nests_the_noise_only_fit(example_fits):
    """On data from the fit's own simulator the sds come out at ~0 and the levels model
    reproduces the noise-only fit: estimates within 0.1 standard error, errors within 2%
    (the two stages are a Laplace approximation of the same likelihood)."""
    on, off = example_fits
    var = on.result.variability
    assert var is not None and off.result.variability is None
    for name in on.model.physical_names:
        a, b = on.estimates[name], off.estimates[name]
        assert abs(a.estimate - b.estimate) < 0.1 * b.std_error, name
        assert abs(a.std_error / b.std_error - 1.0) < 0.02, name
    for name, (est, lo, hi) in var.sds.items():
        assert est < 0.003 and lo <= est <= hi, name
    # lack of fit calibrated: chi2 near its degrees of freedom, no warning
    assert var.p_value > 0.01 and abs(var.chi2 - var.dof) < 4 * math.sqrt(2 * var.dof)
    assert not any("misses the traces" in w for w in on.warnings)


def test_free_levels_match_the_model_where_it_is_right(example_fits):
    """Each measured trace's own FR agrees with the fitted curve within its errors."""
    on, _ = example_fits
    free = on.result.variability.free
    k = free.measured
    z = (free.friction_ratio[k] - on.result.friction_ratio[k]) / free.friction_ratio_se[k]
    assert k.sum() >= 10
    assert np.max(np.abs(z)) < 4.0 and abs(np.mean(z)) < 1.0


@pytest.mark.slow
def test_free_levels_are_the_traces_own_where_the_model_is_far_from_them():
    """On a bench whose coupling law the fit does not ship (departure "coupling", seed
    3: the physical model's ON level at 670 N, 50% sits 22 N below the data's) each
    measured trace's own FR is its truth's within 4 standard errors, and so the mean FR
    bands at the six measured operating points hold their truths. One Gauss-Newton step
    from the physical levels (before iterating, ``ITERATE_ABOVE``) left those traces at
    0.42 against 0.461, 14 standard errors off, and every one of the six bands missed."""
    params = departure_params("coupling", 3)
    dataset, truth = idtool.simulate_bench(params, seed=3)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the fit's misfit warnings: expected here
        fit = idtool.fit(dataset, seed=0)
    free = fit.result.variability.free
    true_fr = np.array([t.friction_ratio for t in truth.traces])
    k = free.measured
    assert k.sum() >= 10
    z = (free.friction_ratio[k] - true_fr[k]) / free.friction_ratio_se[k]
    assert np.max(np.abs(z)) < 4.0, z
    for p in fit.predict([270.0, 450.0, 670.0], [0.5, 0.7]):
        fr = true_friction_ratio(params, p.normal_load_n, p.amplitude_fraction)
        assert p.ci95[0] <= fr <= p.ci95[1], (p, fr)
    # the levels are the free optimum: one more step from them moves no level by more
    # than the iteration's stopping threshold (its steps shrink quadratically)
    res = fit.result
    model, z = res.model, np.asarray(res.z)
    state = res.noise_state
    first, u = _free_step(model, z, state)
    cc = _linearise(model, z, state)[3]  # the ON levels freed: as the first step chose
    sb = int(np.sum(model.level_group < 0))
    on_free = first.measured | (cc[:, sb + 1, sb + 1] > INFORMED_ON * cc[:, sb, sb])
    _, cc, cr = _linearise_at(model, u, z, state)
    h_b = _gauss_newton(np.zeros(0), cc, cr, sb, on_free)[1]
    m = model.data.n_traces
    moved = np.abs(h_b[:, :2]) / np.stack([u[:m], u[m : 2 * m]], axis=1)
    assert np.max(moved[:, 0]) < 1e-5 and np.max(moved[k, 1]) < 1e-5


@pytest.mark.slow
def test_the_levels_model_survives_an_on_level_pushed_beyond_the_slopes_reach():
    """On departure "all", seed 601 (a lag actuator and a coupling law the fit does not
    ship) a Gauss-Newton step after the first took a freed ON level where the force no
    longer reaches it: its trace's system was singular, the levels model was dropped
    ("levels_not_estimated") and the FR bands at the held-out points held 0 of 6. The
    line search refuses such a step: the levels model stands, and the bands hold."""
    params = departure_params("all", 601)
    dataset, _ = idtool.simulate_bench(params, seed=601)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the fit's misfit warnings: expected here
        fit = idtool.fit(dataset, seed=0)
    assert fit.result.variability is not None
    assert not with_code(fit.warnings, "levels_not_estimated")
    for p in fit.predict([360.0, 560.0], [0.5, 0.6, 0.7]):
        fr = true_friction_ratio(params, p.normal_load_n, p.amplitude_fraction)
        assert p.ci95[0] <= fr <= p.ci95[1], (p, fr)


def test_a_nuisance_the_trace_does_not_inform_is_held():
    """A trace whose horn did not lower the force shows no switch, and its horn lags no
    information: the free levels' step holds such a nuisance where it is (a step of 0,
    out of the covariance) and solves the rest as if it were not there; with its
    information the solve is the dense one. Solved whole, the near-singular block sent
    a lag by -10.8 s and the next step an ON level to -367 N (issue 29)."""
    rng = np.random.default_rng(3)
    m, sb, t, n = 3, 1, 4, 40  # traces; shared; own: OFF, ON, offset, lag
    jac = rng.normal(size=(m, n, sb + t))
    jac[1, :, sb + 3] = 1e-9  # trace 1's lag: information 4e-17, below the threshold
    r = rng.normal(size=(m, n))
    cc = np.einsum("mni,mnj->mij", jac, jac)
    cr = np.einsum("mni,mn->mi", jac, r)
    assert cc[1, sb + 3, sb + 3] < UNINFORMED_NUISANCE < cc[0, sb + 3, sb + 3]
    h_s, h_b, d_inv, _, _, held = _gauss_newton(np.zeros(0), cc, cr, sb, np.ones(m, bool))
    assert held.tolist() == [[False] * t, [False, False, False, True], [False] * t]
    assert h_b[1, 3] == 0.0 and d_inv[1, 3, 3] == 1.0
    assert np.all(d_inv[1, 3, :3] == 0.0)
    # the reference: the dense least squares in every input but the held one
    cols = [(None, 0)] + [(i, j) for i in range(m) for j in range(t) if (i, j) != (1, 3)]
    big = np.zeros((m * n, len(cols)))
    for c, (i, j) in enumerate(cols):
        for tr in range(m):
            if i is None:
                big[tr * n : (tr + 1) * n, c] = jac[tr, :, 0]
            elif i == tr:
                big[tr * n : (tr + 1) * n, c] = jac[tr, :, sb + j]
    step = np.linalg.lstsq(big, r.reshape(-1), rcond=None)[0]
    got = np.concatenate([h_s, np.delete(h_b.reshape(-1), 1 * t + 3)])
    np.testing.assert_allclose(got, step, rtol=1e-10)


# The laws study's truth 10 (issue 29: the paper's matrix with pull-to-pull scatter and
# ten planned pulls at amplitudes 0.1-0.2; a load-power truth)
NO_REDUCTION_TRUTH = {
    "law": "load-power",
    "values": {
        "Kt": 1650174170.131364,
        "mu": 0.3292099789146136,
        "coupling_gain": 0.029104224345166393,
        "load_exponent": 0.2420361473487911,
        "power_load_n": 120.13540338597853,
    },
    "sds": {"scatter_mu": 0.0065, "scatter_fr": 0.04506082696156961},
}
NO_REDUCTION_PLANNED = [(670.0, 0.2), (670.0, 0.1), (270.0, 0.2), *[(670.0, 0.1)] * 4]
NO_REDUCTION_PLANNED += [(270.0, 0.1), (670.0, 0.2), (270.0, 0.1)]


@pytest.mark.slow
def test_the_levels_model_survives_pulls_the_horn_did_not_reduce():
    """Five pulls at 670 N and 10%, where this truth's horn gives no reduction (FR 1):
    their traces show no switch, and the free levels' step took one ON level through
    zero; the levels model was dropped and the intervals were the noise-only ones (3 of
    the laws study's 20 benches, 14 of its 20 FR misses). Held, the uninformed lags stay
    put, the levels model stands and reads the scatter the traces have."""
    from idtool._study._truths import Truth, design_points, truth_params

    base = json.loads(idtool.example_params_path().read_text())
    truth = Truth.from_dict(NO_REDUCTION_TRUTH)
    doc = truth_params(truth, base, base["rig"], "dahl", "scatter")
    params = idtool.BenchParams.from_dict(doc)
    points = [
        (n, a, 0.025, on)
        for n in (270.0, 450.0, 670.0)
        for a in (0.5, 0.7)
        for on in (0.5, 1.0, 2.0, 2.5)
    ]
    points += [(n, a, 0.025, 2.0) for n, a in NO_REDUCTION_PLANNED]
    dataset, _ = idtool.simulate_bench(params, 109501320, design_points(points))
    assert true_friction_ratio(params, 670.0, 0.1) == pytest.approx(1.0, abs=1e-12)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the fit's misfit warnings: expected here
        fit = idtool.fit(dataset, seed=0, coupling="load-power")
    v = fit.result.variability
    assert v is not None and not with_code(fit.warnings, "levels_not_estimated")
    # the scatter read: 4.5% in FR and 0.65% in mu (truth), the free levels far from
    # the curve in the load cell's noise
    assert v.chi2 / v.dof > 20.0
    assert v.sds["scatter_mu"][1] <= 0.0065 <= v.sds["scatter_mu"][2]


def test_bands_carry_discrepancy_and_scatter():
    """with_variability: zero sds leave the curve alone; a scatter widens only the
    new-pull band; a discrepancy widens both; both are capped at FR = 1."""
    rng = np.random.default_rng(1)
    fr = 0.3 + 0.001 * rng.standard_normal((4000, 1))
    base = Draws(None, {}, "fit covariance", "")  # type: ignore[arg-type]
    x = np.array([[np.log(450.0), 0.5, np.log(0.025)]])  # no conditioning: any point
    mean, new = with_variability(fr, base, x)
    assert mean is fr and new is fr
    sds = {"discrepancy_fr": np.zeros(4000), "scatter_fr": np.full(4000, 0.05)}
    mean, new = with_variability(fr, dataclasses.replace(base, sds=sds), x)
    assert np.std(mean) == pytest.approx(0.001, rel=0.05)
    assert np.std(np.log(new)) == pytest.approx(0.05, rel=0.05)
    sds = {"discrepancy_fr": np.full(4000, 0.05), "scatter_fr": np.zeros(4000)}
    mean, _ = with_variability(fr, dataclasses.replace(base, sds=sds), x)
    assert np.std(np.log(mean)) == pytest.approx(0.05, rel=0.05)
    mean, new = with_variability(np.full((4000, 1), 0.99), dataclasses.replace(base, sds=sds), x)
    assert mean.max() <= 1.0 and new.max() <= 1.0


def test_predictions_report_both_bands(example_fits):
    on, _ = example_fits
    p = on.predict(450, [0.5, 0.7])
    row = p.to_dict()["rows"][0]
    assert set(row) >= {"friction_ratio", "new_trace"}
    lo, hi = row["new_trace"]["ci95"]
    mlo, mhi = row["friction_ratio"]["ci95"]
    assert lo <= row["new_trace"]["median"] <= hi
    assert hi - lo >= 0.95 * (mhi - mlo)
    assert "REML" in p.note


def test_saved_fit_keeps_the_levels_model(example_fits, tmp_path):
    on, _ = example_fits
    out = on.save(tmp_path / "fit", plots=False)
    back = idtool.load_fit(out)
    assert back.levels is not None
    free, sds = back.levels
    np.testing.assert_array_equal(free.y, on.result.variability.free.y)
    assert set(sds) == set(on.result.variability.sds)
    a = on.predict(450, 0.5).to_dict()["rows"][0]
    b = back.predict(450, 0.5).to_dict()["rows"][0]
    assert a["new_trace"]["median"] == pytest.approx(b["new_trace"]["median"])
    assert a["new_trace"]["ci95"] == pytest.approx(b["new_trace"]["ci95"])


def test_levels_posterior_samples_the_sds(example_fits):
    on, _ = example_fits
    post = on.sample(walkers=20, steps=150, seed=3)
    assert post.noise == "levels"
    assert {"scatter_mu", "scatter_fr", "discrepancy_fr"} <= set(post.names)
    again = on.sample(walkers=20, steps=150, seed=3)
    np.testing.assert_array_equal(post.chain, again.chain)
    draws = post.draws()
    assert np.all(draws["discrepancy_fr"] > 0)


def test_discrepancy_conditioning_is_gaussian_conditioning():
    """The kriging moments against conditioning the joint Gaussian of (d(x*), y) by
    brute force; at a measured point the band follows the data, far away it reverts to
    the unconditional sd. Two traces at each of the six points (with a dense noise
    covariance): the moments go through the distinct points (issue 28)."""
    rng = np.random.default_rng(3)
    scales = np.array([0.45, 0.1, 0.1])
    pts = np.array([[np.log(n), a, np.log(0.025)] for n in (270, 450, 670) for a in (0.5, 0.7)])
    x = np.concatenate([pts, pts[::-1]])  # repeats, not in order
    a_ = rng.normal(size=(x.shape[0], x.shape[0]))
    v = np.diag(rng.uniform(1e-6, 4e-6, x.shape[0])) + 1e-7 * a_ @ a_.T / x.shape[0]
    y = rng.normal(0, 0.05, x.shape[0])
    sd_d, sd_c = 0.08, 0.01
    cond = Conditioning(x, y, v, scales)
    np.testing.assert_array_equal(cond.points, np.unique(pts, axis=0))
    g_points = rng.normal(0, 0.01, (1, cond.points.shape[0]))
    weights, s_inv = cond.weights(g_points, np.array([sd_d]), np.array([sd_c]))
    assert weights.shape == (1, 6) and s_inv.shape == (1, 6, 6)
    where = [int(np.flatnonzero(np.all(cond.points == row, axis=1))[0]) for row in x]
    g = g_points[0, where]
    x_new = np.array(
        [[np.log(360.0), 0.6, np.log(0.025)], x[3], [np.log(3000.0), 0.6, np.log(0.025)]]
    )
    mean, var = discrepancy_moments(x_new, cond.points, scales, weights[0], s_inv[0], sd_d)
    # brute force: the joint covariance of (d(x_new), y), conditioned
    k_all = np.asarray(correlation(np.vstack([x_new, x]), np.vstack([x_new, x]), scales))
    joint = sd_d**2 * k_all
    joint[3:, 3:] += v + sd_c**2 * np.eye(x.shape[0])
    a, b = joint[:3, 3:], joint[3:, 3:]
    np.testing.assert_allclose(mean, a @ np.linalg.solve(b, y - g), rtol=1e-10)
    np.testing.assert_allclose(var, np.diag(joint[:3, :3] - a @ np.linalg.solve(b, a.T)), rtol=1e-8)
    # measured point: about the data's own spread (noise and scatter), not sd_d
    assert var[1] < (2 * sd_c) ** 2
    # 3000 N is 3.3 length scales outside the design: unconditional to 0.1%
    assert var[2] == pytest.approx(sd_d**2, rel=1e-3)


def test_free_levels_in_blocks_are_the_dense_solution(example_fits):
    """The free levels' step through the Schur complement of the trace blocks, and their
    covariance as blocks plus a low rank (issue 28), against the dense normal equations
    in ``u`` solved and inverted whole (the reference, kept here)."""
    res = example_fits[1].result
    model, z, phi = res.model, np.asarray(res.z), res.phi
    k, m = model.n_physical, model.data.n_traces
    # the first Gauss-Newton step's algebra (the iterated steps solve the same system
    # at the next linearisation)
    free, u = _free_step(model, z, phi, max_steps=0)
    w, lv, _, cc, cr = _linearise(model, z, phi)
    jtj, jtr = u_normal_equations(model, cc, cr)
    info = np.diag(jtj)
    on_free = free.measured | (info[m : 2 * m] > INFORMED_ON * info[:m])
    keep = np.flatnonzero(np.concatenate([np.ones(m, bool), on_free, np.ones(z.size - k, bool)]))
    sub = jtj[np.ix_(keep, keep)]
    step = np.linalg.solve(sub, jtr[keep])
    ref = np.concatenate([lv, z[k:]])
    ref[keep] -= step
    sigma2 = (float(w @ w) - float(jtr[keep] @ step)) / (w.size - keep.size)
    cov_u = np.zeros((ref.size, ref.size))
    cov_u[np.ix_(keep, keep)] = sigma2 * np.linalg.inv(sub)
    idx = np.flatnonzero(free.measured)
    dy = np.zeros((m + idx.size, ref.size))
    dy[np.arange(m), np.arange(m)] = 1.0 / ref[:m]
    dy[m + np.arange(idx.size), m + idx] = 1.0 / ref[m + idx]
    dy[m + np.arange(idx.size), idx] = -1.0 / ref[idx]
    cov_y = dy @ cov_u @ dy.T
    np.testing.assert_allclose(u, ref, rtol=1e-10, atol=1e-12)
    assert free.sigma_n == pytest.approx(math.sqrt(sigma2), rel=1e-10)
    assert free.cov_y is None  # in its blocks alone (issue 28), dense on demand
    got = free.covariance()
    np.testing.assert_allclose(got, cov_y, rtol=0, atol=1e-10 * np.abs(cov_y).max())
    np.testing.assert_allclose(free.variances(), np.diag(got), rtol=1e-14)
    idx = m + np.arange(free.measured.sum())
    np.testing.assert_allclose(free.fr_covariance(), got[np.ix_(idx, idx)], rtol=1e-14, atol=0)
    r = np.random.default_rng(1).normal(size=cov_y.shape[0])
    assert free.cov_parts is not None
    assert free.cov_parts.quad(r) == pytest.approx(r @ np.linalg.solve(cov_y, r), rel=1e-8)


def test_levels_posterior_in_blocks_is_the_dense_one(example_fits):
    """The sampler's levels likelihood with ``V + Sigma(sds)`` in blocks (issue 28)
    against the dense Cholesky factorisation (the reference: a target without the
    blocks, as a fit saved before them gives), at walkers around the fit."""
    on, _ = example_fits
    model, free = on.model, on.result.variability.free
    assert free.cov_parts is not None
    names = [p.name for p in levels_params(model, free)]
    priors = dict.fromkeys(names, SD_PRIOR)
    blocks = build_levels_target(model, free, priors)
    unblocked = dataclasses.replace(free, cov_y=free.covariance(), cov_parts=None)
    dense = build_levels_target(model, unblocked, priors)
    assert blocks.parts is not None and dense.parts is None
    rng = np.random.default_rng(5)
    k = model.n_physical
    z = np.asarray(on.result.z)[:k]
    v = {}
    for i, p in enumerate(blocks.params):
        internal = z[i] + 0.01 * rng.normal(size=6) if i < k else rng.uniform(0.0, 2.0, 6)
        v[p.name] = p.value(jnp.asarray(internal))
    quad, logdet = _quad_and_logdet_blocks(v, blocks)
    g, chol = _mean_and_cholesky(v, dense)
    want_quad = jax.vmap(_quadratic)(chol, dense.y[None] - g)
    want_logdet = 2.0 * jnp.sum(jnp.log(jnp.diagonal(chol, axis1=1, axis2=2)), axis=1)
    np.testing.assert_allclose(np.asarray(quad), np.asarray(want_quad), rtol=1e-9)
    np.testing.assert_allclose(np.asarray(logdet), np.asarray(want_logdet), rtol=1e-11)
    theta = rng.normal(size=(4, len(names))) * 0.01
    theta[:, :k] += z
    np.testing.assert_allclose(
        np.asarray(blocks.log_posterior_batch(jnp.asarray(theta))),
        np.asarray(dense.log_posterior_batch(jnp.asarray(theta))),
        rtol=1e-10,
    )


def test_levels_replicates_in_blocks_are_the_dense_gaussian(example_fits):
    """The posterior predictive check's replicated levels drawn on ``V + Sigma(sds)`` in
    blocks (a per-trace part and a low-rank part, issue 28) are the dense Gaussian
    ``g + chol(C) eps``: the same mean, and the covariance the linear map from ``eps``
    implies is ``C``; the discrepancies and each trace's leave-one-out terms (``C^-1``'s
    diagonal blocks) are the dense ones."""
    on, _ = example_fits
    model, free = on.model, on.result.variability.free
    names = [p.name for p in levels_params(model, free)]
    priors = dict.fromkeys(names, SD_PRIOR)
    blocks = build_levels_target(model, free, priors)
    unblocked = dataclasses.replace(free, cov_y=free.covariance(), cov_parts=None)
    dense = build_levels_target(model, unblocked, priors)
    rng = np.random.default_rng(6)
    k, walkers = model.n_physical, 3
    z = np.asarray(on.result.z)[:k]
    theta = np.column_stack(
        [
            z[i] + 0.01 * rng.normal(size=walkers) if i < k else rng.uniform(0, 2, walkers)
            for i in range(len(names))
        ]
    )
    v = {p.name: p.value(jnp.asarray(theta[:, i])) for i, p in enumerate(blocks.params)}
    g_ref, chol = (np.asarray(a) for a in _mean_and_cholesky(v, dense))
    c_ref = np.einsum("wij,wkj->wik", chol, chol)
    size = blocks.noise_size
    assert blocks.parts is not None and dense.noise_size == dense.y.size
    m, r = model.data.n_traces, blocks.parts[1].shape[2] + blocks.parts[2].shape[2]
    assert size == 2 * m + r  # two per trace, one per low-rank column

    @jax.jit
    def noise(e):  # y_rep - g for the same eps at every walker: linear in eps
        g, y_rep, *_ = replicate_in_blocks(v, blocks, jnp.broadcast_to(e, (walkers, size)))
        return y_rep - g

    basis = np.asarray(jax.vmap(noise)(jnp.eye(size)))  # (size, walkers, n)
    for w in range(walkers):
        implied = basis[:, w].T @ basis[:, w]
        scale = np.abs(c_ref[w]).max()
        np.testing.assert_allclose(implied, c_ref[w], rtol=0, atol=1e-10 * scale)
    eps = rng.standard_normal((walkers, size))
    g, y_rep, a, prec, d_obs, d_rep = (
        np.asarray(x) for x in replicate_in_blocks(v, blocks, jnp.asarray(eps))
    )
    np.testing.assert_allclose(g, g_ref, rtol=1e-12)
    y = np.asarray(dense.y)
    want_obs = [(y - g_ref[w]) @ np.linalg.solve(c_ref[w], y - g_ref[w]) for w in range(walkers)]
    rep = y_rep - g
    want_rep = [rep[w] @ np.linalg.solve(c_ref[w], rep[w]) for w in range(walkers)]
    np.testing.assert_allclose(d_obs, want_obs, rtol=1e-9)
    np.testing.assert_allclose(d_rep, want_rep, rtol=1e-9)
    idx, mask = (np.asarray(x) for x in trace_rows(dense))
    for w in range(walkers):
        inv = np.linalg.inv(c_ref[w])
        want_a = inv @ (y - g_ref[w])
        np.testing.assert_allclose(
            np.where(mask, a[w], 0.0), np.where(mask, want_a[idx], 0.0), rtol=1e-8, atol=1e-12
        )
        both = mask[:, :, None] & mask[:, None, :]
        want_p = inv[idx[:, :, None], idx[:, None, :]]
        np.testing.assert_allclose(
            np.where(both, prec[w], 0.0), np.where(both, want_p, 0.0), rtol=1e-9, atol=0
        )
    ll_blocks, _ = _levels_terms(jnp.asarray(theta), blocks, jnp.asarray(eps), idx, mask)
    eps_dense = jnp.asarray(rng.standard_normal((walkers, dense.noise_size)))
    ll_dense, _ = _levels_terms(jnp.asarray(theta), dense, eps_dense, idx, mask)
    np.testing.assert_allclose(np.asarray(ll_blocks), np.asarray(ll_dense), rtol=1e-9)


def test_discrepancy_conditioning_in_blocks_is_the_dense_one(example_fits):
    """The kriging weights with ``V`` in blocks (its diagonal and rank-``q`` part, inverted
    by Woodbury per draw; issue 28) against ``V`` dense (diagonalised once), at draws of
    both sds: the example's levels fit, and a random ``V`` of 12 rows with repeats."""
    on, _ = example_fits
    model, free = on.model, on.result.variability.free
    blocks = discrepancy_conditioning(model, free)
    dense = discrepancy_conditioning(
        model, dataclasses.replace(free, cov_y=free.covariance(), cov_parts=None)
    )
    assert blocks.v is None and blocks.v_low is not None and dense.v is not None
    rng = np.random.default_rng(8)
    x = np.concatenate([dense.x, dense.x[::-1]])
    n = x.shape[0]
    low = 0.01 * rng.normal(size=(n, 3))
    diag = rng.uniform(1e-6, 4e-6, n)
    y = rng.normal(0, 0.05, n)
    random_blocks = Conditioning(x, y, None, dense.scales, diag, low)
    random_dense = Conditioning(x, y, np.diag(diag) + low @ low.T, dense.scales)
    for b, d in ((blocks, dense), (random_blocks, random_dense)):
        g = rng.normal(0, 0.01, (5, d.points.shape[0]))
        sd_d, sd_c = rng.uniform(0.0, 0.1, 5), rng.uniform(0.0, 0.05, 5)
        wb, sb = b.weights(g, sd_d, sd_c)
        wd, sd = d.weights(g, sd_d, sd_c)
        np.testing.assert_allclose(wb, wd, rtol=1e-9, atol=1e-10 * np.abs(wd).max())
        np.testing.assert_allclose(sb, sd, rtol=1e-9, atol=1e-10 * np.abs(sd).max())
