"""The discrepancy's funnel opened (idtool._posterior._funnel): the transform's density
against the change-of-variables formula with the Jacobian from autodiff, its inverse, and
the funnel's scale measured on a target whose widening is known in closed form."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from idtool._model._params import Param
from idtool._posterior._funnel import FunnelTarget, funnel_scale, open_funnel
from idtool._posterior._prior import Prior

S0 = 0.01  # the scaled parameters' conditional sd at zero discrepancy (internal units)
DELTA0 = 0.004  # where it has grown by sqrt(2)
CENTRE = np.array([0.3, -0.2, 0.0])


class KnownFunnel(eqx.Module):
    """Kt and the gain given the discrepancy sd ``d``: normal about ``CENTRE`` with sd
    ``S0 sqrt(1 + (d / DELTA0)^2)``; mu normal with sd 0.001 whatever ``d``; ``d``
    half-normal(0, 0.1) (its density on the internal scale, Jacobian included)."""

    @property
    def params(self):
        return (
            Param("Kt", "N/m", "log", 1e4, 1e13, physical=True),
            Param("coupling_gain", "1", "log", 1e-5, 1.0, physical=True),
            Param("mu", "1", "tanh", 0.0, 1.0, physical=True),
            Param("discrepancy_fr", "1", "log", 1e-6, 2.0),
        )

    @property
    def names(self):
        return tuple(p.name for p in self.params)

    @property
    def priors(self):
        return (None, None, None, Prior("normal", 0.0, 0.1))

    def log_posterior_batch(self, theta):
        sd_param = self.params[3]
        d = sd_param.value(theta[..., 3])
        s = S0 * jnp.sqrt(1.0 + (d / DELTA0) ** 2)
        lp = -0.5 * ((theta[..., 2] - CENTRE[2]) / 0.001) ** 2
        for j in (0, 1):
            lp = lp - 0.5 * ((theta[..., j] - CENTRE[j]) / s) ** 2 - jnp.log(s)
        return lp + Prior("normal", 0.0, 0.1).logpdf(d) + sd_param.log_jacobian(theta[..., 3])


def _batched(target):
    fn = jax.jit(target.log_posterior_batch)
    return lambda x: np.asarray(fn(jnp.asarray(x)))


def test_the_funnels_scale_is_measured_where_it_is_known():
    """``delta0`` from the curvatures at two sds equals the target's own: its
    conditional sds widen exactly as ``sqrt(1 + (d / delta0)^2)``, the form assumed (the
    second differences' error is ~1e-7 relative at a step of 1e-3 on curvatures of 1e4)."""
    base = KnownFunnel()
    theta = np.array([*CENTRE, base.params[3].internal(0.01)])
    got = funnel_scale(_batched(base), base.params, theta, (0, 1), 3)
    assert got == pytest.approx(DELTA0, rel=1e-4)
    funnel = open_funnel(base, _batched(base), theta, 3)
    assert funnel is not None and funnel.scaled == (0, 1)  # mu is not scaled
    assert funnel.delta0 == pytest.approx(DELTA0, rel=1e-4)


def test_no_funnel_leaves_the_coordinates_alone():
    class Flat(KnownFunnel):
        def log_posterior_batch(self, theta):
            return -0.5 * jnp.sum(((theta[..., :3] - CENTRE) / 0.01) ** 2, axis=-1)

    base = Flat()
    theta = np.array([*CENTRE, base.params[3].internal(0.01)])
    assert funnel_scale(_batched(base), base.params, theta, (0, 1), 3) is None
    assert open_funnel(base, _batched(base), theta, 3) is None


def test_the_walkers_density_is_the_targets_times_the_jacobian():
    """``log p_x(x) = log p(theta(x)) + log |det d theta / d x|``, the determinant from
    JAX's autodiff of the transform (an independent path to the formula ``m log f``);
    and ``from_internal`` inverts ``to_internal``."""
    base = KnownFunnel()
    funnel = FunnelTarget(base, jnp.asarray(CENTRE[:2]), (0, 1), 3, DELTA0)
    rng = np.random.default_rng(4)
    x = np.column_stack(
        [
            CENTRE[:2] + 0.05 * rng.standard_normal((6, 2)),
            CENTRE[2] + 0.001 * rng.standard_normal(6),
        ]
    )
    x = np.column_stack([x, rng.uniform(-4.0, 2.0, 6)])  # sds from 3e-5 to 1.6
    got = np.asarray(funnel.log_posterior_batch(jnp.asarray(x)))
    for row, value in zip(x, got, strict=True):
        jac = jax.jacfwd(funnel.to_internal)(jnp.asarray(row))
        log_det = float(np.linalg.slogdet(np.asarray(jac))[1])
        want = float(base.log_posterior_batch(funnel.to_internal(jnp.asarray(row)))) + log_det
        assert value == pytest.approx(want, rel=1e-12, abs=1e-9)
    back = np.asarray(funnel.from_internal(funnel.to_internal(jnp.asarray(x))))
    np.testing.assert_allclose(back, x, rtol=0, atol=1e-13)
    again = FunnelTarget.from_doc(base, funnel.to_doc())
    np.testing.assert_array_equal(np.asarray(again.log_posterior_batch(jnp.asarray(x))), got)
