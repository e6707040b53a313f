"""Levenberg-Marquardt on a series, the Gauss-Newton covariance and the AR(1) check of
the residuals.

The Jacobian is dense and narrow (a handful of parameters, thousands of samples): it is
formed by forward-mode products through the :func:`jax.lax.scan` of the integrator, one
per parameter, with the residuals as their primal, once per LM step. (The project's
coloured LM, :mod:`idtool._fit._lm`, is for the bench's block-arrow structure;
optimistix's LevenbergMarquardt took 180 ms a step here against 16 ms for the
Jacobian itself, on 3,000 samples: 36 s for a LuGre fit.) Every solve is vmapped: the
multi-start's best few, and the profile refits with one parameter held
(:mod:`idtool._lawfit._profile`), run as one batch through one compiled program.
"""

from __future__ import annotations

import dataclasses
import functools
import math

import jax
import jax.numpy as jnp
import numpy as np

from idtool._fit._compiled import QUICK_COMPILE
from idtool._lawfit._lag import LAG, LagCheck, lag_test
from idtool._lawfit._problem import Data, Model, Problem, batch_loss, make_problem, start_grid

__all__ = [
    "PHI_TRIGGER",
    "BatchedLM",
    "Optimum",
    "ar1",
    "fit_lag",
    "levenberg_marquardt",
    "refit_batch",
    "solve",
]

# Whiten when the residuals' lag-1 autocorrelation exceeds this and is significant
# (beyond 3/sqrt(n)): below 0.1 white-noise intervals are within ~10% of the AR(1) ones
# (their width scales as sqrt((1 + phi) / (1 - phi))).
PHI_TRIGGER = 0.1
_BEST_STARTS = 4
_MAX_STEPS = 200
_RTOL = 1e-10
# A profile refit stops once the full Gauss-Newton step would lower -2 log L by less
# than this: its rise is then within 0.01 of the converged one, beside the 1 and 3.84 it
# is compared with (idtool._fit._intervals.REFIT_TOL)
REFIT_DECREMENT = 1e-2
MAIN_DECREMENT = 1e-4  # the main fit's (levenberg_marquardt's default)
_MAX_STEP_Z = 1.0


@dataclasses.dataclass(frozen=True)
class Optimum:
    """The optimum: internal ``z``, residual variance, covariance of z, AR(1) state.

    Attributes:
        z: (p,) internal values.
        cov_z: (p, p) covariance of z (Gauss-Newton, whitened), ``inf`` on the diagonal
            of a parameter the data do not move at all.
        rss: whitened residual sum of squares (scaled units).
        sigma2: its variance per sample, ``rss / (n - p)`` (scaled units).
        phi: the AR(1) coefficient used (0: white).
        phi_white: the lag-1 autocorrelation of the white fit's residuals.
        steps: LM steps of the final solve.
        lag_check: the likelihood-ratio test of the load cell's lag
            (:mod:`idtool._lawfit._lag`), once :func:`fit_lag` has run.
    """

    z: np.ndarray
    cov_z: np.ndarray
    rss: float
    sigma2: float
    phi: float
    phi_white: float
    steps: int
    lag_check: LagCheck | None = None


@functools.partial(jax.jit, static_argnums=0, compiler_options=QUICK_COMPILE)
def _lm_batch(model: Model, data: Data, z0, phi, held, value, decrement, max_steps):
    """LM from each row of ``z0`` with ``z[k, j]`` held at ``value[k, j]`` where
    ``held[k, j]``, as one vmapped program: ``(z, |r|^2, steps)`` per row."""

    def one(z0, held, value):
        def fn(z):
            r = model.residuals(data, jnp.where(held, value, z), phi)
            return r, r

        return levenberg_marquardt(fn, jnp.where(held, value, z0), decrement, max_steps)

    return jax.vmap(one)(z0, held, value)


