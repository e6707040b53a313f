"""Levenberg-Marquardt on a series, the Gauss-Newton covariance and the AR(1) check of
the residuals.

The Jacobian is dense and narrow (a handful of parameters, thousands of samples): it is
formed by forward-mode products through the integrator in the parameters its state
depends on, and through the output equation in all
(:meth:`idtool._lawfit._problem.Model.linearised`), with the residuals as their primal,
once per LM step. (The project's coloured LM, :mod:`idtool._fit._lm`, is for the
bench's block-arrow structure; optimistix's LevenbergMarquardt took 180 ms a step here
against 16 ms for the Jacobian itself, on 3,000 samples: 36 s for a LuGre fit.) Every
solve is batched: the multi-start's best starts, and the profile refits with one
parameter held (:mod:`idtool._lawfit._profile`), step together in one loop of one
compiled program, which also gives the residuals and Jacobian at a point (run for no
step), so that a fit compiles no other program of its own but the start grid's loss.
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
from idtool._lawfit._lm import REFIT_DECREMENT, dominated, lm_init, lm_step
from idtool._lawfit._problem import Data, Model, Problem, batch_loss, make_problem, start_grid

__all__ = [
    "MAIN_DECREMENT",
    "PHI_TRIGGER",
    "REFIT_DECREMENT",
    "BatchedLM",
    "Optimum",
    "ar1",
    "fit_lag",
    "refit_batch",
    "solve",
]

# Whiten when the residuals' lag-1 autocorrelation exceeds this and is significant
# (beyond 3/sqrt(n)): below 0.1 white-noise intervals are within ~10% of the AR(1) ones
# (their width scales as sqrt((1 + phi) / (1 - phi))).
PHI_TRIGGER = 0.1
_BEST_STARTS = 4
_MAX_STEPS = 200
MAIN_DECREMENT = 1e-4  # the main fit's convergence threshold (idtool._lawfit._lm)


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
def _lm_batch(model: Model, data: Data, z0, phi, held, value, decrement, max_steps, multistart):
    """LM from each row of ``z0`` with ``z[k, j]`` held at ``value[k, j]`` where
    ``held[k, j]``, the rows stepped together in one loop: ``(z, |r|^2, steps, r, J)``
    per row (``r`` and ``J`` at ``z``: with ``max_steps`` 0 the residuals and Jacobian
    at ``z0``, so that the fit needs no program of its own for them). ``multistart``:
    the rows are starts of one problem, and a row stops once its Gauss-Newton model
    cannot beat the best converged row (:func:`~idtool._lawfit._lm.dominated`)."""

    def lin(z, held, value):
        r, j = model.linearised(data, jnp.where(held, value, z), phi)
        return r, j * ~held  # a held entry does not move

    z0 = jnp.where(held, value, z0)
    state = jax.vmap(lambda z: lm_init(z, data.force_n.shape[0]))(z0)

    def running(state):
        # the start is evaluated whatever the budget (``max_steps`` 0: r and J at z0)
        return (state.steps < 0) | ((state.steps < max_steps) & ~state.done)

    def body(state):
        new = jax.vmap(
            lambda s, h, v: lm_step(functools.partial(lin, held=h, value=v), decrement, s)
        )(state, held, value)
        active = running(state)
        new = jax.tree.map(lambda a, b: jnp.where(_rows(active, a), a, b), new, state)
        # (a traced flag: the main solve and the profile refits share one program)
        return new._replace(done=new.done | (multistart & dominated(new)))

    out = jax.lax.while_loop(lambda s: jnp.any(running(s)), body, state)
    return out.z, jnp.sum(out.r * out.r, axis=1), out.steps, out.r, out.j


@dataclasses.dataclass(frozen=True)
class BatchedLM:
    """:func:`_lm_batch` on one problem, every call padded to ``width`` rows (copies of
    its first row, which converge with it: no extra steps): one batch shape, one
    compiled program per fit (a second shape was 2-5 s of a 13 s first fit of 10,000
    samples). The width is the profile's, two refits per physical parameter (chunks of
    four rows instead doubled a presliding fit's time)."""

    model: Model
    data: Data
    width: int

    def __call__(self, z0, phi, held, value, decrement, max_steps=_MAX_STEPS, multistart=False):
        """LM from the rows of ``z0`` (k, p) with the entries ``held`` (k, p) held at
        ``value`` (k, p); ``multistart``: the rows are starts of one problem
        (:func:`_lm_batch`). Returns ``z`` (k, p), ``|r|^2`` (k,) and the steps (k,) in
        NumPy, and the residuals and Jacobian at ``z`` as the program's arrays (rows past
        k are padding)."""
        k = z0.shape[0]
        if k > self.width:
            raise ValueError(f"z0: {k} rows, more than the batch width {self.width}")
        pad = self.width - k

        def padded(x):
            # (NumPy in: jnp.asarray here compiled a staging program per shape)
            x = np.asarray(x)
            return np.concatenate([x, np.repeat(x[:1], pad, axis=0)])

        # (every argument typed alike on every call: a weakly typed number is a new
        # program)
        z, loss, steps, r, j = _lm_batch(
            self.model,
            self.data,
            padded(z0),
            np.float64(phi),
            padded(held),
            padded(value),
            np.float64(decrement),
            np.int64(max_steps),
            np.bool_(multistart),
        )
        # cut in NumPy: a JAX slice is one more program to compile for every k
        return np.asarray(z)[:k], np.asarray(loss)[:k], np.asarray(steps)[:k], r, j

    def linearise(self, z, phi) -> tuple[np.ndarray, np.ndarray]:
        """The residuals (n,) and their Jacobian (n, p) at ``z``, whitened at ``phi``:
        the program run for no step."""
        z = np.asarray(z, float)[None]
        _, _, _, r, j = self(z, phi, np.zeros(z.shape, bool), z, 0.0, 0)
        # indexed in NumPy: a JAX index compiles two programs per shape
        return np.asarray(r)[0], np.asarray(j)[0]


