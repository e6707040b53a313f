"""The log-posterior the sampler explores (issue 5): noise models, nuisances, priors.

What is sampled: the shared parameters of the fit (the physical ones and the actuator
model's, on the fit's internal scale) and the noise parameters. The 4 nuisances of every
trace (load-cell offset, pull start, horn lags) are *integrated out*, not held fixed:
holding them at the fit's values narrows the posterior of mu to 30% of its marginal
width on the example and the others to 55-65% (the fit's covariance shows it; see
:func:`conditioning_shrinkage`), because 96 modest correlations add up. Each trace's
nuisances enter only that trace's residuals, and the model is close to linear in them
over their posterior range, so they are integrated analytically: the whitened residuals
are linearised in the nuisances at the fit's values, ``w(theta, eta) = w(theta, eta*)
+ J_w (eta - eta*)`` (``J`` computed once at the fit), and under a wide Gaussian prior
(sd 100 internal units: +-100 N, +-5 s, +-1 s, +-1 N/s) the integral is Gaussian, one
4 x 4 (5 x 5) Cholesky per trace. For Student-t innovations the same Gaussian integral is
used as a Laplace approximation (nuisances profiled by least squares).

The noise model is the model's (:mod:`idtool._model._noise`); the sampler may swap it
(``idtool sample --noise``).
"""

from __future__ import annotations

import dataclasses
import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jax.scipy.linalg import solve_triangular
from jaxtyping import Array

from idtool._fit._cov import Covariance
from idtool._model._benchmodel import BenchModel
from idtool._model._noise import NOISE_MODELS
from idtool._model._params import Param
from idtool._posterior._prior import Prior

__all__ = [
    "Target",
    "build_target",
    "conditioning_shrinkage",
    "log_posterior",
    "log_posterior_batch",
    "physical_values",
    "sampled_params",
    "trace_logliks_batch",
]

NUISANCE_PRIOR_SD = 100.0  # internal units (trace groups' scales): effectively flat


def sampled_params(model: BenchModel) -> tuple[Param, ...]:
    """The sampled parameters: the model's shared ones, then its noise model's."""
    return (*model.shared_params, *model.noise.params)


class Target(eqx.Module):
    """What the log-posterior needs beyond the model: the per-trace nuisances at the
    point where they are linearised, their Jacobian and Gram matrices, the priors.
    Arrays are leaves (one compiled program serves every dataset of the same shape)."""

    model: BenchModel
    nuisances: dict[str, Array]  # per-trace values (traces,) at the linearisation
    jac_e: Array  # (blocks, groups) d prediction / d nuisance (internal units) there
    # (terms, traces, groups, groups): what the noise model precomputes of the whitened
    # Gram J_w^T J_w (AbstractNoise.gram_terms; AR(1): its 3 terms in 1, phi, phi^2)
    gram: Array
    continues: Array  # (blocks,) the next block belongs to the same trace
    priors: tuple[Prior, ...] = eqx.field(static=True)

    @property
    def params(self) -> tuple[Param, ...]:
        return sampled_params(self.model)

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(p.name for p in self.params)

    def log_posterior_batch(self, theta: Array) -> Array:
        """:func:`log_posterior_batch` of this target (the sampler calls either target
        the same way)."""
        return log_posterior_batch(theta, self)

    @property
    def force_n(self) -> Array:
        return jnp.asarray(self.model.data.force_n)

    @property
    def first(self) -> Array:
        return jnp.asarray(self.model.data.first)


def build_target(
    model: BenchModel, z_fit: np.ndarray, noise: str, priors: dict[str, Prior]
) -> Target:
    """The log-posterior's target for ``model`` (with the noise model ``noise``) around
    the internal vector ``z_fit``, where the nuisances are linearised."""
    model = dataclasses.replace(model, noise=NOISE_MODELS.get(noise)())
    d = model.data
    v = model.values(jnp.asarray(z_fit))
    first = np.asarray(d.first)
    continues = np.zeros(d.n_blocks, bool)
    continues[:-1] = ~first[1:]
    n, g = d.n_traces, len(model.trace_groups)
    target = Target(
        model=model,
        nuisances={group: jnp.asarray(v[group]) for group, _, _ in model.trace_groups},
        jac_e=jnp.zeros((d.n_blocks, g)),
        gram=jnp.zeros((0, n, g, g)),  # set below, from the Jacobian
        continues=jnp.asarray(continues),
        priors=tuple(priors[p.name] for p in sampled_params(model)),
    )
    shared = {p.name: v[p.name] for p in model.shared_params}
    jac_e = np.asarray(_nuisance_jacobian(shared, target))
    gram = model.noise.gram_terms(jac_e, first, np.asarray(d.block_trace), n)
    return eqx.tree_at(lambda t: (t.jac_e, t.gram), target, (jnp.asarray(jac_e), jnp.asarray(gram)))


