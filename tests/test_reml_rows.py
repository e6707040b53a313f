"""The levels model's likelihood at one set of sds (:func:`idtool._fit._reml.at_sds`,
a one-row program since issue 28) is the grid program's at that row."""

from __future__ import annotations

import numpy as np
import pytest

from idtool._fit._reml import GRID, at_sds, evaluate


@pytest.mark.parametrize("restricted", [False, True])
def test_one_row_is_the_grids_row(restricted):
    rng = np.random.default_rng(28)
    n, k = 20, 3
    a = rng.normal(size=(n, n))
    v = a @ a.T / n + 0.1 * np.eye(n)
    kinds = np.zeros((n, 2))
    kinds[: n // 2, 0] = 1.0
    kinds[n // 2 :, 1] = 1.0
    x = np.linspace(0.0, 1.0, n // 2)
    zz = np.zeros((n, n))
    zz[n // 2 :, n // 2 :] = np.exp(-((x[:, None] - x[None, :]) ** 2) / 0.1)
    r, g = rng.normal(size=n), rng.normal(size=(n, k))
    args = (v, kinds, zz)
    tau2 = np.array([0.02, 0.05, 0.03]) ** 2
    nll, step = at_sds(tau2, r, g, args, restricted)
    rows = np.tile(tau2, (GRID, 1))
    rows[1:, 0] = 0.5  # the other rows must not matter
    grid_nll, grid_step = (np.asarray(x) for x in evaluate(rows, r, g, *args, restricted))
    assert nll == pytest.approx(float(grid_nll[0]), rel=1e-12)
    np.testing.assert_allclose(step, grid_step[0], rtol=1e-12, atol=0.0)
    assert np.isfinite(nll) and grid_nll[1] != pytest.approx(nll)
