"""Levenberg-Marquardt for block-structured least squares, with a coloured Jacobian.

A bench fit has a few shared parameters (Kt, mu, the coupling, the actuator slopes) and
a few nuisances per trace (offset, pull start, horn lags), and each trace's residuals
depend on its own nuisances only. The Jacobian is then block-arrow shaped: of its ~100
columns, the per-trace ones touch disjoint rows. Columns that never share a row can be
given one colour and probed by a single forward-mode product (Curtis, Powell and Reid
1974), so a Jacobian costs ``n_shared + n_slots`` JVPs (10 on the example) instead of
one per parameter (102); :func:`idtool._fit._program.bench_normal_equations` goes to 8 by
differentiating the bench model in its per-trace levels. optimistix's own
LevenbergMarquardt builds the dense Jacobian column by column (about 14x the work per
step here, benchmarks/bench_fit.py); :class:`ColouredLevenbergMarquardt` is an optimistix
least-squares solver that keeps the classical algorithm (Moré-scaled damping, Nielsen's
update of the damping) around the coloured Jacobian, and :func:`levenberg_marquardt` runs
it through :func:`optimistix.least_squares`.

The normal equations ``J^T J`` and ``J^T r`` are assembled from per-trace sums of the
coloured columns, never from the dense Jacobian, and kept in their arrowhead blocks
(:class:`idtool._fit._arrow.Arrow`): the nuisances are eliminated per trace by their
Schur complement at every step, so a step costs time and memory linear in the traces
(the dense ``(p, p)`` system cost O(traces^3) to assemble and solve: 0.08 s for 15
steps on 24 traces, 0.73 s on 48). Everything is pure JAX and jittable;
the loop is a ``lax.while_loop``, so one compiled program serves every start, mask and
AR(1) coefficient.

References: K. Madsen, H. B. Nielsen, O. Tingleff, *Methods for non-linear least squares
problems* (2004), Algorithm 3.16; J. J. Moré, *The Levenberg-Marquardt algorithm:
implementation and theory* (1978).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx
from jaxtyping import Array, Bool, Float, Int

from idtool._fit._arrow import Arrow, DenseNormal

__all__ = [
    "ColouredJacobian",
    "ColouredLevenbergMarquardt",
    "LMResult",
    "arrow_equations",
    "arrow_of_blocks",
    "coloured_blocks",
    "coloured_equations",
    "levenberg_marquardt",
    "levenberg_marquardt_loop",
    "normal_equations",
]


class ColouredJacobian(eqx.Module):
    """Sparsity of a residual function's Jacobian: rows in groups, columns in colours.

    Attributes:
        seeds: (c, p) 0/1 tangents, one per colour.
        colour: (p,) colour of each parameter.
        param_group: (p,) the row group each parameter moves alone, -1 if every one
            (shared); no (groups, p) array: memory stays linear in the groups.
        row_group: (n,) group of each residual row.
    """

    seeds: Float[np.ndarray, "c p"]
    colour: Int[np.ndarray, " p"]
    param_group: Int[np.ndarray, " p"]
    row_group: Int[np.ndarray, " n"]
    n_groups: int = eqx.field(static=True)
    n_shared: int = eqx.field(static=True, default=0)  # the first colours, one each
    # the normal equations as dense (p, p) matrices instead of arrowhead blocks: the
    # reference the tests check the arrowhead against
    dense: bool = eqx.field(static=True, default=False)

    @classmethod
    def from_groups(
        cls, param_group: np.ndarray, row_group: np.ndarray, dense: bool = False
    ) -> ColouredJacobian:
        """Structure where parameter j moves every row (``param_group[j] == -1``, shared)
        or only the rows of its group ``param_group[j]``.

        Shared parameters get a colour each; the k-th parameter of every group shares
        colour ``n_shared + k``, so every group must list its parameters in the same
        order (as :class:`idtool._model._benchmodel.FitModel` does).
        """
        param_group = np.asarray(param_group, int)
        row_group = np.asarray(row_group, int)
        n_groups = int(row_group.max()) + 1
        colour = np.empty(param_group.size, int)
        shared = param_group < 0
        colour[shared] = np.arange(int(shared.sum()))
        rank = np.zeros(n_groups, int)
        for j in np.flatnonzero(~shared):
            g = param_group[j]
            colour[j] = int(shared.sum()) + rank[g]
            rank[g] += 1
        n_colours = int(colour.max()) + 1
        seeds = (colour[None, :] == np.arange(n_colours)[:, None]).astype(float)
        # NumPy, not JAX, arrays: the structure may first be built inside a trace (a
        # cached property), and it must not capture that trace's values.
        return cls(
            seeds=seeds,
            colour=colour,
            param_group=param_group,
            row_group=row_group,
            n_groups=n_groups,
            n_shared=int(shared.sum()),
            dense=dense,
        )


def normal_equations(
    fn: Callable[[Array], Array], z: Float[Array, " p"], structure: ColouredJacobian
) -> tuple[Float[Array, " n"], Float[Array, "p p"], Float[Array, " p"]]:
    """Residuals ``r``, ``J^T J`` and ``J^T r`` at ``z`` from one JVP per colour, dense
    (p, p): the reference for :func:`arrow_equations` (its assembly costs O(groups p^2)
    time and memory)."""
    r, lin = jax.linearize(fn, z)
    c = jax.vmap(lin)(structure.seeds).T  # (n, colours): coloured columns
    g = structure.row_group
    cc = jax.ops.segment_sum(c[:, :, None] * c[:, None, :], g, structure.n_groups)
    cr = jax.ops.segment_sum(c * r[:, None], g, structure.n_groups)
    col = structure.colour
    pg = jnp.asarray(structure.param_group)
    act = ((pg[None, :] < 0) | (pg[None, :] == jnp.arange(structure.n_groups)[:, None])) * 1.0
    jtj = jnp.einsum("mp,mq,mpq->pq", act, act, cc[:, col][:, :, col])
    jtr = jnp.einsum("mp,mp->p", act, cr[:, col])
    return r, jtj, jtr


def coloured_blocks(
    fn: Callable[[Array], Array], z: Float[Array, " p"], structure: ColouredJacobian
) -> tuple[Float[Array, " n"], Float[Array, "m c c"], Float[Array, "m c"]]:
    """Residuals ``r`` at ``z`` and, per row group, the Gram matrix of the coloured
    columns (m, c, c) and their products with ``r`` (m, c): one JVP per colour, memory
    linear in the groups. Within group ``g`` the colours are its parameters (the shared
    ones first, then the group's own in order), so these are the group's own blocks of
    ``J^T J`` and ``J^T r``."""
    r, lin = jax.linearize(fn, z)
    c = jax.vmap(lin)(structure.seeds).T  # (n, colours): coloured columns
    g = structure.row_group
    cc = jax.ops.segment_sum(c[:, :, None] * c[:, None, :], g, structure.n_groups)
    cr = jax.ops.segment_sum(c * r[:, None], g, structure.n_groups)
    return r, cc, cr


def arrow_of_blocks(h: Float[Array, "m q q"], gh: Float[Array, "m q"], n_shared: int) -> Arrow:
    """The arrowhead normal equations from each group's own blocks over (shared
    parameters, its own): the shared block summed over the groups."""
    s = n_shared
    return Arrow(
        a=h[:, :s, :s].sum(0), b=h[:, :s, s:], d=h[:, s:, s:], gs=gh[:, :s].sum(0), gb=gh[:, s:]
    )


def arrow_equations(
    fn: Callable[[Array], Array], z: Float[Array, " p"], structure: ColouredJacobian
) -> tuple[Float[Array, " n"], Arrow | DenseNormal]:
    """Residuals ``r`` and the normal equations at ``z`` in arrowhead blocks
    (:class:`~idtool._fit._arrow.Arrow`; dense if ``structure.dense``), for ``z`` laid
    out shared parameters first, then the groups' parameters slot by slot."""
    r, cc, cr = coloured_blocks(fn, z, structure)
    arrow = arrow_of_blocks(cc, cr, structure.n_shared)
    return r, (arrow.as_dense() if structure.dense else arrow)


