"""What ``posterior.nc`` holds beyond the draws, so that ArviZ's model checks run on it
(issue 13, item 5): ``log_likelihood``, ``observed_data``, ``constant_data`` and
``posterior_predictive``.

The unit of observation is the trace (a pull): ``az.loo`` leaves one trace out.

* Levels model (the default): the data are the traces' own log levels ``y`` (log OFF of
  every trace, log FR of those whose ON level is measured) with ``y ~ N(g(theta), C)``,
  ``C = V + Sigma(sds)`` not diagonal (the discrepancy correlates the operating points).
  The pointwise term of trace ``T`` is then its leave-one-out predictive density
  ``log p(y_T | y_-T, theta)`` (Bürkner, Gabry & Vehtari 2021, *Efficient leave-one-out
  cross-validation for Bayesian non-factorized normal and Student-t models*, eq. 8-9):
  with ``P = C^-1`` and ``a = P (y - g)``, ``y_T | y_-T ~ N(y_T - P_TT^-1 a_T,
  P_TT^-1)``, so ``log p = -k/2 log 2 pi + 1/2 log det P_TT - 1/2 a_T^T P_TT^-1 a_T``.
  ``az.loo`` given these terms computes exactly the importance-sampled LOO of that
  paper. ``posterior_predictive``: replicated ``y`` at each draw, ``g + C^(1/2) eps``
  (on ``C``'s per-trace blocks and low rank where the fit saved them, as ``P_TT`` and
  ``a``: :func:`~idtool._posterior._levels.replicate_in_blocks`; else the dense
  factor).
* Noise-only models: given the shared parameters the traces are independent (nuisances
  and AR(1) noise are per trace), so each trace's marginal log-likelihood is the exact
  factorisation (:func:`~idtool._posterior._likelihood.trace_logliks_batch`).
  ``observed_data`` are the block means [N]; ``posterior_predictive`` replicated block
  means at a few draws per walker (all blocks of all draws would be hundreds of MB).

Every group is computed at the thinned steps :func:`thinned_steps` picks (at most
:data:`MAX_DRAWS` draws in all): the log-likelihood costs a model evaluation per draw,
as much as a sampler step. Thinning by fewer steps than the autocorrelation time keeps
the effective sample size (README, "posterior.nc").
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np
from jax.scipy.linalg import cho_solve

from idtool._posterior._levels import (
    LevelsTarget,
    _mean_and_cholesky,
    build_levels_target,
    replicate_in_blocks,
)
from idtool._posterior._likelihood import (
    Target,
    build_target,
    predict_blocks_batch,
    trace_logliks_batch,
)
from idtool._posterior._ppc import replicate_blocks
from idtool._posterior._record import LEVELS, MAX_DRAWS, PosteriorRecord, thinned_steps

__all__ = ["MAX_DRAWS", "levels_groups", "model_check_groups", "noise_groups", "thinned_steps"]

PREDICTIVE_DRAWS = 200  # noise-only posterior predictive: block means of 200 draws
_CHUNK = 1000  # draws per compiled call (memory: draws x levels^2 on the dense path)


def _chunked(fn, *arrays: np.ndarray) -> tuple[np.ndarray, ...]:
    """``fn`` over chunks of draws (the leading axis of every array in ``arrays``), its
    outputs concatenated; the last chunk padded so one compiled program serves all."""
    n = arrays[0].shape[0]
    size = min(_CHUNK, n)
    pad = (-n) % size
    padded = [np.concatenate([a, np.repeat(a[-1:], pad, axis=0)]) if pad else a for a in arrays]
    outs = [fn(*(jnp.asarray(a[i : i + size]) for a in padded)) for i in range(0, n + pad, size)]
    return tuple(np.concatenate([np.asarray(o[j]) for o in outs])[:n] for j in range(len(outs[0])))


@jax.jit
def _levels_terms(theta, target: LevelsTarget, eps, idx, mask):
    """Per draw: each trace's leave-one-out log density (module docstring) and a
    replicated ``y``; ``idx``, ``mask``: :func:`trace_rows`."""
    v = {p.name: p.value(theta[:, i]) for i, p in enumerate(target.params)}
    if target.parts is not None:  # C in blocks: its inverse's diagonal blocks, O(traces)
        _, y_rep, a_pairs, p_tt, _, _ = replicate_in_blocks(v, target, eps)
        a_t = jnp.where(mask, a_pairs, 0.0)
    else:  # a fit saved without the blocks: the dense (n, n) inverse per draw
        g, chol = _mean_and_cholesky(v, target)
        n = target.y.size
        prec = jax.vmap(lambda c: cho_solve((c, True), jnp.eye(n)))(chol)
        a = jnp.einsum("wij,wj->wi", prec, target.y[None] - g)
        p_tt = prec[:, idx[:, :, None], idx[:, None, :]]  # (draws, traces, 2, 2)
        a_t = jnp.where(mask, a[:, idx], 0.0)
        y_rep = g + jnp.einsum("wij,wj->wi", chol, eps)
    both = mask[:, :, None] & mask[:, None, :]
    p_tt = jnp.where(both, p_tt, jnp.eye(2))  # a missing FR row: an inert unit block
    chol_t = jnp.linalg.cholesky(p_tt)
    logdet = 2.0 * jnp.sum(jnp.log(jnp.diagonal(chol_t, axis1=-2, axis2=-1)), axis=-1)
    quad = jnp.einsum("wti,wti->wt", a_t, jnp.linalg.solve(p_tt, a_t[..., None])[..., 0])
    k = jnp.sum(mask, axis=1)
    ll = -0.5 * k * jnp.log(2.0 * jnp.pi) + 0.5 * logdet - 0.5 * quad
    return ll, y_rep


@jax.jit
def _noise_terms(theta, target: Target):
    """Per draw: each trace's marginal log-likelihood and nuisance shift. The target is
    an argument, not a closed-over constant (XLA would fold its arrays for seconds)."""
    v = {p.name: p.value(theta[:, i]) for i, p in enumerate(target.params)}
    e = predict_blocks_batch(v, target) - target.force_n[None]
    return trace_logliks_batch(e, v, target)


def trace_rows(target: LevelsTarget) -> tuple[jax.Array, jax.Array]:
    """Per trace, the rows of ``y`` it owns: (traces, 2) indices (log OFF, log FR) and
    a mask (False where the trace's FR is not measured)."""
    m = target.model.data.n_traces
    rows = np.asarray(target.rows)
    fr_rows = np.full(m, -1)
    fr_rows[rows[m:] - m] = np.arange(m, rows.size)
    idx = np.stack([np.arange(m), np.maximum(fr_rows, 0)], axis=1)
    mask = np.stack([np.ones(m, bool), fr_rows >= 0], axis=1)
    return jnp.asarray(idx), jnp.asarray(mask)


def _walker_major(x: np.ndarray, steps: int, walkers: int) -> np.ndarray:
    """(steps * walkers, ...) in step-major order -> (walkers, steps, ...)."""
    return np.swapaxes(x.reshape(steps, walkers, *x.shape[1:]), 0, 1)


def _constant_data(model) -> dict:
    d = model.data
    return {
        "normal_load_n": (("trace",), np.asarray(d.normal_load_n, float)),
        "amplitude_fraction": (("trace",), np.asarray(d.amplitude_fraction, float)),
        "pull_speed_m_s": (("trace",), np.asarray(d.pull_speed_m_s, float)),
    }


def levels_groups(theta: np.ndarray, target: LevelsTarget, seed: int) -> dict:
    """The groups of a levels-model posterior from its thinned draws ``theta`` (steps,
    walkers, ndim; internal scale): ``{group: {name: (dims, array)}}`` (module
    docstring)."""
    steps, walkers, ndim = theta.shape
    flat = theta.reshape(-1, ndim)
    eps = np.random.default_rng([seed, 7]).standard_normal((flat.shape[0], target.noise_size))
    idx, mask = trace_rows(target)
    ll, y_rep = _chunked(lambda t, e: _levels_terms(t, target, e, idx, mask), flat, eps)
    m = target.model.data.n_traces
    level = [f"{tid} OFF" for tid in target.model.data.trace_ids]
    level += [f"{target.model.data.trace_ids[r - m]} FR" for r in np.asarray(target.rows)[m:]]
    return {
        "log_likelihood": {"per_trace": (("trace",), _walker_major(ll, steps, walkers))},
        "posterior_predictive": {"log_level": (("level",), _walker_major(y_rep, steps, walkers))},
        "observed_data": {"log_level": (("level",), np.asarray(target.y))},
        "constant_data": _constant_data(target.model),
        "coords": {"trace": list(target.model.data.trace_ids), "level": level},
        "attrs": {
            "log_likelihood": "per trace: log p(y_T | y_-T, theta), the trace's own log "
            "levels given every other trace's (Bürkner, Gabry & Vehtari 2021)",
            "log_level": "log OFF level [log N] of every trace, then log friction ratio "
            "[log 1] of the traces whose ON level is measured",
        },
    }


def noise_groups(theta: np.ndarray, target: Target, seed: int) -> dict:
    """The groups of a noise-only posterior from its thinned draws ``theta`` (steps,
    walkers, ndim): per-trace log-likelihoods at every draw, replicated block means at
    about :data:`PREDICTIVE_DRAWS` of them."""
    steps, walkers, ndim = theta.shape
    flat = theta.reshape(-1, ndim)

    ll, _ = _chunked(lambda t: _noise_terms(t, target), flat)
    every = max(1, math.ceil(steps * walkers / PREDICTIVE_DRAWS))
    pick = np.arange(steps - 1, -1, -every)[::-1]
    replicated, _ = replicate_blocks(theta[pick].reshape(-1, ndim), target, seed)
    d = target.model.data
    return {
        "log_likelihood": {"per_trace": (("trace",), _walker_major(ll, steps, walkers))},
        "posterior_predictive": {
            "force_n": (("block",), _walker_major(replicated, pick.size, walkers))
        },
        "observed_data": {"force_n": (("block",), np.asarray(d.force_n))},
        "constant_data": _constant_data(target.model)
        | {
            "block_time_s": (("block",), np.asarray(d.block_time_s)),
            "block_trace": (("block",), np.asarray(d.block_trace)),
        },
        "coords": {"trace": list(d.trace_ids), "block": np.arange(d.n_blocks)},
        "predictive_steps": pick,
        "attrs": {
            "log_likelihood": "per trace: its marginal log-likelihood (nuisances "
            "integrated out), the exact factorisation given the shared parameters",
            "force_n": "block-mean force [N]",
        },
    }


def model_check_groups(
    post: PosteriorRecord, target: Target | LevelsTarget | None = None
) -> tuple[dict, np.ndarray]:
    """The model-check groups of ``post`` (which must carry its model) and the kept
    steps they were computed at; ``target``: its log-posterior's, if already built."""
    assert post.model is not None
    burn = post.diagnostics.burn
    steps = thinned_steps(post.chain.shape[0] - burn, post.chain.shape[1])
    thinned = post.chain[burn:][steps]
    if post.noise == LEVELS:
        assert post.free_levels is not None
        if not isinstance(target, LevelsTarget):
            target = build_levels_target(post.model, post.free_levels, post.priors)
        return levels_groups(thinned, target, post.seed), steps
    if not isinstance(target, Target):
        target = build_target(post.model, post.z_lin, post.noise, post.priors)
    return noise_groups(thinned, target, post.seed), steps