@dataclasses.dataclass(frozen=True)
class BatchedLM:
    """:func:`_lm_batch` on one problem, every call padded to ``width`` rows (copies of
    its first row, which converge with it: no extra steps): one batch shape, one
    compiled program per fit (a second shape was 2-5 s of a 13 s first fit of 10,000
    samples). The width is the profile's, two refits per physical parameter; the
    integration's scan is latency-bound, so rows in one batch cost little more than one
    (chunks of four rows instead doubled a presliding fit's time)."""

    model: Model
    data: Data
    width: int

    def __call__(self, z0, phi, held, value, decrement, max_steps=_MAX_STEPS):
        """LM from the rows of ``z0`` (k, p) with the entries ``held`` (k, p) held at
        ``value`` (k, p)."""
        k = z0.shape[0]
        if k > self.width:
            raise ValueError(f"z0: {k} rows, more than the batch width {self.width}")
        pad = self.width - k

        def padded(x):
            x = np.asarray(x)
            return jnp.asarray(np.concatenate([x, np.repeat(x[:1], pad, axis=0)]))

        # (every argument typed alike on every call: a weakly typed number is a new
        # program)
        z, loss, steps = _lm_batch(
            self.model,
            self.data,
            padded(z0),
            np.float64(phi),
            padded(held),
            padded(value),
            np.float64(decrement),
            np.int64(max_steps),
        )
        return z[:k], loss[:k], steps[:k]


def _lm(problem: Problem) -> BatchedLM:
    """The batched LM of :func:`_lm_batch` on ``problem``."""
    return BatchedLM(problem.model, problem.data, max(_BEST_STARTS, 2 * problem.n_physical))


def levenberg_marquardt(fn, z0, decrement=1e-4, max_steps=_MAX_STEPS):
    """Minimise ``|r(z)|^2`` (``fn(z) -> (r, r)``) by Levenberg-Marquardt with Moré's
    scaling and Nielsen's damping update (Madsen, Nielsen & Tingleff 2004, Algorithm
    3.16, as :mod:`idtool._fit._lm`), the Jacobian by forward mode (one pass of the
    scan per parameter, with the residuals as its primal). Stops when the full
    Gauss-Newton step would lower -2 log L by less than ``decrement`` (the main fit's
    test of an optimum; 1e-2 for a profile's refits, as :data:`REFIT_DECREMENT`), or a
    step changes z by less than ``_RTOL`` (relative).
    Returns ``(z, |r|^2, steps)``; pure JAX (a ``lax.while_loop``)."""
    jac = jax.jacfwd(fn, has_aux=True)

    def lin(z):
        j, r = jac(z)
        return r, j

    r0, j0 = lin(z0)
    a0 = j0.T @ j0
    state0 = (z0, r0, j0, 1e-3 * jnp.max(jnp.diag(a0)), 2.0, 0, False)

    def cond(state):
        return (state[5] < max_steps) & ~state[6]

    def body(state):
        z, r, j, mu, nu, k, _ = state
        a, g = j.T @ j, j.T @ r
        # Moré's scaling, floored: a parameter in its sigmoid's tail (diag ~ 1e-15 of
        # the others) would otherwise get a huge step that the cap below turns into a
        # step along it alone, and LM would crawl along the flat tail
        d = jnp.maximum(jnp.diag(a), 1e-6 * jnp.max(jnp.diag(a)))
        d = jnp.where(d > 0, d, 1.0)
        h = jnp.linalg.solve(a + mu * jnp.diag(d), -g)
        # at most _MAX_STEP_Z on the internal scale: a longer Gauss-Newton step can jump
        # a bounded parameter into its sigmoid's flat tail, where no gradient brings it
        # back (a LuGre static ratio at 1, its Stribeck velocity at a bound)
        h = h * jnp.minimum(1.0, _MAX_STEP_Z / jnp.max(jnp.abs(h)))
        # the Gauss-Newton decrement, in residual variances: the loss the full GN step
        # would still gain; below _DECREMENT the optimum is reached
        gn = jnp.linalg.solve(a + 1e-12 * jnp.diag(d), g)
        variance = (r @ r) / jnp.maximum(r.size - z.size, 1)
        converged = g @ gn <= decrement * variance
        z_new = z + h
        r_new, j_new = lin(z_new)
        loss, loss_new = r @ r, r_new @ r_new
        predicted = -(2.0 * g @ h + h @ a @ h)  # loss - |r + J h|^2
        rho = (loss - loss_new) / jnp.where(predicted > 0, predicted, 1.0)
        ok = jnp.isfinite(loss_new) & (loss_new < loss)
        small = converged | (jnp.linalg.norm(h) <= _RTOL * (jnp.linalg.norm(z) + _RTOL))
        mu_ok = mu * jnp.maximum(1.0 / 3.0, 1.0 - (2.0 * rho - 1.0) ** 3)
        return (
            jnp.where(ok & ~converged, z_new, z),
            jnp.where(ok & ~converged, r_new, r),
            jnp.where(ok & ~converged, j_new, j),
            jnp.where(ok, mu_ok, mu * nu),
            jnp.where(ok, 2.0, 2.0 * nu),
            k + 1,
            small | (mu > 1e30),
        )

    z, r, _, _, _, k, _ = jax.lax.while_loop(cond, body, state0)
    return z, r @ r, k