class LMResult(eqx.Module):
    """Outcome of :func:`levenberg_marquardt`.

    ``residuals`` are the residuals at ``z``; ``aux`` what ``equations`` returned
    beside the normal equations there; ``normal`` the normal equations at ``z`` (masked
    parameters included; arrowhead blocks, :class:`~idtool._fit._arrow.Arrow`), ready
    for a Gauss-Newton covariance; ``jtj`` and ``jtr`` their dense form.
    ``steps`` counts trial steps (accepted or not), ``n_jacobians`` linearisations
    (each the residuals and one JVP per colour): the start point and every trial.
    """

    z: Float[Array, " p"]
    loss: Float[Array, ""]
    residuals: Float[Array, " n"]
    aux: Any
    normal: Arrow | DenseNormal
    steps: Int[Array, ""]
    n_jacobians: Int[Array, ""]
    converged: Bool[Array, ""]

    @property
    def jtj(self) -> Float[Array, "p p"]:
        """``J^T J`` at ``z``, dense (p, p)."""
        return self.normal.dense()[0]

    @property
    def jtr(self) -> Float[Array, " p"]:
        """``J^T r`` at ``z``."""
        return self.normal.grad


def coloured_equations(
    fn: Callable[[Array, Any], Array], structure: ColouredJacobian
) -> Callable[[Array, Any], tuple[Array, Arrow | DenseNormal, tuple]]:
    """The ``equations`` of :func:`levenberg_marquardt` for residuals ``fn(z, args)``
    with the sparsity ``structure``: :func:`arrow_equations`, no auxiliary output."""

    def equations(z, args):
        return (*arrow_equations(lambda y: fn(y, args), z, structure), ())

    return equations


