"""The contact's sine and cosine polynomials (idtool._model._trig) against NumPy's."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from idtool._model import _trig as trig

# Two roundings of a value of size 1 (NumPy's own result is within one of the exact
# value, ours within one more): what the module promises for |x| <= 1e6 (its docstring)
TOL = 2.3e-16


@pytest.mark.parametrize("name", ["cos", "sin"])
def test_matches_numpy_over_the_promised_range(name):
    x = np.concatenate(
        [
            np.linspace(-100.0, 100.0, 400_001),
            np.linspace(-1e6, 1e6, 100_001),
            # the quadrant boundaries, where the reduction switches polynomial
            np.arange(-127, 128) * (np.pi / 4.0),
            np.nextafter(np.arange(-127, 128) * (np.pi / 4.0), np.inf),
        ]
    )
    got = np.asarray(getattr(trig, name)(jnp.asarray(x)))
    assert np.max(np.abs(got - getattr(np, name)(x))) < TOL


def test_derivatives_are_the_other_function():
    # autodiff through the polynomials: d cos = -sin, d sin = cos, to the same accuracy
    x = jnp.linspace(0.0, 4.0 * np.pi, 2001)
    d_cos = jax.vmap(jax.grad(trig.cos))(x)
    d_sin = jax.vmap(jax.grad(trig.sin))(x)
    assert np.max(np.abs(np.asarray(d_cos) + np.sin(np.asarray(x)))) < TOL
    assert np.max(np.abs(np.asarray(d_sin) - np.cos(np.asarray(x)))) < TOL
