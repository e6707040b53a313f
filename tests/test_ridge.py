"""The posterior's start (issue 26): inside the parameters' ranges, and along a ridge the
data barely bound (idtool._posterior._ridge): the profile follows a curved ridge between
two plateaus, the sheared coordinates keep the density, and the one-sided statement is
the fit's rule."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from idtool._fit._result import Z_AT_BOUND, Estimate, interval_statement, weakly_identified
from idtool._model._params import Param
from idtool._posterior._prior import Prior
from idtool._posterior._ridge import (
    RIDGE_POINTS,
    RIDGE_REFINE_LEVELS,
    RIDGE_REFINE_WITHIN,
    Ridge,
    RidgeTarget,
    open_sides,
    ridge_profile,
    ridge_walkers,
    weak_parameter,
)
from idtool._posterior._start import MAX_START_SD_Z, initial_walkers, start_within
from idtool._report._fit_text import _est

KT = Param("Kt", "N/m", "log", 1e4, 1e13, physical=True)
GAIN = Param("coupling_gain", "1", "log", 1e-5, 1.0, physical=True)
KT_PRIOR = Prior("loguniform", 1e4, 1e13)
GAIN_PRIOR = Prior("loguniform", 1e-5, 1.0)


def _path(z):
    """The ridge: the gain's internal value along Kt's, from one plateau's to the other's
    (0.64 apart, as the creep and Coulomb limits' gains on the ceiling bench)."""
    return 1.0 - 0.32 * (1.0 + jnp.tanh(2.0 * z))


def _log_lik(z, g):
    """Two plateaus in Kt (creep and Coulomb limits) joined by a valley 5 deep at z = 0,
    the gain tight (sd 0.03) around the ridge."""
    return -0.5 * ((g - _path(z)) / 0.03) ** 2 - 5.0 * jnp.exp(-2.0 * z**2)


class TwoPlateaus(eqx.Module):
    """A levels-like target: log-posterior of internal (Kt, gain), priors included."""

    @property
    def params(self):
        return (KT, GAIN)

    @property
    def priors(self):
        return (KT_PRIOR, GAIN_PRIOR)

    @property
    def names(self):
        return ("Kt", "coupling_gain")

    def log_posterior_batch(self, theta):
        z, g = theta[:, 0], theta[:, 1]
        own = sum(
            pr.logpdf(p.value(theta[:, i])) + p.log_jacobian(theta[:, i])
            for i, (p, pr) in enumerate(zip(self.params, self.priors, strict=True))
        )
        return _log_lik(z, g) + own


def _batched(target):
    def fn(x):
        return np.asarray(target.log_posterior_batch(jnp.asarray(np.atleast_2d(x))))

    return fn


def test_a_fit_at_a_bound_starts_its_walkers_inside_the_range():
    # the ceiling bench's fit: Kt at its bound, internal -30, Gauss-Newton variance 1e19
    theta = np.array([-30.0, 1.0])
    cov = np.array([[1e19, -0.5 * np.sqrt(1e19) * 0.01], [-0.5 * np.sqrt(1e19) * 0.01, 1e-4]])
    centre, spread = start_within(theta, cov, (KT, GAIN))
    assert centre[0] == -Z_AT_BOUND and centre[1] == 1.0
    assert np.isclose(np.sqrt(spread[0, 0]), MAX_START_SD_Z)
    assert np.isclose(spread[1, 1], 1e-4)  # a spread within the cap is kept
    corr = spread[0, 1] / np.sqrt(spread[0, 0] * spread[1, 1])
    assert np.isclose(corr, -0.5)  # and the correlation
    target = TwoPlateaus()

    def fn(x):
        return np.asarray(target.log_posterior_batch(jnp.asarray(x)))

    p0 = initial_walkers(theta, cov, fn, 32, np.random.default_rng(0), target.params)
    assert np.all(np.abs(p0[:, 0]) < Z_AT_BOUND + 5 * MAX_START_SD_Z)
    assert np.all(np.isfinite(fn(p0)))


def test_only_a_parameter_wider_than_half_a_decade_is_profiled():
    theta = np.array([0.0, 1.0])
    # d ln Kt / dz = ln(1e9) / 4 = 5.18 at z = 0: an internal sd of 0.02 is 0.18 decades
    narrow = np.diag([0.02**2, 1e-4])
    assert weak_parameter((KT, GAIN), theta, narrow, 2) is None
    decade = np.diag([0.115**2, 1e-4])  # one decade (the coupling bench's 0.8-1.1)
    assert weak_parameter((KT, GAIN), theta, decade, 2) == 0
    wide = np.diag([1.0, 1e-4])  # over ~9 decades
    assert weak_parameter((KT, GAIN), theta, wide, 2) == 0
    at_bound = np.array([-30.0, 1.0])  # at the bound, whatever its variance
    assert weak_parameter((KT, GAIN), at_bound, narrow, 2) == 0
    assert weak_parameter((KT, GAIN), theta, wide, 0) is None  # physical ones only


def test_the_profile_follows_the_curved_ridge_to_the_other_plateau():
    target = TwoPlateaus()
    # started on one plateau
    ridge = ridge_profile(_batched(target), target, np.array([-3.0, 1.0]), 0)
    assert ridge.grid[0] == -Z_AT_BOUND and ridge.grid[-1] == Z_AT_BOUND
    # the coarse points, and a quarter unit apart wherever the posterior has mass
    coarse = np.linspace(-Z_AT_BOUND, Z_AT_BOUND, RIDGE_POINTS)
    assert np.all(np.isin(coarse, ridge.grid)) and np.all(np.diff(ridge.grid) > 0)
    step = 0.5**RIDGE_REFINE_LEVELS * (coarse[1] - coarse[0])
    massive = np.maximum(ridge.log_post[:-1], ridge.log_post[1:])
    massive = massive > np.max(ridge.log_post) - RIDGE_REFINE_WITHIN + 1.0
    assert massive.sum() > RIDGE_POINTS
    np.testing.assert_allclose(np.diff(ridge.grid)[massive], step)
    # every profile point on the ridge (the other plateau's gain is 21 sds away); the
    # gain's own prior and Jacobian move the posterior's maximum off the likelihood's by
    # 4e-4 (sd^2 times their slope), a fiftieth of the ridge's sd
    np.testing.assert_allclose(ridge.theta[:, 1], _path(ridge.grid), atol=1e-3)
    expected = np.asarray(_log_lik(jnp.asarray(ridge.grid), _path(jnp.asarray(ridge.grid))))
    # log_lik: the parameter's own prior and Jacobian taken out (the gain's prior stays)
    gain_prior = np.asarray(
        GAIN_PRIOR.logpdf(GAIN.value(ridge.theta[:, 1])) + GAIN.log_jacobian(ridge.theta[:, 1])
    )
    # (the likelihood at that maximum is 0.5 (4e-4 / 0.03)^2 = 1e-4 below the ridge's)
    np.testing.assert_allclose(ridge.log_lik - gain_prior, expected, atol=1e-3)
    # the walkers start on both plateaus, on the ridge
    centres, spread = ridge_walkers(ridge, np.diag([0.25, 1e-4]), 64, np.random.default_rng(1))
    assert np.sum(centres[:, 0] < -1.0) >= 10 and np.sum(centres[:, 0] > 1.0) >= 10
    assert spread[0, 1] == 0.0 and spread[0, 0] < 1e-10


def test_walkers_start_in_proportion_to_the_profiles_mass_on_an_uneven_grid():
    # a flat profile, refined on its left half: the walkers still spread evenly in z
    grid = np.concatenate([np.linspace(-7.0, 0.0, 29), np.linspace(1.0, 7.0, 7)])
    flat = Ridge(0, grid, np.zeros((grid.size, 2)), np.zeros(grid.size), np.zeros(grid.size))
    centres, _ = ridge_walkers(flat, np.eye(2), 4000, np.random.default_rng(2))
    left = np.mean(centres[:, 0] < 0.0)
    # the cells reach halfway to their neighbours, a half cell beyond the ends: 7.125 of
    # 14.625 units lie left of 0; binomial sd sqrt(0.25 / 4000) = 0.008
    assert abs(left - 7.125 / 14.625) < 0.03
    assert centres[:, 0].min() >= -7.125 and centres[:, 0].max() <= 7.5


def _ridge(log_lik):
    grid = np.linspace(-Z_AT_BOUND, Z_AT_BOUND, log_lik.size)
    return Ridge(0, grid, np.zeros((grid.size, 2)), log_lik, log_lik)


def test_the_sides_the_data_bound_are_the_fits_rule_on_the_profile():
    z = np.linspace(-Z_AT_BOUND, Z_AT_BOUND, RIDGE_POINTS)
    assert open_sides(_ridge(-0.5 * z**2)) == ""  # a peak: bounded on both sides
    # two plateaus and a valley (the ceiling bench): the 95% set reaches both edges, and
    # the interval is said to be the range's, not the data's
    assert open_sides(_ridge(-5.0 * np.exp(-2.0 * z**2))) == "neither"
    # falling only towards small values: bounded below, open above ("> lo")
    rising = np.minimum(z, 0.0) * 3.0
    assert open_sides(_ridge(rising)) == "lower"
    assert open_sides(_ridge(rising[::-1])) == "upper"
    # said as the fit's one-sided estimates are
    e = Estimate("Kt", "N/m", 1e9, 0.0, (1.6e8, 1e13), one_sided="lower")
    assert e.statement.startswith("> 1.6e+08")
    e = Estimate("Kt", "N/m", 1e9, 0.0, (1.5e4, 3.8e12), one_sided="neither")
    assert e.statement == "[1.5e+04, 3.8e+12] (95%; not identified: bounded by its range alone)"


def test_the_sheared_coordinates_keep_the_density():
    target = TwoPlateaus()
    ridge = ridge_profile(_batched(target), target, np.array([-3.0, 1.0]), 0)
    sheared = RidgeTarget.along(target, ridge)
    theta = np.array([[-2.0, 1.01], [0.3, 0.7], [4.0, 0.35], [-8.0, 1.2]])
    x = np.asarray(sheared.from_internal(jnp.asarray(theta)))
    np.testing.assert_allclose(np.asarray(sheared.to_internal(jnp.asarray(x))), theta, atol=1e-12)
    # on the ridge the other coordinate is (about) zero
    assert abs(float(x[0, 1]) - (1.01 - float(_path(-2.0)))) < 0.01
    np.testing.assert_allclose(
        np.asarray(sheared.log_posterior_batch(jnp.asarray(x))),
        np.asarray(target.log_posterior_batch(jnp.asarray(theta))),
        rtol=1e-12,
    )
    # a shear: unit Jacobian determinant, so no density correction
    jac = jax.jacfwd(lambda v: sheared.to_internal(v))(jnp.asarray(x[1]))
    assert np.isclose(float(jnp.linalg.det(jac)), 1.0)
    # recorded with the chain and rebuilt on resume
    again = RidgeTarget.from_doc(target, sheared.to_doc())
    np.testing.assert_array_equal(np.asarray(again.path), np.asarray(sheared.path))


def test_an_interval_over_two_decades_is_said_to_be_weakly_identified():
    # bounded by the data on both sides, but 6.5 decades wide (the "ceiling" bench's
    # fit, seed 903): said so with its width, and recorded in fit.json
    e = Estimate("Kt", "N/m", 3e8, 0.0, (1.0e5, 3.2e11))
    assert e.weakly_identified
    assert e.statement == "[1e+05, 3.2e+11] (95%; weakly identified: spans 6.5 decades)"
    assert _est(e)["weakly_identified"] is True and "one_sided" not in _est(e)
    # two decades exactly is not over them; a one-sided or unidentified one is said so
    narrow = Estimate("Kt", "N/m", 1e9, 0.0, (1e8, 1e10))
    assert not narrow.weakly_identified and narrow.statement == "[1e+08, 1e+10]"
    assert "weakly_identified" not in _est(narrow)
    for side in ("lower", "upper", "neither"):
        wide = Estimate("Kt", "N/m", 1e9, 0.0, (1.5e4, 3.8e12), one_sided=side)
        assert not wide.weakly_identified and "weakly" not in wide.statement
    # a parameter that can be negative (a slope) is never "weakly identified"
    assert not weakly_identified(-1.0, 1e3, "")
    # the caller that knows better overrides the rule (a scatter sd's spike towards zero)
    assert interval_statement(1e-7, 0.03, "", weak=False) == "[1e-07, 0.03]"
    assert "weakly" in interval_statement(1e-7, 0.03, "")