class _Linearisation(eqx.Module):
    """What one linearisation gives the update: residuals, normal equations (their
    masked version ``a`` too, and its gradient ``g``) and the caller's auxiliary
    output."""

    r: Array
    normal: Any
    a: Any
    g: Array
    aux: Any


def _initial_state(z0: Array, n: int, normal: Any, aux: Any) -> dict[str, Any]:
    """The iteration's state before the first linearisation: ``n`` residuals,
    ``normal`` and ``aux`` the shapes of the normal equations and of the caller's
    auxiliary output; the first update accepts ``z0`` whatever its loss."""
    p = z0.size

    def zeros(tree):
        return jax.tree.map(lambda x: jnp.zeros(x.shape, x.dtype), tree)

    return dict(
        aux=zeros(aux),
        z=z0,
        loss=jnp.asarray(jnp.inf),
        r=jnp.zeros(n),
        normal=zeros(normal),
        a=zeros(normal),
        g=jnp.zeros(p),
        trial=z0,
        predicted=jnp.asarray(1.0),
        first=jnp.asarray(True),
        damping=jnp.asarray(1e-3),  # relative to each curvature (Moré scaling below)
        nu=jnp.asarray(2.0),
        scale=jnp.zeros(p),
        steps=jnp.asarray(0),
        n_jac=jnp.asarray(0),
        done=jnp.asarray(False),
        failed=jnp.asarray(False),
    )


