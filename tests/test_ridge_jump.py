"""The ridge-jump move (idtool._posterior._ridge_jump): a chain whose walkers all start in
the peak between two wide plateaus recovers the plateaus' share of the mass, checked
against the marginal by quadrature; the proposal's density and Hastings factor."""

import emcee
import equinox as eqx
import jax.numpy as jnp
import numpy as np

from idtool._model._params import Param
from idtool._posterior._moves import sampler_moves
from idtool._posterior._prior import Prior
from idtool._posterior._record import LEVELS
from idtool._posterior._ridge import RidgeTarget, ridge_profile
from idtool._posterior._ridge_jump import RIDGE_UNIFORM_SHARE, ridge_cells, ridge_jump
from idtool._posterior._snooker import snooker_move

KT = Param("Kt", "N/m", "log", 1e4, 1e13, physical=True)
GAIN = Param("coupling_gain", "1", "log", 1e-5, 1.0, physical=True)
PRIORS = (Prior("loguniform", 1e4, 1e13), Prior("loguniform", 1e-5, 1.0))
PEAK_Z = 0.3


def _path(z):
    """The gain's internal value along Kt's ridge, from the creep plateau's to the
    Coulomb plateau's (0.64 apart)."""
    return 1.0 - 0.32 * (1.0 + jnp.tanh(2.0 * (z - PEAK_Z)))


class PeakAndPlateaus(eqx.Module):
    """Kt's levels posterior on a bench whose coupling law the fit does not ship (seed
    503): a peak 3 high and 0.25 wide in internal Kt between two plateaus that span the
    rest of its range, the gain tight (sd 0.03) around a curved ridge; priors and
    Jacobians included."""

    @property
    def params(self):
        return (KT, GAIN)

    @property
    def priors(self):
        return PRIORS

    @property
    def names(self):
        return ("Kt", "coupling_gain")

    def log_posterior_batch(self, theta):
        z, g = theta[..., 0], theta[..., 1]
        lik = -0.5 * ((g - _path(z)) / 0.03) ** 2 + 3.0 * jnp.exp(-(((z - PEAK_Z) / 0.25) ** 2))
        own = sum(
            pr.logpdf(p.value(theta[..., i])) + p.log_jacobian(theta[..., i])
            for i, (p, pr) in enumerate(zip(self.params, self.priors, strict=True))
        )
        return lik + own


def _fn(target):
    # compiled once per batch shape: run op by op, the chains of
    # test_walkers_gathered_in_the_peak_find_the_plateaus_mass_again spent ~40 s in
    # JAX's dispatch of a 2-D density
    log_post = eqx.filter_jit(lambda t, x: t.log_posterior_batch(x))

    def fn(x):
        return np.asarray(log_post(target, jnp.asarray(np.atleast_2d(x))))

    return fn


def _plateau_share_by_quadrature(target) -> float:
    """P(|z - peak| > 0.75) from the 2-D density on a fine grid (the gain integrated
    over its ridge +- 0.45, 15 of its sds; z over +-14, where the prior's tails are e^-14)."""
    z = np.linspace(-14.0, 14.0, 5601)
    dg = np.linspace(-0.45, 0.45, 601)
    theta = np.stack(np.broadcast_arrays(z[:, None], np.asarray(_path(z))[:, None] + dg), -1)
    lp = np.asarray(target.log_posterior_batch(jnp.asarray(theta)))
    marginal = np.exp(lp - lp.max()).sum(axis=1)  # the grids are even: sums are integrals
    return float(marginal[np.abs(z - PEAK_Z) > 0.75].sum() / marginal.sum())


def _plateau_share(moves, sheared, seed=3) -> tuple[float, float]:
    """The share of a chain's draws on the plateaus, every walker started in the peak
    (32 x 4000, the first 1000 dropped), and its effective sample size (the
    indicator's integrated autocorrelation time, emcee's estimator)."""
    rng = np.random.default_rng(seed)
    x0 = np.column_stack([PEAK_Z + 0.05 * rng.standard_normal(32), 0.01 * rng.standard_normal(32)])
    sampler = emcee.EnsembleSampler(32, 2, _fn(sheared), vectorize=True, moves=moves)
    sampler._random.seed(seed)
    sampler.run_mcmc(x0, 4000)
    z = sampler.get_chain(discard=1000)[..., 0]  # the profiled coordinate is not sheared
    on = (np.abs(z - PEAK_Z) > 0.75).astype(float)
    tau = float(emcee.autocorr.integrated_time(on[:, :, None], quiet=True)[0])
    return float(on.mean()), on.size / tau