@jax.jit
def _nuisance_jacobian(shared: dict, target: Target) -> Array:
    """d prediction / d nuisance (internal units), (blocks, groups): one forward-mode
    pass per group, every trace at once (a block depends on its own trace's nuisances
    only). Compiled once per data shape: the data are arguments, not constants."""
    primals = target.nuisances

    def pred(nuisances):
        return predict_blocks(shared, target, nuisances)

    cols = []
    for group, _, scale in target.model.trace_groups:
        tangents = {
            k: jnp.full_like(x, scale) if k == group else jnp.zeros_like(x)
            for k, x in primals.items()
        }
        cols.append(jax.jvp(pred, (primals,), (tangents,))[1])
    return jnp.stack(cols, axis=1)


def physical_values(theta: Array, target: Target) -> dict[str, Array]:
    """Physical values of one internal vector, by name."""
    return {p.name: p.value(theta[i]) for i, p in enumerate(target.params)}


def predict_blocks_batch(
    v: dict, target: Target, nuisances: dict[str, Array] | None = None
) -> Array:
    """Block-mean force [N] for a batch of parameter sets (``v`` maps names to arrays of
    shape (walkers,)), the nuisances at ``nuisances`` (default: the linearisation
    point): (walkers, blocks). FR is solved at the distinct operating points only."""
    model = target.model
    off, on, _ = jax.vmap(model.levels)(v)  # (walkers, traces)
    vals = dict(target.nuisances if nuisances is None else nuisances)
    bench = (*model.actuator.fit_params, *model.level.fit_params)
    vals |= {p.name: v[p.name] for p in bench if p.name in v}  # not fixed
    return model.block_means(off.T, on.T, vals).T


def predict_blocks(v: dict, target: Target, nuisances: dict[str, Array] | None = None) -> Array:
    """Block-mean force [N] for one parameter set (scalars in ``v``): (blocks,)."""
    batch = {k: jnp.asarray(x)[None] for k, x in v.items()}
    return predict_blocks_batch(batch, target, nuisances)[0]


def marginal_loglik_batch(e: Array, v: dict, target: Target) -> tuple[Array, Array]:
    """Log-likelihood of residuals ``e`` (walkers, blocks; model - data) with the
    nuisances integrated out (module docstring), (walkers,); and the nuisance shift at
    its conditional mode, (walkers, traces, groups). ``v`` maps names to (walkers,) arrays.
    The sum over traces of :func:`trace_logliks_batch`."""
    ll, shift = trace_logliks_batch(e, v, target)
    return jnp.sum(ll, axis=1), shift