def _update(
    s: dict[str, Any], lin: _Linearisation, mask: Array, tol: float, max_step: float
) -> dict[str, Any]:
    """One Levenberg-Marquardt iteration from the linearisation ``lin`` at the trial
    point ``s["trial"]``: accept or reject it, adapt the damping (Nielsen), and set the
    next trial point (Moré-scaled damped Gauss-Newton step)."""
    loss_new = 0.5 * jnp.dot(lin.r, lin.r)
    gain = (s["loss"] - loss_new) / jnp.maximum(s["predicted"], 1e-300)
    accept = s["first"] | (jnp.isfinite(loss_new) & (gain > 0.0))

    def pick(new, old):
        return jnp.where(accept, new, old)

    z, loss, r = pick(s["trial"], s["z"]), pick(loss_new, s["loss"]), pick(lin.r, s["r"])
    normal = jax.tree.map(pick, lin.normal, s["normal"])
    a, g = jax.tree.map(pick, lin.a, s["a"]), pick(lin.g, s["g"])
    aux = jax.tree.map(pick, lin.aux, s["aux"])
    shrink = jnp.where(s["first"], 1.0, jnp.maximum(1.0 / 3.0, 1.0 - (2.0 * gain - 1.0) ** 3))
    damping = jnp.where(accept, s["damping"] * shrink, s["damping"] * s["nu"])
    nu = jnp.where(accept, 2.0, 2.0 * s["nu"])

    # The next trial step. Moré's scaling: damp each parameter in proportion to the
    # largest curvature it has shown so far. A running maximum, so that a direction
    # that turns flat (a bounded parameter saturating) cannot take an unbounded step.
    diag = a.diagonal()
    scale = jnp.maximum(s["scale"], diag)
    scale = jnp.maximum(scale, 1e-12 * jnp.max(scale))
    h = a.solve(damping * scale, -g)
    h = jnp.where(mask, h, 0.0)
    # The internal scale is of order one (a bounded parameter spans its range within
    # |z| < 10): a longer step only happens along a direction gone flat, which the
    # damping cannot hold, so it is cut back.
    h = h * jnp.minimum(1.0, max_step / jnp.maximum(jnp.max(jnp.abs(h)), 1e-300))
    # Converged when the Gauss-Newton decrement is below tol times the residual
    # variance; jitter keeps a rank-deficient J^T J solvable (flat directions only).
    gn = a.solve(jnp.full(g.size, 1e-12 * jnp.max(diag)), g)
    return dict(
        aux=aux,
        z=z,
        loss=loss,
        r=r,
        normal=normal,
        a=a,
        g=g,
        trial=z + h,
        predicted=-jnp.dot(g, h) - 0.5 * jnp.dot(h, a.matvec(h)),
        first=jnp.asarray(False),
        damping=damping,
        nu=nu,
        scale=scale,
        steps=s["steps"] + jnp.where(s["first"], 0, 1),
        n_jac=s["n_jac"] + 1,
        done=accept & (jnp.dot(g, gn) <= tol * 2.0 * loss / r.size),
        failed=~(damping < 1e30),
    )


def _linearise(fn: Callable, z: Array, args: Any, mask: Array) -> _Linearisation:
    r, (normal, aux) = fn(z, args)
    a = normal.masked(mask)
    return _Linearisation(r=r, normal=normal, a=a, g=a.grad, aux=aux)


class ColouredLevenbergMarquardt(optx.AbstractLeastSquaresSolver):
    """Levenberg-Marquardt as an optimistix least-squares solver, for residual functions
    that linearise themselves from a coloured Jacobian.

    ``fn(z, args)`` returns the residuals ``r`` and, as its auxiliary output,
    ``(normal, aux)`` at ``z``, ``normal`` the normal equations ``J^T J`` and ``J^T r``
    (an :class:`~idtool._fit._arrow.Arrow`, or their dense reference)
    (:func:`coloured_equations` makes such a function
    from plain residuals and their sparsity; the bench model's
    :func:`idtool._fit._program.bench_normal_equations` goes through the per-trace levels). So
    one evaluation of ``fn`` per iteration is the whole linearisation: the residuals
    and one JVP per colour, never a dense Jacobian. optimistix drives the loop
    (:func:`optimistix.least_squares`); each iteration is :func:`_update`.

    ``options``: ``mask`` (bool, per parameter: which ones move), ``max_steps`` (a
    traced step budget: one compiled program serves every budget) and optionally
    ``tol`` (a traced ``rtol``, which it then replaces). Attributes:
    ``rtol``, the convergence threshold on the Gauss-Newton decrement ``g^T (J^T J)^-1
    g`` relative to the residual variance ``|r|^2 / n`` (the optimum is then within
    ``sqrt(rtol)`` standard errors in every direction); ``max_step``, the longest step
    on the internal scale. ``atol`` and ``norm`` are optimistix's interface and unused:
    the decrement is scale-free.
    """

    rtol: float = 1e-8
    atol: float = 0.0
    norm: Callable = optx.max_norm
    max_step: float = 5.0

    def init(self, fn, y, args, options, f_struct, aux_struct, tags):
        return _initial_state(jnp.asarray(y), f_struct.shape[0], *aux_struct)

    def step(self, fn, y, args, options, state, tags):
        lin = _linearise(fn, state["trial"], args, options["mask"])
        tol = options.get("tol", self.rtol)
        state = _update(state, lin, options["mask"], tol, self.max_step)
        return state["z"], state, (state["normal"], state["aux"])

    def terminate(self, fn, y, args, options, state, tags):
        budget = state["steps"] >= options["max_steps"]
        stop = ~state["first"] & (state["done"] | state["failed"] | budget)
        return stop, optx.RESULTS.successful

    def postprocess(self, fn, y, aux, args, options, state, tags, result):
        return y, aux, {}


