"""Priors, transforms and noise densities against independent values (SciPy, autodiff,
dense linear algebra): the pieces of the log-posterior one by one."""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from sample_helpers import two_trace_data
from scipy import stats

import idtool
from idtool._model._benchmodel import bench_model
from idtool._model._noise import NOISE_MODELS, whiten
from idtool._posterior._likelihood import (
    NUISANCE_PRIOR_SD,
    build_target,
    marginal_loglik,
    physical_values,
    predict_blocks,
    sampled_params,
)
from idtool._posterior._prior import Prior, default_prior

X = np.array([0.02, 0.3, 1.7, 25.0])


@pytest.mark.parametrize(
    ("prior", "reference"),
    [
        (Prior("uniform", 0.01, 30.0), stats.uniform(0.01, 30.0 - 0.01)),
        (Prior("loguniform", 0.01, 30.0), stats.loguniform(0.01, 30.0)),
        (Prior("normal", 0.3, 0.1), stats.norm(0.3, 0.1)),
        (Prior("lognormal", 0.3, 0.7), stats.lognorm(0.7, scale=0.3)),
        (Prior("gamma", 2.0, 0.1), stats.gamma(2.0, scale=1 / 0.1)),
    ],
    ids=lambda x: getattr(x, "dist", ""),
)
def test_prior_log_densities_are_normalised_densities(prior, reference):
    """Exactly SciPy's log-pdf (normalised, not just up to a constant), -inf outside."""
    np.testing.assert_allclose(np.asarray(prior.logpdf(jnp.asarray(X))), reference.logpdf(X))
    if prior.dist in ("uniform", "loguniform"):
        assert float(prior.logpdf(jnp.asarray(31.0))) == -math.inf


PARAMS = [
    idtool.Param("a", "N", "log", 1e-3, 1e5),
    idtool.Param("b", "1", "tanh", -1.0, 1.0),
    idtool.Param("c", "s", "linear", centre=2.0, scale=0.05),
]


@pytest.mark.parametrize("param", PARAMS, ids=lambda p: p.kind)
def test_log_jacobian_is_the_log_derivative_of_the_transform(param):
    """Against autodiff of ``value`` (an independent path) where float64 resolves the
    derivative (|z| <= 7: ``1 - sigmoid(z)`` keeps ~10 digits), and against the
    asymptote far out (|z| = 30), where autodiff itself loses ~3 digits to ``1 - s``
    and the naive formula would underflow."""
    for z in (-7.0, -3.0, -1.0, 0.0, 0.5, 3.0, 7.0):
        slope = float(jax.grad(param.value)(jnp.asarray(z)))
        got = float(param.log_jacobian(jnp.asarray(z)))
        assert got == pytest.approx(math.log(slope), rel=1e-9, abs=1e-9), z
        assert param.slope(z) == pytest.approx(slope, rel=1e-9)
    for z in (-30.0, 30.0):
        if param.kind == "log":  # sigmoid -> 0 or 1: log lo or log hi, times e^-|z|
            end = math.log(param.hi) if z > 0 else math.log(param.lo)
            expected = end + math.log(math.log(param.hi / param.lo)) - abs(z)
        elif param.kind == "tanh":  # (hi - lo) / 2 sech^2 z ~ 2 (hi - lo) e^(-2|z|)
            expected = math.log(2.0 * (param.hi - param.lo)) - 2.0 * abs(z)
        else:
            expected = math.log(param.scale)
        assert float(param.log_jacobian(jnp.asarray(z))) == pytest.approx(expected, abs=1e-9)
    for z in (-5.0, -0.3, 0.0, 2.0, 5.0):
        assert param.internal(float(param.value(jnp.asarray(z)))) == pytest.approx(z, abs=1e-9)


def test_default_priors_cover_each_parameters_range():
    assert default_prior(PARAMS[0]) == Prior("loguniform", 1e-3, 1e5)
    assert default_prior(PARAMS[1]) == Prior("uniform", -1.0, 1.0)
    assert default_prior(PARAMS[2]).dist == "normal"


@pytest.mark.parametrize("noise", ["student-t", "ar1-student-t"])
def test_student_t_innovations_are_scipys(noise):
    model = NOISE_MODELS.get(noise)()
    u = jnp.linspace(-8.0, 8.0, 9)
    for nu in (1.5, 4.0, 30.0, 900.0):
        got = np.asarray(model.innovation_logpdf(u, {"nu": jnp.asarray(nu)}))
        np.testing.assert_allclose(got, stats.t(nu).logpdf(np.asarray(u)), rtol=1e-12)
        info = float(model.nuisance_information({"nu": jnp.asarray(nu)}))
        # Fisher information of a t location: (nu + 1) / (nu + 3), by quadrature
        score2 = stats.t(nu).expect(lambda x, n=nu: ((n + 1) * x / (n + x * x)) ** 2)
        assert info == pytest.approx(score2, rel=1e-6)


def test_student_t_marginal_likelihood_is_its_laplace_approximation():
    """The Student-t marginal likelihood (nuisances profiled, Gaussian curvature with the
    t's Fisher information) against the same quantities from dense NumPy algebra."""
    data = two_trace_data()
    model = bench_model(data, coupling="constant", noise="student-t")
    z = model.z0(Kt=1e9, coupling_gain=0.02)
    table = {p.name: default_prior(p) for p in sampled_params(model)}
    target = build_target(model, z, "student-t", table)
    theta = jnp.asarray(np.concatenate([z[: model.n_shared], [0.0, 0.5]]))  # sigma, nu
    v = physical_values(theta, target)
    e_res = predict_blocks(v, target) - target.force_n + 0.3
    ll, shift = marginal_loglik(e_res, v, target)

    sigma, nu = float(v["sigma_n"]), float(v["nu"])
    w = np.asarray(whiten(e_res, target.first, 0.0))
    jw = np.asarray(target.jac_e)
    trace = np.asarray(data.block_trace)
    n_tr = data.n_traces
    big = np.zeros((w.size, 4 * n_tr))
    for i in range(n_tr):
        big[trace == i, 4 * i : 4 * i + 4] = jw[trace == i]
    info = (nu + 1) / (nu + 3) / sigma**2
    prec = info * big.T @ big + np.eye(4 * n_tr) / NUISANCE_PRIOR_SD**2
    s = np.linalg.solve(prec, -info * big.T @ w)  # Gauss-Newton step from zero shift
    np.testing.assert_allclose(np.asarray(shift).ravel(), s, rtol=1e-8, atol=1e-10)
    u = (w + big @ s) / sigma
    dense = np.sum(stats.t(nu).logpdf(u)) - w.size * np.log(sigma)
    dense -= 0.5 * np.sum(s**2) / NUISANCE_PRIOR_SD**2
    dense -= 0.5 * np.linalg.slogdet(prec)[1] + s.size * np.log(NUISANCE_PRIOR_SD)
    assert float(ll) == pytest.approx(dense, rel=1e-9)