def ar1(r: np.ndarray) -> float:
    """Lag-1 autocorrelation of residuals ``r``."""
    r = r - r.mean()
    return float(np.dot(r[1:], r[:-1]) / np.dot(r, r))


def solve(problem: Problem, starts: np.ndarray | None = None) -> tuple[Optimum, BatchedLM]:
    """The least-squares optimum of ``problem`` from the best starts of
    :func:`idtool._lawfit._problem.start_grid` (or from each row of ``starts``),
    whitened by AR(1) when the white fit's residuals are correlated
    (:data:`PHI_TRIGGER`). Returns it and the batched LM (for the profile refits)."""
    lm = _lm(problem)
    if starts is None:
        grid = start_grid(problem)
        losses = np.asarray(batch_loss(problem.model, problem.data, jnp.asarray(grid)))
        # as many starts as the batch holds (two per physical parameter, at least
        # four): on a presliding series the main solve from 12 starts left an optimum
        # whose profile refits converged sooner, 44 s a fit against 63 s from 4 starts
        # padded to 12
        rows = grid[np.argsort(np.where(np.isfinite(losses), losses, np.inf))[: lm.width]]
    else:
        rows = np.asarray(starts, float)
    z_white, step_count = _best(lm, rows)
    r = np.asarray(problem.residuals(jnp.asarray(z_white)))
    n = r.size
    phi_white = ar1(r)
    phi = 0.0
    z_opt = z_white
    if abs(phi_white) > max(PHI_TRIGGER, 3.0 / math.sqrt(n)):
        # Cochrane-Orcutt: refit on the innovations, re-estimate phi, refit once more
        phi = phi_white
        for _ in range(2):
            z_opt, step_count = _best(lm, z_opt[None], phi)
            phi = ar1(np.asarray(problem.residuals(jnp.asarray(z_opt))))
        phi = float(np.clip(phi, -0.99, 0.99))
    zj = jnp.asarray(z_opt)
    rw = np.asarray(problem.residuals(zj, phi))
    jac = np.asarray(_jacobian(problem.model, problem.data, zj, phi))
    rss = float(rw @ rw)
    sigma2 = rss / (n - z_opt.size)
    cov = sigma2 * _pinv(jac.T @ jac)
    return Optimum(z_opt, cov, rss, sigma2, phi, phi_white, step_count), lm


def _best(lm: BatchedLM, rows, phi=0.0, decrement=MAIN_DECREMENT, max_steps=_MAX_STEPS):
    """LM from each row (nothing held); the best row's z and its steps."""
    rows = np.asarray(rows, float)
    held = np.zeros(rows.shape, bool)
    z, loss, steps = lm(rows, phi, held, rows, decrement, max_steps)
    best = int(np.nanargmin(np.asarray(loss)))
    return np.asarray(z[best]), int(steps[best])