def _lm(problem: Problem) -> BatchedLM:
    """The batched LM of :func:`_lm_batch` on ``problem``."""
    return BatchedLM(problem.model, problem.data, max(_BEST_STARTS, 2 * problem.n_physical))


def _rows(mask, x):
    """``mask`` (rows,) broadcast against ``x`` (rows, ...)."""
    return mask.reshape(mask.shape + (1,) * (x.ndim - 1))


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
        losses = np.asarray(batch_loss(problem.model, problem.data, grid))
        # as many starts as the batch holds (two per physical parameter, at least
        # four): on a presliding series the main solve from 12 starts left an optimum
        # whose profile refits converged sooner, 44 s a fit against 63 s from 4 starts
        # padded to 12
        rows = grid[np.argsort(np.where(np.isfinite(losses), losses, np.inf))[: lm.width]]
    else:
        rows = np.asarray(starts, float)
    best = _best(lm, rows)
    n = best.r.size
    phi_white = ar1(best.r)
    phi = 0.0
    if abs(phi_white) > max(PHI_TRIGGER, 3.0 / math.sqrt(n)):
        # Cochrane-Orcutt: refit on the innovations, re-estimate phi, refit once more
        phi = phi_white
        for _ in range(2):
            best = _best(lm, best.z[None], phi)
            phi = ar1(lm.linearise(best.z, 0.0)[0])
        phi = float(np.clip(phi, -0.99, 0.99))
        r, j = lm.linearise(best.z, phi)
        best = dataclasses.replace(best, r=r, j=j)
    z_opt, step_count, jac = best.z, best.steps, best.j
    rss = float(best.r @ best.r)
    sigma2 = rss / (n - z_opt.size)
    cov = sigma2 * _pinv(jac.T @ jac)
    return Optimum(z_opt, cov, rss, sigma2, phi, phi_white, step_count), lm


@dataclasses.dataclass(frozen=True)
class _Best:
    """A multi-start's best row: internal ``z``, LM steps, and the whitened residuals
    (n,) and Jacobian (n, p) there."""

    z: np.ndarray
    steps: int
    r: np.ndarray
    j: np.ndarray


def _best(lm: BatchedLM, rows, phi=0.0, decrement=MAIN_DECREMENT, max_steps=_MAX_STEPS):
    """LM from each row (nothing held), whitened at ``phi``: the best row."""
    rows = np.asarray(rows, float)
    held = np.zeros(rows.shape, bool)
    z, loss, steps, r, j = lm(rows, phi, held, rows, decrement, max_steps, multistart=True)
    k = int(np.nanargmin(loss))
    return _Best(z[k], int(steps[k]), np.asarray(r)[k], np.asarray(j)[k])


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
    lagged = _best(lm, rows, optimum.phi, REFIT_DECREMENT, LAG_STEPS)
    z_lag, rss = lagged.z, float(lagged.r @ lagged.r)
    n = problem.series.n_samples
    lag_s = float(lagged_problem.params[k].value(z_lag[k]))
    check = lag_test(lag_s, (optimum.rss, n, optimum.phi), (rss, n, optimum.phi))
    if not check.fitted:
        return problem, dataclasses.replace(optimum, lag_check=check), None
    lagged_opt, _ = solve(lagged_problem, z_lag[None])
    return lagged_problem, dataclasses.replace(lagged_opt, lag_check=check), lm


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
    z, loss, *_ = lm(z0, optimum.phi, held, z0, REFIT_DECREMENT)
    return z, (loss - optimum.rss) / optimum.sigma2
