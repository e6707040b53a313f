"""The walkers' box coordinates (idtool._posterior._box): the map and its inverse, the
Jacobian against automatic differentiation, a log-uniform prior flat on the box, the
walls, and a profiled ridge carried onto the box with its mass kept."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from idtool._model._params import Param
from idtool._posterior._box import BoxTarget, base_internal, ridge_in_box
from idtool._posterior._ridge import Ridge

PARAMS = (
    Param("Kt", "N/m", "log", 1e4, 1e13, physical=True),
    Param("ratio", "1", "tanh", -1.0, 3.0),
    Param("offset_n", "N", "linear", centre=2.0, scale=0.5),
)


class _PriorOnly:
    """A target whose density is each parameter's prior on the internal scale,
    normalised: log-uniform Kt (``d ln Kt / dz`` over ``ln(hi / lo)``: sigmoid(z)
    (1 - sigmoid(z))), uniform ratio (``2 s (1 - s)``, ``s = sigmoid(2 z)``), and a
    standard normal z of the linear one without its constant."""

    params = PARAMS
    names = tuple(p.name for p in PARAMS)
    priors = ()

    def log_posterior_batch(self, z):
        s1, s2 = jax.nn.sigmoid(z[..., 0]), jax.nn.sigmoid(2.0 * z[..., 1])
        return jnp.log(s1 * (1.0 - s1)) + jnp.log(2.0 * s2 * (1.0 - s2)) - 0.5 * z[..., 2] ** 2


def test_the_map_round_trips_and_boxes_only_bounded_parameters():
    box = BoxTarget.of(_PriorOnly())
    assert box.slopes == (1.0, 2.0, 0.0)
    z = np.random.default_rng(0).uniform(-8.0, 8.0, (50, 3))
    x = np.asarray(box.from_internal(jnp.asarray(z)))
    assert np.all((x[:, :2] > 0.0) & (x[:, :2] < 1.0))
    np.testing.assert_array_equal(x[:, 2], z[:, 2])
    np.testing.assert_allclose(np.asarray(box.to_internal(jnp.asarray(x))), z, rtol=0, atol=1e-9)
    # u is the place in the range: affine in ln(value) for a log parameter, in the value
    # for a tanh one
    kt, ratio = PARAMS[0].value(z[:, 0]), PARAMS[1].value(z[:, 1])
    np.testing.assert_allclose(x[:, 0], np.log(kt / 1e4) / np.log(1e9), rtol=1e-12)
    np.testing.assert_allclose(x[:, 1], (ratio + 1.0) / 4.0, rtol=0, atol=1e-12)
    assert BoxTarget.of(_PriorOnly(), (1,)).slopes == (0.0, 2.0, 0.0)
    again = BoxTarget.from_doc(_PriorOnly(), box.to_doc())
    assert again.slopes == box.slopes and box.to_doc()["kind"] == "box"


def test_the_jacobian_is_the_maps_own_derivative():
    box = BoxTarget.of(_PriorOnly())
    x = jnp.asarray([[0.03, 0.9, 1.5], [0.5, 0.2, -3.0], [0.999, 0.001, 0.0]])
    jac = jax.vmap(jax.jacfwd(box.to_internal))(x)
    expected = np.log(np.abs(np.linalg.det(np.asarray(jac))))
    np.testing.assert_allclose(np.asarray(box.log_jacobian(x)), expected, rtol=1e-12)


def test_a_log_uniform_prior_is_flat_on_the_box_and_the_walls_reject():
    """On the box a log-uniform prior on Kt and a uniform one on the ratio, normalised,
    have density 1 (log 0) whatever u: the density was carried, not lost; and outside
    0 < u < 1 the density is zero."""
    box = BoxTarget.of(_PriorOnly())
    u = np.random.default_rng(1).uniform(1e-6, 1.0 - 1e-6, (200, 2))
    x = jnp.asarray(np.column_stack([u, np.zeros(200)]))
    lp = np.asarray(box.log_posterior_batch(x))
    np.testing.assert_allclose(lp, 0.0, rtol=0, atol=1e-9)
    walls = jnp.asarray([[0.0, 0.5, 0.0], [1.0, 0.5, 0.0], [0.5, -0.1, 0.0], [0.5, 1.2, 0.0]])
    assert np.all(np.asarray(box.log_posterior_batch(walls)) == -np.inf)


def test_a_ridge_on_the_box_keeps_its_mass_and_maps_back():
    """A profile along Kt (internal scale) carried onto the box: the same points, the
    other coordinates mapped, and the mass of each cell unchanged (density per unit of
    u times du equals density per unit of z times dz, to the cells' first order)."""
    grid = np.linspace(-6.0, 6.0, 241)
    theta = np.column_stack([grid, 0.3 * np.tanh(grid), np.sin(grid)])
    log_post = -0.5 * ((grid - 1.0) / 1.5) ** 2
    ridge = Ridge(0, grid, theta, log_post, log_post)
    box = BoxTarget.of(_PriorOnly())
    on_box = ridge_in_box(ridge, box)
    np.testing.assert_allclose(on_box.grid, 1.0 / (1.0 + np.exp(-grid)), rtol=1e-12)
    back = np.asarray(box.to_internal(jnp.asarray(on_box.theta)))
    np.testing.assert_allclose(back, theta, rtol=0, atol=1e-9)
    mass_z = np.exp(log_post) * np.gradient(grid)
    mass_u = np.exp(on_box.log_post) * np.gradient(on_box.grid)
    # the cells' widths through the map (central differences, the ends' one-sided ones
    # left out) agree to second order in the 0.05 spacing: ~ 0.05^2 / 6 = 4e-4
    np.testing.assert_allclose(mass_u[1:-1], mass_z[1:-1], rtol=2e-3)
    assert on_box.log_lik is ridge.log_lik


def test_base_internal_unwinds_every_layer():
    box = BoxTarget.of(_PriorOnly())
    outer = BoxTarget(box, (0.0, 0.0, 0.0))  # an identity layer over the box
    z = jnp.asarray([[1.0, -0.5, 0.25]])
    x = box.from_internal(z)
    np.testing.assert_allclose(np.asarray(base_internal(outer, x)), np.asarray(z), atol=1e-12)
    assert base_internal(_PriorOnly(), z) is z


@pytest.mark.parametrize("x", [0.2, 0.7])
def test_the_density_on_the_box_is_the_targets_times_the_jacobian(x):
    box = BoxTarget.of(_PriorOnly(), (0,))
    row = jnp.asarray([[x, 0.3, -0.4]])
    z = box.to_internal(row)
    direct = _PriorOnly().log_posterior_batch(z) + box.log_jacobian(row)
    np.testing.assert_allclose(np.asarray(box.log_posterior_batch(row)), np.asarray(direct))
