"""The one compiled Levenberg-Marquardt program every step of a fit runs: each start,
polish, noise-state round, interval check and profile point, of every dataset of about the
same length and the same laws (its blocks padded to a bucketed count), and the figures'
prediction at the optimum (the program run for no step); and the bench model's normal
equations it solves (:func:`bench_normal_equations`): how the fit linearises the model,
a concern of the solver's, not of the model (:mod:`idtool._model._benchmodel`).
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from idtool._data._blocks import padded_size
from idtool._fit._arrow import Arrow, DenseNormal
from idtool._fit._compiled import program
from idtool._fit._lm import (
    ColouredJacobian,
    LMResult,
    arrow_of_blocks,
    coloured_blocks,
    levenberg_marquardt,
)
from idtool._model._benchmodel import BenchModel

__all__ = [
    "LM_TOL",
    "bench_normal_equations",
    "level_structure",
    "lm_arguments",
    "lm_program",
    "prediction_at",
    "run_lm",
    "u_normal_equations",
    "unwhiten",
]

# XLA's newer CPU fusion emitters compile the fit's programs ~30% slower for the same
# run time (2.6 s vs 1.9 s for the LM loop on the example; benchmarks/bench_fit.py);
# LLVM's optimisation level 1 instead of 2 compiles it in 1.19 s instead of 1.35 s and
# runs 20 steps in 83 ms as before (level 0: 0.58 s, but 235 ms).
_COMPILE = {"xla_cpu_use_fusion_emitters": False, "xla_backend_optimization_level": 1}
# Levenberg-Marquardt's convergence threshold on the Gauss-Newton decrement, in residual
# variances: the optimum within sqrt(1e-8) = 1e-4 standard errors in every direction.
LM_TOL = 1e-8


def level_structure(model: BenchModel, dense: bool = False) -> ColouredJacobian:
    """The sparsity of the Jacobian of ``model``'s residuals in the inputs ``u = (OFF, ON
    levels, z[k:])`` (:attr:`BenchModel.level_group`), coloured: outside a trace only
    (NumPy on the model's block layout). ``dense``: the fit's normal equations as dense
    matrices (the reference the tests check the arrowhead against)."""
    return ColouredJacobian.from_groups(model.level_group, model.data.block_trace, dense)


def bench_normal_equations(
    model: BenchModel, structure: ColouredJacobian, z: Float[Array, " p"], state: Array | float
) -> tuple[Array, Arrow | DenseNormal, tuple[Array, Array, Array, Array]]:
    """Whitened residuals ``r`` (the noise model's whitening at its correlation ``state``,
    :meth:`~idtool._model._noise.AbstractNoise.whiten`) and the normal equations ``J^T J``,
    ``J^T r`` of ``model`` at ``z`` in arrowhead blocks (:class:`~idtool._fit._arrow.Arrow`:
    the shared parameters, then each trace's nuisances); and the levels ``(OFF, ON)`` [N] (2
    n_traces) with their Jacobian in the physical parameters, and each trace's blocks of the
    normal equations in ``u`` (below; :func:`u_normal_equations`), which the levels model
    reads.

    The physical parameters reach the traces only through the per-trace OFF and ON
    levels, so the Jacobian is taken in the bench model's inputs ``u = (OFF, ON,
    z[k:])`` with one JVP per colour of ``structure`` (:func:`level_structure`; 8, 9
    with the lag actuator; the contact model stays out of them) and mapped back by the
    chain rule, ``J = J_u T`` with ``T = du/dz``: the levels' small Jacobian in the
    physical parameters, the identity for the rest. Trace by trace: its colours (the
    shared bench parameters, its OFF and ON levels, its nuisances) map to (the physical
    parameters, the shared bench ones, its nuisances) by a (colours, s + nb) block of
    ``T``, so time and memory stay linear in the traces.
    """
    k, m = model.n_physical, model.data.n_traces
    z = jnp.asarray(z)

    def levels(zp):
        off, on, _ = model.levels(model.values(z.at[:k].set(zp)))
        return jnp.concatenate([off, on])

    def resid(u):
        return model.level_residuals(u, z, state)

    # (2 m, k) and (2 m,): the Jacobian and, from the same pass, the levels
    dlv, lv = jax.jacfwd(lambda zp: (levels(zp),) * 2, has_aux=True)(z[:k])
    u = jnp.concatenate([lv, z[k:]])
    r, cc, cr = coloured_blocks(resid, u, structure)  # (m, c, c), (m, c)
    sb = structure.n_shared  # shared bench parameters: the first colours
    nb = cc.shape[1] - sb - 2  # each trace's nuisances: the colours after its levels
    # per trace, T's block: colours (bench, OFF, ON, nuisances) -> (physical, bench,
    # nuisances)
    t = jnp.zeros((m, sb + 2 + nb, k + sb + nb))
    t = t.at[:, :sb, k : k + sb].set(jnp.eye(sb))
    t = t.at[:, sb, :k].set(dlv[:m]).at[:, sb + 1, :k].set(dlv[m:])
    t = t.at[:, sb + 2 :, k + sb :].set(jnp.eye(nb))
    h = jnp.einsum("mcq,mcd,mdr->mqr", t, cc, t)
    gh = jnp.einsum("mcq,mc->mq", t, cr)
    arrow = arrow_of_blocks(h, gh, k + sb)
    normal = arrow.as_dense() if structure.dense else arrow
    return r, normal, (lv, dlv, cc, cr)


def u_normal_equations(
    model: BenchModel, cc: np.ndarray, cr: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """The dense normal equations in ``u = (OFF, ON, z[k:])`` (NumPy) from each trace's
    blocks that :func:`bench_normal_equations` returns (its colours: the shared bench
    parameters, the trace's OFF and ON levels, its nuisances): for the levels model,
    which solves in ``u`` once."""
    m = model.data.n_traces
    cc, cr = np.asarray(cc), np.asarray(cr)
    group = model.level_group
    sb = int(np.sum(group < 0))
    # the position in u of each trace's colours (m, c): shared, then its own in order
    shared = np.flatnonzero(group < 0)
    own = np.stack([np.flatnonzero(group == i) for i in range(m)])
    idx = np.concatenate([np.broadcast_to(shared, (m, sb)), own], axis=1)
    q = group.size
    jtj, jtr = np.zeros((q, q)), np.zeros(q)
    np.add.at(jtj, (idx[:, :, None], idx[:, None, :]), cc)
    np.add.at(jtr, idx, cr)
    return jtj, jtr


@program(compiler_options=_COMPILE)
def lm_program(
    model: BenchModel, structure: ColouredJacobian, z0, mask, state, max_steps, tol
) -> LMResult:
    """The compiled program of :func:`run_lm` (its model already padded, ``structure``
    its :func:`level_structure`)."""
    equations = jax.tree_util.Partial(bench_normal_equations, model, structure)
    return levenberg_marquardt(equations, z0, state, mask, max_steps, tol)


def run_lm(model: BenchModel, z0, mask, state, max_steps, tol: float = LM_TOL) -> LMResult:
    """Levenberg-Marquardt on the residuals of ``model`` whitened at the noise model's
    correlation ``state`` (an array of the model's length, so that every state value
    runs the same program; for AR(1) ``[phi]``, a bare number is taken as phi)
    (:func:`bench_normal_equations`) over the parameters in ``mask``, returning
    them with the per-trace levels; ``tol``: the convergence threshold on the
    Gauss-Newton decrement, in residual variances (:func:`levenberg_marquardt`). The
    model is an argument, not a constant, and its blocks are padded to
    :func:`~idtool._data._blocks.padded_size` (residuals 0 there, cut off again here):
    one compiled program serves every start, polish, noise-state round, profile point,
    tolerance and every dataset of about the same length and the same laws."""
    n = model.data.force_n.shape[0]
    padded = _padded(model)
    out = lm_program(padded, level_structure(padded), z0, mask, state, max_steps, float(tol))
    # cut in NumPy: a JAX slice would be one more program to compile for every n
    return eqx.tree_at(lambda o: o.residuals, out, np.asarray(out.residuals)[:n])


def lm_arguments(model: BenchModel) -> tuple:
    """Arguments of :func:`lm_program` of the types :func:`run_lm`'s calls for ``model``
    give it, its blocks padded (for compiling ahead:
    :class:`~idtool._fit._prefetch.CompileAhead`)."""
    z = np.asarray(model.z0(), float)
    padded = _padded(model)
    state = model.noise.initial_state()
    return (padded, level_structure(padded), z, np.ones(z.size, bool), state, 0, LM_TOL)


def _padded(model: BenchModel) -> BenchModel:
    """``model`` on its blocks padded to :func:`~idtool._data._blocks.padded_size`."""
    return model.padded(padded_size(model.data.force_n.shape[0]))


def prediction_at(model: BenchModel, z: np.ndarray, state) -> tuple[np.ndarray, np.ndarray]:
    """The model's block means [N] at ``z`` and their residuals whitened at the noise
    ``state`` (:func:`run_lm`), from the
    fit's own compiled program run for no step (no program of their own to trace,
    compile or load: 0.4 s of a repeated fit's figures)."""
    out = run_lm(model, np.asarray(z, float), np.ones(np.size(z), bool), state, 0)
    w = np.asarray(out.residuals)
    return np.asarray(model.data.force_n) + unwhiten(w, state, model), w


def unwhiten(w: np.ndarray, state, model: BenchModel) -> np.ndarray:
    """Residuals ``e`` [N] from whitened ones (the inverse of
    :meth:`~idtool._model._benchmodel.BenchModel.residuals`' whitening by ``model``'s
    noise model at ``state``)."""
    return model.noise.unwhiten(w, np.asarray(model.data.first), state)
