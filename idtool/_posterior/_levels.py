"""The levels model's log-posterior: what the sampler explores when a fit carries
pull-to-pull scatter and model discrepancy (issue 10; :mod:`idtool._fit._variability`).

Sampled: the physical parameters (internal scale) and the sds of the levels model
(``scatter_mu``, ``scatter_fr`` when traces repeat an operating point,
``discrepancy_fr``). The likelihood is the levels model's marginal one,

    y ~ N(g(theta), V + Sigma(sds)),

``y`` the traces' own log levels and ``V`` their covariance from the load-cell noise,
nuisances and actuator slopes (stage 1 of the fit, kept in ``fit_state.npz``): the
random effects are integrated analytically, so the walkers see 5-7 dimensions whatever
the number of traces. Priors on the sds: half-normal with scale 0.1 (a 10% relative
sd; ``normal(0, 0.1)`` on a positive parameter), weakly informative: the bench's
scatter is a few percent, and the prior keeps a discrepancy that four operating points
cannot pin down from wandering to implausible sizes. They can be overridden like any
prior (``--priors``).
"""

from __future__ import annotations

import dataclasses

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jax.scipy.linalg import cho_solve
from jaxtyping import Array

from idtool._fit._free_levels import FreeLevels
from idtool._fit._level_cov import draw, factor, precision_blocks, solve
from idtool._fit._level_design import level_design
from idtool._fit._variability import SD_PARAMS
from idtool._model._benchmodel import BenchModel
from idtool._model._params import Param
from idtool._posterior._prior import Prior

__all__ = [
    "SD_PRIOR",
    "LevelsTarget",
    "build_levels_target",
    "levels_params",
    "replicate_in_blocks",
]

SD_PRIOR = Prior("normal", 0.0, 0.1)  # half-normal on the positive sds (module docstring)


def levels_params(model: BenchModel, free: FreeLevels) -> tuple[Param, ...]:
    """Sampled parameters: the physical ones, then the identifiable sds."""
    active = level_design(model, free.measured).active
    sds = tuple(p for p, on in zip(SD_PARAMS, active, strict=True) if on)
    return (*model.shared_params[: model.n_physical], *sds)


class LevelsTarget(eqx.Module):
    """Data of the levels likelihood; arrays are leaves (one program per shape)."""

    model: BenchModel
    y: Array  # log OFF of every trace, log FR of the measured ones
    # y's covariance V dense (n, n): only for a fit saved without the blocks (parts)
    cov_y: Array | None
    rows: Array  # rows of (log OFF, log FR) per trace that y holds
    kinds: Array  # (n, 2) one-hot: an OFF row, an FR row
    # (n, n) the discrepancy's correlation between the FR rows: as cov_y, dense path only
    disc_corr: Array | None
    priors: tuple[Prior, ...] = eqx.field(static=True)
    sd_names: tuple[str, ...] = eqx.field(static=True)
    # V + Sigma(sds) in per-trace blocks and a low rank (idtool._fit._level_cov: block,
    # low, disc, measured) and each row's place in the pairs (n,): the likelihood in time
    # linear in the traces (issue 28); None for a fit saved without them (dense)
    parts: tuple[Array, Array, Array, Array] | None = None
    pair_of_row: Array | None = None

    @property
    def params(self) -> tuple[Param, ...]:
        by_name = {p.name: p for p in SD_PARAMS}
        return (
            *self.model.shared_params[: self.model.n_physical],
            *(by_name[n] for n in self.sd_names),
        )

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(p.name for p in self.params)

    @property
    def noise_size(self) -> int:
        """Standard normals per replicated ``y``: one per row on the dense covariance; on
        its blocks two per trace and one per low-rank column
        (:func:`~idtool._fit._level_cov.draw`)."""
        if self.parts is None:
            return int(self.y.size)
        block, low, disc, _ = self.parts
        return 2 * block.shape[0] + low.shape[2] + disc.shape[2]

    def log_posterior_batch(self, theta: Array) -> Array:
        """Log-posterior (up to a constant) of internal vectors (walkers, ndim)."""
        params = self.params
        lp = jnp.zeros(theta.shape[0])
        v = {}
        for i, (p, prior) in enumerate(zip(params, self.priors, strict=True)):
            v[p.name] = p.value(theta[:, i])
            lp = lp + prior.logpdf(v[p.name]) + p.log_jacobian(theta[:, i])
        if self.parts is None:
            g, chol = _mean_and_cholesky(v, self)
            r = self.y[None] - g
            quad = jax.vmap(_quadratic)(chol, r)
            logdet = 2.0 * jnp.sum(jnp.log(jnp.diagonal(chol, axis1=1, axis2=2)), axis=1)
        else:
            quad, logdet = _quad_and_logdet_blocks(v, self)
        out = lp - 0.5 * (quad + logdet)
        out = jnp.where(jnp.isfinite(lp), out, -jnp.inf)
        return jnp.where(jnp.isnan(out), -jnp.inf, out)


