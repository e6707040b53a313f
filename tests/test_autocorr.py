"""The sampler's autocorrelation time (idtool._posterior._diagnostics._tau) is emcee's
estimator: equal to ``emcee.autocorr.integrated_time`` on AR(1) chains, at lengths
whose fast transform length is not a power of two; a walker that never moved is left
out of the average."""

import emcee
import numpy as np
import pytest

from idtool._posterior._diagnostics import _tau


@pytest.mark.parametrize("steps", [401, 3000, 12345])
def test_tau_is_emcees_estimator(steps):
    rng = np.random.default_rng(steps)
    phi = np.array([0.0, 0.5, 0.9, 0.98])  # tau = (1 + phi) / (1 - phi): 1, 3, 19, 99
    x = np.empty((steps, 8, phi.size))
    x[0] = rng.normal(size=(8, phi.size))
    for t in range(1, steps):
        x[t] = phi * x[t - 1] + rng.normal(size=(8, phi.size))
    expected = emcee.autocorr.integrated_time(x, c=5, quiet=True)
    np.testing.assert_allclose(_tau(x), expected, rtol=1e-12)


def test_a_walker_that_never_moved_is_left_out():
    rng = np.random.default_rng(0)
    x = rng.normal(size=(500, 6, 2))
    stuck = x.copy()
    stuck[:, 0, :] = 1.0  # zero variance: no autocorrelation defined
    np.testing.assert_allclose(
        _tau(stuck), emcee.autocorr.integrated_time(x[:, 1:], c=5, quiet=True), rtol=1e-12
    )
