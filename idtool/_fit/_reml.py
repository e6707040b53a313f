"""The levels model's likelihood in its three sds (REML), for :mod:`idtool._fit._variability`.

The free levels' residuals ``r`` against the physical model, linearised as ``g`` in its
parameters, are ``N(0, V + Sigma(sds))``: ``V`` the free levels' covariance, ``Sigma``
the trace scatter (OFF rows, FR rows) and the operating-point discrepancy's correlation
``zz`` between FR rows. Theta is profiled by its generalised least-squares step; the
restricted likelihood adds ``log det(g' C^-1 g)`` (REML: the sds' estimate then does
not shrink with the parameters fitted, Patterson & Thompson 1971). Pure and jittable.

The programs work on ``C`` in per-trace blocks and a low rank
(:mod:`idtool._fit._level_cov`): linear in the traces. :func:`neg_log_lik` on the dense
matrices is the reference the tests check them against (dense, a grid of 241 Cholesky
factorisations of the (2 traces)^2 matrix and every BFGS step one more: ~traces^3,
12 of the 14 s of the levels model at 96 traces, issue 28).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx
from jax.scipy.linalg import cho_solve

from idtool._fit._compiled import program
from idtool._fit._level_cov import factor, solve
from idtool._model._xp import xp

__all__ = [
    "GRID",
    "at_sds",
    "covariance",
    "evaluate",
    "fit_sds",
    "neg_log_lik",
    "neg_log_lik_blocks",
]

GRID = 241  # points of each sd's grid (REML likelihood times the spike-and-slab prior)


def covariance(tau2, v, kinds, zz):
    """``V + Sigma(sds)`` as a dense matrix (the reference): ``kinds`` (n, 2) one-hot
    OFF / FR rows, ``zz`` the discrepancy's correlation between the FR rows (0 in the
    OFF rows). NumPy or JAX by argument."""
    diag = kinds[:, 0] * tau2[0] + kinds[:, 1] * tau2[1]
    return v + xp(tau2, v, kinds, zz).diag(diag) + tau2[2] * zz


def neg_log_lik(tau2, r, g, v, kinds, zz, restricted):
    """-log of the (restricted) likelihood of the level residuals ``r`` (theta profiled
    on the linearised model ``g``), up to a constant; and theta's Gauss-Newton step. On
    the dense matrices: the reference of :func:`neg_log_lik_blocks`."""
    c = covariance(tau2, v, kinds, zz)
    chol = jnp.linalg.cholesky(c)
    ci_r = cho_solve((chol, True), r)
    ci_g = cho_solve((chol, True), g)
    a = g.T @ ci_g
    step = jnp.linalg.solve(a, g.T @ ci_r)
    rt = r - g @ step
    quad = rt @ cho_solve((chol, True), rt)
    logdet_c = 2.0 * jnp.sum(jnp.log(jnp.diagonal(chol)))
    logdet_a = jnp.linalg.slogdet(a)[1]
    return 0.5 * (quad + logdet_c + jnp.where(restricted, logdet_a, 0.0)), step


def neg_log_lik_blocks(tau2, r2, g2, block, low, disc, measured, restricted):
    """:func:`neg_log_lik` with ``C`` in blocks (:class:`~idtool._fit._level_cov.
    LevelCovariance`'s arrays) and ``r``, ``g`` in pairs (m, 2), (m, 2, k)
    (:func:`~idtool._fit._level_cov.to_pairs`): time linear in the traces."""
    f = factor(tau2, block, low, disc, measured)
    ci = solve(f, jnp.concatenate([r2[:, :, None], g2], axis=2))
    ci_r, ci_g = ci[:, :, 0], ci[:, :, 1:]
    a = jnp.einsum("mik,mil->kl", g2, ci_g)
    step = jnp.linalg.solve(a, jnp.einsum("mik,mi->k", g2, ci_r))
    rt = r2 - g2 @ step
    quad = jnp.sum(rt * (ci_r - ci_g @ step))
    logdet_a = jnp.linalg.slogdet(a)[1]
    return 0.5 * (quad + f[4] + jnp.where(restricted, logdet_a, 0.0)), step


@program()
def fit_sds(s0, free, r2, g2, block, low, disc, measured):
    """REML log sds (optimistix BFGS); the sds outside ``free`` stay 0."""

    def loss(s, _):
        tau2 = free * jnp.exp(2.0 * s)
        return neg_log_lik_blocks(tau2, r2, g2, block, low, disc, measured, True)[0]

    sol: optx.Solution = optx.minimise(
        loss, optx.BFGS(rtol=1e-8, atol=1e-8), s0, max_steps=200, throw=False
    )
    return sol.value


@program()
def evaluate(tau2_rows, r2, g2, block, low, disc, measured, restricted):
    """-log (restricted) likelihood and theta's step at every row of ``tau2_rows``
    (rows, 3): one program for the profiles and the steps."""
    return jax.vmap(
        lambda t: neg_log_lik_blocks(t, r2, g2, block, low, disc, measured, restricted)
    )(tau2_rows)


def at_sds(tau2, r2, g2, args, restricted=False):
    """:func:`evaluate` at one ``tau2``: a one-row program of its own (loaded from the
    disk cache when warm). Padded to the grid's shape, each call cost GRID - 1 wasted
    evaluations (13 s of a 96-trace ``idtool fit`` while they were dense, issue 28)."""
    nll, step = evaluate(np.asarray(tau2, float)[None, :], r2, g2, *args, restricted)
    return float(np.asarray(nll)[0]), np.asarray(step)[0]