def _solver_fn(equations: Callable) -> Callable:
    """``equations`` as the residual function the solver takes: ``(r, (normal,
    aux))``."""

    def fn(z, a):
        r, normal, aux = equations(z, a)
        return r, (normal, aux)

    return fn


def _result(s: dict[str, Any]) -> LMResult:
    return LMResult(
        z=s["z"],
        loss=s["loss"],
        residuals=s["r"],
        aux=s["aux"],
        normal=s["normal"],
        steps=s["steps"],
        n_jacobians=s["n_jac"],
        converged=s["done"],
    )


def levenberg_marquardt(
    equations: Callable[[Array, Any], tuple[Array, Any, Any]],
    z0: Float[Array, " p"],
    args: Any,
    mask: Bool[Array, " p"],
    max_steps: int | Array = 100,
    tol: float | Array = 1e-8,
    max_step: float = 5.0,
) -> LMResult:
    """Minimise ``0.5 |r(z)|^2`` over the parameters in ``mask``, with optimistix
    (:class:`ColouredLevenbergMarquardt` in :func:`optimistix.least_squares`).

    ``equations(z, args) -> (r, normal, aux)`` linearises the residuals at ``z``
    (``normal``: ``J^T J`` and ``J^T r``, an :class:`~idtool._fit._arrow.Arrow`)
    (:func:`coloured_equations` builds it from a residual function and its sparsity);
    ``aux`` (any pytree it computes on the way) is returned for the final ``z``.

    Convergence: the Gauss-Newton decrement ``g^T (J^T J)^-1 g`` (twice the decrease a
    full Gauss-Newton step still promises) falls below ``tol`` times the residual
    variance ``|r|^2 / n``: the optimum is then within ``sqrt(tol)`` standard errors in
    every direction, whatever the parameters' scales and correlations. Stops early
    after ``max_steps`` iterations (a traced value: no recompilation) or if the damping
    explodes (no downhill step exists in floating point).

    No step moves a parameter by more than ``max_step`` on the internal scale. Every
    iteration linearises at the trial point, whether or not it is then accepted: the
    model appears once in the compiled loop (compile time is most of the time to a
    first fit), at the price of a wasted Jacobian per rejected step (about 1 in 10).
    """

    solution: optx.Solution = optx.least_squares(
        _solver_fn(equations),
        ColouredLevenbergMarquardt(max_step=max_step),
        jnp.asarray(z0, float),
        args,
        options={
            "mask": jnp.asarray(mask),
            "max_steps": jnp.asarray(max_steps),
            "tol": jnp.asarray(tol, float),  # traced: one program for every tolerance
        },
        has_aux=True,
        max_steps=None,  # the budget is the traced option above
        throw=False,
    )
    return _result(solution.state)


def levenberg_marquardt_loop(
    equations: Callable[[Array, Any], tuple[Array, Any, Any]],
    z0: Float[Array, " p"],
    args: Any,
    mask: Bool[Array, " p"],
    max_steps: int | Array = 100,
) -> LMResult:
    """:func:`levenberg_marquardt` (default tolerances) driven by a plain
    ``lax.while_loop`` instead of optimistix: the solver's own ``init``, ``step`` and
    ``terminate``, the reference that ``benchmarks/bench_fit.py`` and
    ``tests/test_lm.py`` compare the optimistix driver with (time per step and identical
    iterates)."""
    solver = ColouredLevenbergMarquardt()
    fn = _solver_fn(equations)
    z0 = jnp.asarray(z0, float)
    options = {"mask": jnp.asarray(mask), "max_steps": jnp.asarray(max_steps)}
    f_struct, aux_struct = jax.eval_shape(fn, z0, args)
    tags: frozenset = frozenset()

    def cond(s):
        return ~solver.terminate(fn, s["z"], args, options, s, tags)[0]

    def body(s):
        return solver.step(fn, s["z"], args, options, s, tags)[1]

    state = solver.init(fn, z0, args, options, f_struct, aux_struct, tags)
    return _result(jax.lax.while_loop(cond, body, state))