def test_walkers_gathered_in_the_peak_find_the_plateaus_mass_again():
    target = PeakAndPlateaus()
    truth = _plateau_share_by_quadrature(target)
    assert 0.2 < truth < 0.5  # the plateaus hold much of the mass, though 3 lower
    ridge = ridge_profile(_fn(target), target, np.array([PEAK_Z, 1.0 - 0.32]), 0)
    sheared = RidgeTarget.along(target, ridge)
    # the sampler's moves along a ridge: DE, the snooker, DE's mode jump, the ridge jump
    share, ess = _plateau_share(sampler_moves(LEVELS, sheared), sheared)
    # 4 binomial sds at the chain's effective sample size (a fixed seed: no flake)
    assert ess > 1000 and abs(share - truth) < 4.0 * np.sqrt(truth * (1 - truth) / ess)
    # the same moves with emcee 3.1.6's snooker in place of ter Braak & Vrugt's
    moves = [
        (emcee.moves.DESnookerMove(), w) if i == 1 else (m, w)
        for i, (m, w) in enumerate(sampler_moves(LEVELS, sheared))
    ]
    biased, ess = _plateau_share(moves, sheared)
    assert abs(biased - truth) > 4.0 * np.sqrt(truth * (1 - truth) / ess)


def test_the_snooker_proposal_is_ter_braak_and_vrugts():
    # x' = x + gamma e (e . (z1 - z2)), e = (x - z) / |x - z|; factor (d - 1) log ratio
    s = np.array([[1.0, 2.0, 0.0]])
    z, z1, z2 = np.array([0.0, 0.0, 0.0]), np.array([3.0, 1.0, 1.0]), np.array([1.0, 0.0, 2.0])

    class Picks:  # complementary sets of one walker each, in this order
        def randint(self, n):
            return 0

        def shuffle(self, w):
            pass

    q, factor = snooker_move(gamma=1.5).get_proposal(s, [z[None], z1[None], z2[None]], Picks())
    e = s[0] / np.sqrt(5.0)
    expected = s[0] + 1.5 * e * np.dot(e, z1 - z2)
    np.testing.assert_allclose(q[0], expected, rtol=1e-14)
    np.testing.assert_allclose(factor[0], 2.0 * np.log(np.linalg.norm(expected) / np.sqrt(5.0)))


def test_the_proposal_density_and_its_hastings_factor():
    grid = np.array([-2.0, -1.0, 0.0, 0.5, 1.0, 3.0])
    log_post = np.array([-5.0, -4.0, 0.0, -1.0, -np.inf, -6.0])
    edges, share = ridge_cells(grid, log_post)
    np.testing.assert_allclose(edges, [-2.5, -1.5, -0.5, 0.25, 0.75, 2.0, 4.0])
    width = np.diff(edges)
    mass = np.exp(np.where(np.isfinite(log_post), log_post, -np.inf)) * width
    expected = RIDGE_UNIFORM_SHARE * width / width.sum() + (1 - RIDGE_UNIFORM_SHARE) * (
        mass / mass.sum()
    )
    np.testing.assert_allclose(share, expected, rtol=1e-12)
    assert share[4] == RIDGE_UNIFORM_SHARE * width[4] / width.sum()  # failed: uniform only
    move = ridge_jump(0, grid, log_post)
    coords = np.array([[0.1, 7.0], [3.5, -1.0], [9.0, 2.0]])
    new, factor = move.get_proposal(coords, np.random.RandomState(0))
    np.testing.assert_array_equal(new[:, 1], coords[:, 1])  # the other coordinates kept
    assert np.all((new[:, 0] >= edges[0]) & (new[:, 0] <= edges[-1]))
    density = share / width

    def log_q(z):
        return np.log(density[np.searchsorted(edges, z, side="right") - 1])

    np.testing.assert_allclose(factor[:2], log_q(coords[:2, 0]) - log_q(new[:2, 0]), rtol=1e-12)
    assert factor[2] == -np.inf  # a walker beyond the profile's ends is not moved by it