def _mean_and_cholesky(v: dict, target: LevelsTarget) -> tuple[Array, Array]:
    """Per walker (``v`` maps names to (walkers,) arrays): the model's log levels at the
    rows of ``y`` and the Cholesky factor of ``V + Sigma(sds)``."""
    off, _, fr = jax.vmap(target.model.levels)(v)  # (walkers, traces)
    g = jnp.concatenate([jnp.log(off), jnp.log(fr)], axis=1)[:, target.rows]
    zero = jnp.zeros(g.shape[0])
    tau2 = [v.get(p.name, zero) ** 2 for p in SD_PARAMS]
    diag = target.kinds[:, 0] * tau2[0][:, None] + target.kinds[:, 1] * tau2[1][:, None]
    assert target.cov_y is not None and target.disc_corr is not None  # the dense path
    c = target.cov_y + jax.vmap(jnp.diag)(diag) + tau2[2][:, None, None] * target.disc_corr[None]
    return g, jnp.linalg.cholesky(c)


def _log_levels(v: dict, target: LevelsTarget) -> Array:
    """Per walker the model's log levels at the rows of ``y`` (walkers, n)."""
    off, _, fr = jax.vmap(target.model.levels)(v)  # (walkers, traces)
    return jnp.concatenate([jnp.log(off), jnp.log(fr)], axis=1)[:, target.rows]


def _residual_pairs(v: dict, target: LevelsTarget) -> tuple[Array, Array, Array]:
    """Per walker the model's log levels ``g`` (walkers, n), the residual ``y - g`` in
    pairs (walkers, m, 2; 0 in unmeasured FR entries) and the variances (walkers, 3)."""
    assert target.parts is not None and target.pair_of_row is not None
    g = _log_levels(v, target)
    r = target.y[None] - g
    m = target.parts[0].shape[0]
    r2 = jnp.zeros((r.shape[0], 2 * m)).at[:, target.pair_of_row].set(r).reshape(-1, m, 2)
    zero = jnp.zeros(r.shape[0])
    tau2 = jnp.stack([v.get(p.name, zero) ** 2 for p in SD_PARAMS], axis=1)
    return g, r2, tau2


def _quad_and_logdet_blocks(v: dict, target: LevelsTarget) -> tuple[Array, Array]:
    """Per walker ``r^T C^-1 r`` and ``log det C`` with ``C = V + Sigma(sds)`` in blocks
    (:mod:`idtool._fit._level_cov`): O(traces) per walker where the dense Cholesky
    factorisation was O(traces^3)."""
    parts = target.parts
    assert parts is not None
    _, r2, tau2 = _residual_pairs(v, target)

    def one(t, rp):
        f = factor(t, *parts)
        return jnp.sum(rp * solve(f, rp[:, :, None])[:, :, 0]), f[4]

    return jax.vmap(one)(tau2, r2)


def replicate_in_blocks(v: dict, target: LevelsTarget, eps: Array):
    """Per walker, with ``C = V + Sigma(sds)`` in blocks (O(traces) each, no (n, n)
    matrix): the model's log levels ``g`` (walkers, n), replicated data ``y_rep = g +
    C^(1/2) eps`` (walkers, n; ``eps`` (walkers, :attr:`LevelsTarget.noise_size`),
    :func:`~idtool._fit._level_cov.draw`: the same Gaussian as the dense ``chol(C)
    eps``), ``a = C^-1 (y - g)`` in pairs (walkers, m, 2), the diagonal blocks of
    ``C^-1`` (walkers, m, 2, 2) and the discrepancies ``(y - g)^T C^-1 (y - g)`` and
    ``(y_rep - g)^T C^-1 (y_rep - g)`` (walkers,)."""
    parts, pair_of_row = target.parts, target.pair_of_row
    assert parts is not None and pair_of_row is not None
    g, r2, tau2 = _residual_pairs(v, target)
    kept = jnp.stack([jnp.ones_like(parts[3]), parts[3]], axis=1)  # (m, 2): rows of y

    def one(t, rp, e):
        f = factor(t, *parts)
        noise = draw(t, *parts, e) * kept
        a = solve(f, rp[:, :, None])[:, :, 0]
        a_rep = solve(f, noise[:, :, None])[:, :, 0]
        return noise, a, precision_blocks(f), jnp.sum(rp * a), jnp.sum(noise * a_rep)

    noise, a, prec, d_obs, d_rep = jax.vmap(one)(tau2, r2, eps)
    y_rep = g + noise.reshape(noise.shape[0], -1)[:, pair_of_row]
    return g, y_rep, a, prec, d_obs, d_rep


def _quadratic(chol: Array, x: Array) -> Array:
    """``x^T C^-1 x`` from the Cholesky factor of ``C``."""
    return x @ cho_solve((chol, True), x)