def trace_logliks_batch(e: Array, v: dict, target: Target) -> tuple[Array, Array]:
    """Each trace's log-likelihood (walkers, traces), the nuisances integrated out, and
    the nuisance shift (walkers, traces, groups). Given the shared parameters the traces
    are independent (the nuisances and the noise's correlation are per trace), so these terms
    are the exact factorisation of the likelihood: what ``az.loo`` needs per trace.

    With ``w = L e`` the whitened residuals and ``J_w = L J``, the noise model gives
    ``h = J_w^T w`` and ``J_w^T J_w`` (:meth:`AbstractNoise.nuisance_equations`; AR(1):
    ``J^T (L^T w)`` and a Gram precomputed as a quadratic in phi, so a call costs two
    passes over the blocks, walkers the fastest axis), then one groups x groups
    Cholesky per trace.
    """
    t = target
    noise = t.model.noise
    n_traces = t.model.data.n_traces
    block_trace = jnp.asarray(t.model.data.block_trace)

    def per_trace(x: Array) -> Array:  # (blocks, walkers) -> (walkers, traces)
        return jax.ops.segment_sum(x, block_trace, n_traces).T

    sigma = v["sigma_n"]
    state = noise.state_of(v)  # (k, walkers)
    w = noise.whiten(e.T, t.first, state)  # (blocks, walkers)
    h, g = noise.nuisance_equations(w, t.jac_e, t.gram, t.first, t.continues, block_trace, state)

    def per_walker(x):  # (walkers,) -> broadcast against (walkers, traces, groups, groups)
        return x[:, None, None, None]

    # Precision of the nuisances (Fisher information for Student-t), prior included.
    scale = noise.nuisance_information(v) / sigma**2
    prior_prec = 1.0 / NUISANCE_PRIOR_SD**2
    a = g * per_walker(scale) + prior_prec * jnp.eye(g.shape[-1])
    chol = jnp.linalg.cholesky(a)
    y = solve_triangular(chol, (-h * scale[:, None, None])[..., None], lower=True)
    shift = solve_triangular(jnp.swapaxes(chol, -1, -2), y, lower=False)[..., 0]
    log_det = 2.0 * jnp.sum(jnp.log(jnp.diagonal(chol, axis1=-2, axis2=-1)), axis=-1)
    n = per_trace(jnp.ones_like(w))  # blocks per trace, (walkers, traces)
    p = shift.shape[2]
    if not noise.gaussian:  # Laplace: the innovations' own density at the shifted mode
        jw = noise.whiten(t.jac_e[:, :, None], t.first, state)  # (blocks, 4, walkers)
        moved = jnp.moveaxis(shift, 0, -1)[block_trace]  # (blocks, 4, walkers)
        w_fit = w + jnp.sum(jw * moved, axis=1)
        u = w_fit / sigma
        ll = per_trace(noise.innovation_logpdf(u, v)) - n * jnp.log(sigma)[:, None]
        ll = ll - 0.5 * prior_prec * jnp.sum(shift**2, axis=2)
    else:
        # min over the shift of |w + J_w s|^2 / sigma^2 + s^T s / sd^2, in closed form
        ll = -0.5 * n * jnp.log(2.0 * jnp.pi * sigma**2)[:, None]
        ll = ll - 0.5 * per_trace(w**2) / (sigma**2)[:, None]
        ll = ll + 0.5 * jnp.sum(y**2, axis=(2, 3))
    ll = ll - 0.5 * log_det - p * math.log(NUISANCE_PRIOR_SD)
    return ll + noise.trace_log_det(state)[:, None], shift


def marginal_loglik(e: Array, v: dict, target: Target) -> tuple[Array, Array]:
    """:func:`marginal_loglik_batch` for one parameter set: (log-likelihood, shift)."""
    ll, shift = marginal_loglik_batch(
        e[None], {k: jnp.asarray(x)[None] for k, x in v.items()}, target
    )
    return ll[0], shift[0]


def log_posterior_batch(theta: Array, target: Target) -> Array:
    """Log-posterior (up to a constant) of a batch of internal vectors (walkers, ndim);
    -inf outside the prior."""
    lp = jnp.zeros(theta.shape[0])
    v = {}
    for i, (p, prior) in enumerate(zip(target.params, target.priors, strict=True)):
        v[p.name] = p.value(theta[:, i])
        lp = lp + prior.logpdf(v[p.name]) + p.log_jacobian(theta[:, i])
    e = predict_blocks_batch(v, target) - target.force_n
    ll, _ = marginal_loglik_batch(e, v, target)
    out = jnp.where(jnp.isfinite(lp), lp + ll, -jnp.inf)
    return jnp.where(jnp.isnan(out), -jnp.inf, out)


def log_posterior(theta: Array, target: Target) -> Array:
    """Log-posterior (up to a constant) of one internal vector."""
    return log_posterior_batch(theta[None], target)[0]


def conditioning_shrinkage(cov_z: Covariance, n_shared: int) -> np.ndarray:
    """sd of each shared parameter with the nuisances held fixed, over its marginal sd
    (from the fit's covariance, in its blocks): how much fixing the nuisances would
    understate."""
    if n_shared != cov_z.n_shared:
        raise ValueError(f"{n_shared} shared parameters: the covariance has {cov_z.n_shared}")
    cond = cov_z.shared_given_nuisances()
    return np.sqrt(np.maximum(np.diag(cond), 0.0) / np.diag(cov_z.leading(n_shared)))