# The lag's starts, in sample intervals: a lag and the bristles' compliance both delay
# the force after a reversal, and LM from the lag-free optimum with one small lag
# stayed in the lag-free basin (Kt 1.8x its truth) on one series of eight
LAG_STARTS = (0.1, 0.2, 0.35, 0.5, 0.7, 1.0, 1.4, 2.0, 2.8, 4.0)
# LM steps of the test's lag fits: from a start in the lag's basin LM reached the
# optimum in 8-20 steps; from the others it crawls towards no lag, which the test then
# compares with the lag-free optimum anyway
LAG_STEPS = 12


def fit_lag(problem: Problem, optimum: Optimum) -> tuple[Problem, Optimum, BatchedLM | None]:
    """The load cell's lag (:mod:`idtool._lawfit._lag`) for the lag-free ``optimum`` of
    ``problem``: the lag model fitted from that optimum with the lag at each of
    :data:`LAG_STARTS` (at most :data:`LAG_STEPS` steps, a profile refit's tolerance),
    tested by the likelihood ratio, and where the test keeps it, the lag model's own
    optimum (polished, whitened) and its LM; else ``problem``, ``optimum`` with the test
    attached and no LM."""
    lagged_problem = make_problem(problem.series, problem.law.name, lag=True)
    lm = _lm(lagged_problem)
    k = len(problem.params)  # the lag is declared last
    pick = np.linspace(0, len(LAG_STARTS) - 1, min(lm.width, len(LAG_STARTS))).round()
    rows = np.array([np.append(optimum.z, LAG.internal(LAG_STARTS[int(i)])) for i in pick])
    z_lag, _ = _best(lm, rows, optimum.phi, REFIT_DECREMENT, LAG_STEPS)
    n = problem.series.n_samples
    rss = np.asarray(lagged_problem.residuals(jnp.asarray(z_lag), optimum.phi))
    lag_s = float(lagged_problem.params[k].value(z_lag[k]))
    check = lag_test(lag_s, (optimum.rss, n, optimum.phi), (float(rss @ rss), n, optimum.phi))
    if not check.fitted:
        return problem, dataclasses.replace(optimum, lag_check=check), None
    lagged_opt, _ = solve(lagged_problem, z_lag[None])
    return lagged_problem, dataclasses.replace(lagged_opt, lag_check=check), lm


@functools.partial(jax.jit, static_argnums=0)
def _jacobian(model: Model, data: Data, z, phi):
    return jax.jacfwd(lambda zz: model.residuals(data, zz, phi))(z)


def _pinv(a: np.ndarray) -> np.ndarray:
    """Inverse of ``J^T J``; a parameter whose column is zero (the data do not move it)
    gets an infinite variance, the others the inverse of their block."""
    p = a.shape[0]
    out = np.full((p, p), 0.0)
    moved = np.diag(a) > 1e-300 * max(1.0, float(np.max(np.diag(a))))
    idx = np.flatnonzero(moved)
    out[np.ix_(idx, idx)] = np.linalg.pinv(a[np.ix_(idx, idx)], rcond=1e-13, hermitian=True)
    out[~moved, ~moved] = np.inf
    return out


def refit_batch(lm, optimum: Optimum, index: np.ndarray, value: np.ndarray, starts=None):
    """Refit with ``z[index[k]]`` held at ``value[k]``, every k at once; returns the
    refitted z (k, p) and the rise of ``-2 log L``, ``(RSS_k - RSS) / sigma2``."""
    k = len(index)
    z0 = np.tile(optimum.z, (k, 1)) if starts is None else np.array(starts, float)
    z0[np.arange(k), index] = value
    held = np.zeros(z0.shape, bool)
    held[np.arange(k), index] = True
    z, loss, _ = lm(z0, optimum.phi, held, z0, REFIT_DECREMENT)
    z, loss = np.asarray(z), np.asarray(loss)
    return z, (loss - optimum.rss) / optimum.sigma2