def build_levels_target(
    model: BenchModel, free: FreeLevels, priors: dict[str, Prior]
) -> LevelsTarget:
    """The levels log-posterior of ``model`` from its free levels ``free``."""
    design = level_design(model, free.measured)
    names = tuple(p.name for p in levels_params(model, free))
    parts: tuple[Array, Array, Array, Array] | None = None
    pair_of_row = cov_y = disc_corr = None
    if free.cov_parts is None:  # a fit saved before the blocks: dense (n, n)
        cov_y, disc_corr = jnp.asarray(free.covariance()), jnp.asarray(design.disc_corr())
    else:
        m, idx = free.off_n.size, np.flatnonzero(free.measured)
        block, low, disc, meas = dataclasses.replace(free.cov_parts, disc=design.disc_root).arrays
        parts = (jnp.asarray(block), jnp.asarray(low), jnp.asarray(disc), jnp.asarray(meas))
        pair_of_row = jnp.asarray(np.concatenate([2 * np.arange(m), 2 * idx + 1]))
    return LevelsTarget(
        model=model,
        y=jnp.asarray(free.y),
        cov_y=cov_y,
        rows=jnp.asarray(design.rows),
        kinds=jnp.asarray(design.kinds),
        disc_corr=disc_corr,
        priors=tuple(priors[n] for n in names),
        sd_names=tuple(n for n in names if n in {p.name for p in SD_PARAMS}),
        parts=parts,
        pair_of_row=pair_of_row,
    )


def levels_start(fit_theta: np.ndarray, cov_theta: np.ndarray, sds: dict, target: LevelsTarget):
    """Centre and spread of the walkers: the fit's levels-model estimate and covariance;
    each sd at its REML estimate (at least 0.002: a walker at zero sits at the
    internal scale's edge) with a spread of 0.5 in log."""
    params = target.params
    k = fit_theta.size
    theta = np.concatenate(
        [
            fit_theta,
            [params[k + j].internal(max(sds[n][0], 2e-3)) for j, n in enumerate(target.sd_names)],
        ]
    )
    cov = np.zeros((theta.size, theta.size))
    cov[:k, :k] = cov_theta
    for j in range(len(target.sd_names)):
        p = params[k + j]
        # d z / d log(sd) = 1 / (slope * 1/sd): a 0.5 spread in log sd on the internal scale
        sd_val = float(p.value(jnp.asarray(theta[k + j])))
        cov[k + j, k + j] = (0.5 * sd_val / p.slope(theta[k + j])) ** 2
    return theta, cov


@jax.jit
def _replicate(theta, target: LevelsTarget, eps):
    """Model log levels and replicated data ``y_rep`` for draws ``theta`` (draws, ndim)
    with standard normals ``eps`` (draws, :attr:`LevelsTarget.noise_size`): y_rep = g +
    (V + Sigma)^(1/2) eps, on the covariance's blocks (:func:`replicate_in_blocks`), or
    its dense Cholesky factor for a fit saved without them."""
    v = {p.name: p.value(theta[:, i]) for i, p in enumerate(target.params)}
    if target.parts is not None:
        g, y_rep, _, _, d_obs, d_rep = replicate_in_blocks(v, target, eps)
        return g, y_rep, d_obs, d_rep
    g, chol = _mean_and_cholesky(v, target)
    y_rep = g + jnp.einsum("wij,wj->wi", chol, eps)
    d_obs = jax.vmap(_quadratic)(chol, target.y[None] - g)
    return g, y_rep, d_obs, jax.vmap(_quadratic)(chol, y_rep - g)


class LevelsCheck(eqx.Module):
    """Posterior predictive check of the levels model: each trace's own log level
    against its replicated 95% band, and the chi-square discrepancy's p-value
    (Gelman, Meng & Stern 1996): near 0 when the model misses the levels."""

    y: np.ndarray
    band: tuple[np.ndarray, np.ndarray]
    inside_fraction: float
    p_value: float

    def to_dict(self) -> dict:
        return {
            "quantity": "traces' own log OFF and log FR levels",
            "inside_fraction": self.inside_fraction,
            "chi2_p_value": self.p_value,
        }


def levels_predictive(
    chain: np.ndarray, burn: int, target: LevelsTarget, n_draws: int = 400, seed: int = 0
) -> LevelsCheck:
    """:class:`LevelsCheck` from ``n_draws`` kept draws of ``chain`` (steps, walkers, ndim)."""
    kept = chain[burn:].reshape(-1, chain.shape[-1])
    idx = np.unique(np.linspace(0, kept.shape[0] - 1, min(n_draws, kept.shape[0])).astype(int))
    eps = np.random.default_rng(seed).standard_normal((idx.size, target.noise_size))
    _, y_rep, d_obs, d_rep = (
        np.asarray(x) for x in _replicate(jnp.asarray(kept[idx]), target, jnp.asarray(eps))
    )
    lo, hi = np.percentile(y_rep, [2.5, 97.5], axis=0)
    y = np.asarray(target.y)
    return LevelsCheck(
        y=y,
        band=(lo, hi),
        inside_fraction=float(np.mean((y >= lo) & (y <= hi))),
        p_value=float(np.mean(d_rep >= d_obs)),
    )
