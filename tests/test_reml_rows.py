"""The levels model's likelihood in blocks (issue 28): at one set of sds
(:func:`idtool._fit._reml.at_sds`, a one-row program) it is the grid program's at that
row, and both are the dense reference (:func:`idtool._fit._reml.neg_log_lik`) on the
assembled matrix; the blocks' solves and log-determinant are the dense ones."""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np
import pytest

from idtool._fit._level_cov import LevelCovariance, factor, from_pairs, solve, to_pairs
from idtool._fit._reml import GRID, at_sds, covariance, evaluate, neg_log_lik


def random_parts(seed: int = 28) -> tuple[LevelCovariance, np.ndarray, np.ndarray]:
    """Blocks of 12 traces (8 FRs measured), 2 shared columns, 3 operating points; a
    residual and a Jacobian (3 columns) in pairs."""
    rng = np.random.default_rng(seed)
    m, k = 12, 3
    measured = np.ones(m, bool)
    measured[[1, 5, 6, 10]] = False
    a = rng.normal(size=(m, 2, 2))
    block = a @ a.transpose(0, 2, 1) + 0.1 * np.eye(2)
    block[~measured, 1, :] = block[~measured, :, 1] = 0.0
    block[~measured, 1, 1] = 1.0
    low = rng.normal(size=(m, 2, 2))
    low[~measured, 1] = 0.0
    disc = np.zeros((m, 2, 3))
    root = np.linalg.cholesky(np.array([[1.0, 0.5, 0.2], [0.5, 1.0, 0.5], [0.2, 0.5, 1.0]]))
    disc[measured, 1] = root[rng.integers(0, 3, measured.sum())]
    parts = LevelCovariance(block, low, disc, measured.astype(float))
    r2 = to_pairs(rng.normal(size=m + measured.sum()), measured)
    g2 = to_pairs(rng.normal(size=(m + measured.sum(), k)), measured)
    return parts, r2, g2


def test_blocks_solve_and_log_determinant_are_the_dense_ones():
    parts, r2, _ = random_parts()
    meas = parts.measured.astype(bool)
    tau2 = np.array([0.2, 0.5, 0.3]) ** 2
    c = parts.dense(tau2)
    f = factor(tau2, *parts.arrays)
    r = from_pairs(r2, meas)
    got = from_pairs(solve(f, r2[:, :, None])[:, :, 0], meas)
    np.testing.assert_allclose(got, np.linalg.solve(c, r), rtol=1e-10)
    assert float(f[4]) == pytest.approx(np.linalg.slogdet(c)[1], rel=1e-12)
    assert parts.quad(r, tau2) == pytest.approx(r @ np.linalg.solve(c, r), rel=1e-12)
    # the same on JAX arrays, as the programs run it
    fj = factor(jnp.asarray(tau2), *(jnp.asarray(x) for x in parts.arrays))
    np.testing.assert_allclose(
        np.asarray(solve(fj, jnp.asarray(r2)[:, :, None])), solve(f, r2[:, :, None]), rtol=1e-12
    )


@pytest.mark.parametrize("restricted", [False, True])
def test_one_row_is_the_grids_row_and_the_dense_reference(restricted):
    parts, r2, g2 = random_parts()
    meas = parts.measured.astype(bool)
    args = parts.arrays
    tau2 = np.array([0.02, 0.05, 0.03]) ** 2
    nll, step = at_sds(tau2, r2, g2, args, restricted)
    rows = np.tile(tau2, (GRID, 1))
    rows[1:, 0] = 0.5  # the other rows must not matter
    grid_nll, grid_step = (np.asarray(x) for x in evaluate(rows, r2, g2, *args, restricted))
    assert nll == pytest.approx(float(grid_nll[0]), rel=1e-12)
    np.testing.assert_allclose(step, grid_step[0], rtol=1e-12, atol=0.0)
    assert np.isfinite(nll) and grid_nll[1] != pytest.approx(nll)
    # the dense reference: V and zz assembled, kinds one-hot
    v = parts.dense(np.zeros(3))
    no_v = LevelCovariance(0.0 * parts.block, 0.0 * parts.low, parts.disc, parts.measured)
    zz = no_v.dense(np.array([0.0, 0.0, 1.0]))
    m, n = meas.size, v.shape[0]
    kinds = np.zeros((n, 2))
    kinds[:m, 0] = kinds[m:, 1] = 1.0
    np.testing.assert_allclose(
        covariance(tau2, v, kinds, zz), parts.dense(tau2), rtol=1e-12, atol=1e-15
    )
    ref, ref_step = neg_log_lik(
        jnp.asarray(tau2),
        jnp.asarray(from_pairs(r2, meas)),
        jnp.asarray(from_pairs(g2, meas)),
        jnp.asarray(v),
        jnp.asarray(kinds),
        jnp.asarray(zz),
        restricted,
    )
    assert nll == pytest.approx(float(ref), rel=1e-10)
    np.testing.assert_allclose(step, np.asarray(ref_step), rtol=1e-9)
