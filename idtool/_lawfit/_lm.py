"""The Levenberg-Marquardt step of ``fit-law`` (:mod:`idtool._lawfit._solve` batches it):
Moré's scaling and Nielsen's damping update (Madsen, Nielsen & Tingleff 2004, Algorithm
3.16, as :mod:`idtool._fit._lm`), one evaluation of the model per step, and the rule
that stops a start of a multi-start which cannot win (:func:`dominated`)."""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp

__all__ = ["REFIT_DECREMENT", "LMState", "dominated", "lm_init", "lm_step"]

# A profile refit stops once the full Gauss-Newton step would lower -2 log L by less
# than this: its rise is then within 0.01 of the converged one, beside the 1 and 3.84 it
# is compared with (idtool._fit._intervals.REFIT_TOL)
REFIT_DECREMENT = 1e-2
_MAX_STEP_Z = 1.0
_RTOL = 1e-10


class LMState(NamedTuple):
    """One row's Levenberg-Marquardt state (:func:`lm_step`): the accepted point with
    its residuals and Jacobian, and the candidate the next step evaluates."""

    z: jax.Array  # accepted
    r: jax.Array
    j: jax.Array
    candidate: jax.Array
    predicted: jax.Array  # the candidate's predicted decrease of |r|^2
    mu: jax.Array  # damping
    nu: jax.Array  # its growth on a rejected step
    steps: jax.Array  # evaluations after the start's
    done: jax.Array  # converged, failed, or (multistart) dominated
    converged: jax.Array
    model_min: jax.Array  # |r|^2 at the Gauss-Newton step's model minimum, at z


def lm_init(z0, n: int) -> LMState:
    """The state before the start is evaluated (its candidate ``z0``, taken whatever
    its loss); ``n`` residuals."""
    p = z0.shape[0]
    inf, false = jnp.asarray(jnp.inf), jnp.asarray(False)
    return LMState(
        z0, jnp.full(n, jnp.inf), jnp.zeros((n, p)), z0, jnp.asarray(1.0), jnp.asarray(0.0),
        jnp.asarray(2.0), jnp.asarray(-1), false, false, inf,
    )  # fmt: skip


def lm_step(lin, decrement, state: LMState) -> LMState:
    """One Levenberg-Marquardt step on ``lin(z) -> (r, J)``: the candidate
    evaluated, accepted if it lowers ``|r|^2`` (the start always), the damping updated
    (Nielsen), and the next candidate from the accepted point. One evaluation per step,
    so that the compiled loop holds one pass of the integrator, not two."""
    first = state.steps < 0
    r_new, j_new = lin(state.candidate)
    loss, loss_new = state.r @ state.r, r_new @ r_new
    ok = first | (jnp.isfinite(loss_new) & (loss_new < loss))
    rho = (loss - loss_new) / jnp.where(state.predicted > 0, state.predicted, 1.0)
    mu_ok = state.mu * jnp.maximum(1.0 / 3.0, 1.0 - (2.0 * rho - 1.0) ** 3)
    z = jnp.where(ok, state.candidate, state.z)
    r, j = jnp.where(ok, r_new, state.r), jnp.where(ok, j_new, state.j)
    a, g = j.T @ j, j.T @ r
    mu = jnp.where(first, 1e-3 * jnp.max(jnp.diag(a)), jnp.where(ok, mu_ok, state.mu * state.nu))
    nu = jnp.where(ok, 2.0, 2.0 * state.nu)
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
    # would still gain; below ``decrement`` the optimum is reached
    gn = jnp.linalg.solve(a + 1e-12 * jnp.diag(d), g)
    loss = r @ r
    variance = loss / jnp.maximum(r.size - z.size, 1)
    converged = g @ gn <= decrement * variance
    small = converged | (jnp.linalg.norm(h) <= _RTOL * (jnp.linalg.norm(z) + _RTOL))
    return LMState(
        z, r, j, z + h, -(2.0 * g @ h + h @ a @ h), mu, nu, state.steps + 1,
        small | (mu > 1e30), small, loss - g @ gn,
    )  # fmt: skip


def dominated(state: LMState) -> jax.Array:
    """Rows of a multi-start that cannot win: not converged, and the minimum of their
    Gauss-Newton model (``|r|^2 - g^T (J^T J)^-1 g`` at their last step) is not below
    the best converged row's ``|r|^2`` by :data:`REFIT_DECREMENT` residual variances.
    On a sliding LuGre series 3 of 12 starts sat in a basin 4.5x the best's loss and 6
    more crept to the best's optimum: the main solve ran 46 steps where the best had
    converged in 18. A row still far from a minimum has a large decrement and runs
    on; one that could beat the best by less than the profile refits' tolerance would
    move no interval (on a presliding series, 4 rows crept for 28 steps more towards a
    loss their models put 0.0008 variances below the best's)."""
    loss = jnp.sum(state.r * state.r, axis=1)
    best = jnp.min(jnp.where(state.converged, loss, jnp.inf))
    variance = best / jnp.maximum(state.r.shape[1] - state.z.shape[1], 1)
    margin = REFIT_DECREMENT * variance
    return ~state.done & jnp.isfinite(best) & (state.model_min >= best - margin)
