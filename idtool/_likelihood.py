"""The log-posterior the sampler explores (issue 5): noise models, nuisances, priors.

What is sampled: the shared parameters of the fit (the physical ones and the actuator
slopes, on the fit's internal scale) and the noise parameters. The 4 nuisances of every
trace (load-cell offset, pull start, horn lags) are *integrated out*, not held fixed:
holding them at the fit's values narrows the posterior of mu to 30% of its marginal
width on the example and the others to 55-65% (the fit's covariance shows it; see
:func:`conditioning_shrinkage`), because 96 modest correlations add up. Each trace's
nuisances enter only that trace's residuals, and the model is close to linear in them
over their posterior range, so they are integrated analytically: the whitened residuals
are linearised in the nuisances at the fit's values, ``w(theta, eta) = w(theta, eta*)
+ J_w (eta - eta*)`` (``J`` computed once at the fit), and under a wide Gaussian prior
(sd 100 internal units: +-100 N, +-5 s, +-1 s) the integral is Gaussian, one 4 x 4
Cholesky per trace. For Student-t innovations the same Gaussian integral is used as a
Laplace approximation (nuisances profiled by least squares).

Noise models (``NOISE_MODELS``) of the block-mean residuals:

* ``ar1`` (default): Gaussian AR(1), ``e_t = phi e_{t-1} + sigma eps_t`` within each
  trace, exact likelihood (stationary first block), phi and sigma sampled. The load cell
  at 1 kHz has correlated noise; block means over 40 ms keep a lag-1 correlation of
  about 0.5, and an independent-noise likelihood then counts every block as new
  information and gives intervals about sqrt((1 + phi) / (1 - phi)) ~ 1.8x too narrow
  (tests/test_sample.py measures the under-coverage);
* ``gaussian``: independent Gaussian noise, sigma sampled;
* ``student-t``: independent Student-t noise, sigma and nu sampled;
* ``ar1-student-t``: AR(1) with Student-t innovations (the first block of each trace
  uses the Gaussian stationary scaling, an approximation).
"""

from __future__ import annotations

import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jax.scipy.linalg import solve_triangular
from jaxtyping import Array

from ._bench import TraceTiming, mean_force_n, on_friction_ratio
from ._coupling import ConstantCoupling, PowerLimitedCoupling
from ._fitmodel import CORNER_N, TRACE_GROUPS, FitModel
from ._laws import Dahl, LuGre
from ._prior import NU, PHI, SIGMA, Prior, SampledParam

__all__ = [
    "DEFAULT_NOISE",
    "NOISE_MODELS",
    "Target",
    "build_target",
    "conditioning_shrinkage",
    "log_posterior",
    "log_posterior_batch",
    "noise_params",
    "physical_values",
]

NOISE_MODELS = ("ar1", "gaussian", "student-t", "ar1-student-t")
DEFAULT_NOISE = "ar1"
NUISANCE_PRIOR_SD = 100.0  # internal units (TRACE_GROUPS scales): effectively flat


def noise_params(noise: str) -> tuple[SampledParam, ...]:
    """The noise parameters a noise model samples, in order."""
    return {
        "ar1": (SIGMA, PHI),
        "gaussian": (SIGMA,),
        "student-t": (SIGMA, NU),
        "ar1-student-t": (SIGMA, PHI, NU),
    }[noise]


def _law_at(law: str, v: dict, load_n):
    fc = v["mu"] * load_n
    if law == "lugre":
        return LuGre(
            fc_n=fc, kt_n_m=v["Kt"], fs_n=v["static_ratio"] * fc, vs_m_s=v["stribeck_velocity_m_s"]
        )
    return Dahl(fc_n=fc, kt_n_m=v["Kt"])


def _coupling_of(coupling: str, v: dict):
    if coupling == "power-limited":
        return PowerLimitedCoupling(gain=v["coupling_gain"], power_load_n=v["power_load_n"])
    return ConstantCoupling(gain=v["coupling_gain"])


class Target(eqx.Module):
    """Everything the log-posterior needs: data and fixed nuisances as arrays (so one
    compiled program serves every dataset of the same shape), the layout as static."""

    force_n: Array  # (blocks,) block means
    sub_time_s: Array  # (blocks, sub) model points
    first: Array  # (blocks,) first block of its trace
    block_trace: Array  # (blocks,) trace index
    startup_s: Array  # (blocks, 1) nuisances at the fit's values, per block
    on_start_s: Array
    on_end_s: Array
    offset_n: Array
    load_n: Array  # (traces,)
    speed_m_s: Array
    op_index: Array  # (traces,) index into the distinct operating points
    op_load_n: Array  # (ops,)
    op_alpha: Array
    op_speed_m_s: Array
    jac_e: Array  # (blocks, 4) d prediction / d nuisance (internal units) at the fit
    gram: Array  # (3, traces, 4, 4): J_w^T J_w = gram[0] + phi gram[1] + phi^2 gram[2]
    continues: Array  # (blocks,) the next block belongs to the same trace
    vibration_frequency_hz: Array
    max_amplitude_m: Array
    params: tuple[SampledParam, ...] = eqx.field(static=True)
    priors: tuple[Prior, ...] = eqx.field(static=True)
    noise: str = eqx.field(static=True)
    law: str = eqx.field(static=True)
    coupling: str = eqx.field(static=True)
    n_traces: int = eqx.field(static=True)

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(p.name for p in self.params)


def build_target(
    model: FitModel, z_fit: np.ndarray, noise: str, priors: dict[str, Prior]
) -> Target:
    """The log-posterior's target for ``model`` around the fit's internal vector."""
    if noise not in NOISE_MODELS:
        raise ValueError(f"noise {noise!r}: choose one of {NOISE_MODELS}")
    d = model.data
    k = model.n_shared
    params = tuple(SampledParam.of(s) for s in model.specs[:k]) + noise_params(noise)
    v = model.values(jnp.asarray(z_fit))
    bt = d.block_trace
    ops = np.stack([d.normal_load_n, d.amplitude_fraction, d.pull_speed_m_s], axis=1)
    uniq, op_index = np.unique(ops, axis=0, return_inverse=True)
    first = np.zeros(d.n_blocks, bool)
    first[d.first_block] = True

    n = d.n_traces

    def per_block(x):
        return jnp.asarray(np.asarray(x)[bt][:, None])

    continues = np.zeros(d.n_blocks, bool)
    continues[:-1] = ~first[1:]

    target = Target(
        force_n=jnp.asarray(d.force_n),
        sub_time_s=jnp.asarray(d.sub_time_s),
        first=jnp.asarray(first),
        block_trace=jnp.asarray(bt),
        startup_s=per_block(v["pull_start_s"]),
        on_start_s=per_block(d.on_start_s + np.asarray(v["delay_on_s"])),
        on_end_s=per_block(d.on_end_s + np.asarray(v["delay_off_s"])),
        offset_n=per_block(v["offset_n"]),
        load_n=jnp.asarray(d.normal_load_n),
        speed_m_s=jnp.asarray(d.pull_speed_m_s),
        op_index=jnp.asarray(op_index.ravel()),
        op_load_n=jnp.asarray(uniq[:, 0]),
        op_alpha=jnp.asarray(uniq[:, 1]),
        op_speed_m_s=jnp.asarray(uniq[:, 2]),
        jac_e=jnp.zeros((d.n_blocks, len(TRACE_GROUPS))),
        gram=jnp.zeros((3, n, len(TRACE_GROUPS), len(TRACE_GROUPS))),
        continues=jnp.asarray(continues),
        vibration_frequency_hz=jnp.asarray(d.vibration_frequency_hz),
        max_amplitude_m=jnp.asarray(d.max_amplitude_m),
        params=params,
        priors=tuple(priors[p.name] for p in params),
        noise=noise,
        law=model.law,
        coupling=model.coupling,
        n_traces=n,
    )
    shared = {p.name: v[p.name] for p in model.specs[:k]}
    jac_e = np.asarray(_nuisance_jacobian(shared, target))
    return eqx.tree_at(
        lambda t: (t.jac_e, t.gram),
        target,
        (jnp.asarray(jac_e), jnp.asarray(_gram(jac_e, first, bt, n))),
    )


# Which Target field (per block) each per-trace nuisance group moves.
_NUISANCE_FIELDS = {
    "offset_n": "offset_n",
    "pull_start_s": "startup_s",
    "delay_on_s": "on_start_s",
    "delay_off_s": "on_end_s",
}


@jax.jit
def _nuisance_jacobian(shared: dict, target: Target) -> Array:
    """d prediction / d nuisance (internal units), (blocks, groups): one forward-mode
    pass per group, every trace at once (a block depends on its own trace's nuisances
    only). Compiled once per data shape: the data are arguments, not constants."""
    fields = [_NUISANCE_FIELDS[g] for g, _, _ in TRACE_GROUPS]

    def pred(*values):
        moved = eqx.tree_at(lambda t: [getattr(t, f) for f in fields], target, list(values))
        return predict_blocks(shared, moved)

    primals = tuple(getattr(target, f) for f in fields)
    cols = []
    for j, (_, _, scale) in enumerate(TRACE_GROUPS):
        tangents = tuple(
            jnp.full_like(x, scale) if i == j else jnp.zeros_like(x) for i, x in enumerate(primals)
        )
        cols.append(jax.jvp(pred, primals, tangents)[1])
    return jnp.stack(cols, axis=1)


def _gram(jac: np.ndarray, first: np.ndarray, trace: np.ndarray, n_traces: int) -> np.ndarray:
    """Per trace, the whitened nuisance Gram matrix as a quadratic in phi (3, traces, 4, 4).

    ``(J_t - phi J_{t-1})`` within a trace and ``sqrt(1 - phi^2) J_t`` at its first block,
    expanded, so the sampler never re-whitens J.
    """
    prev = np.roll(jac, 1, axis=0)
    inner = ~first
    outer = np.einsum("ti,tj->tij", jac, jac)
    cross = np.einsum("ti,tj->tij", jac, prev)
    prev_outer = np.einsum("ti,tj->tij", prev, prev)
    terms = np.stack(
        [
            outer,
            -np.where(inner[:, None, None], cross + cross.transpose(0, 2, 1), 0.0),
            np.where(inner[:, None, None], prev_outer, -outer),
        ]
    )
    out = np.zeros((3, n_traces, *jac.shape[1:], jac.shape[1]))
    for k in range(3):
        np.add.at(out[k], trace, terms[k])
    return out


def physical_values(theta: Array, target: Target) -> dict[str, Array]:
    """Physical values of one internal vector, by name."""
    return {p.name: p.value(theta[i]) for i, p in enumerate(target.params)}


def friction_ratios_at(v: dict, target: Target, load_n, alpha, speed_m_s) -> Array:
    """FR at operating points (1-d arrays of equal length) from physical values ``v``."""
    coupling = _coupling_of(target.coupling, v)

    def one(n, a, s):
        law = _law_at(target.law, v, n)
        return on_friction_ratio(
            law, coupling, n, a, s, target.vibration_frequency_hz, target.max_amplitude_m
        )

    return jax.vmap(one)(load_n, alpha, speed_m_s)


def predict_blocks_batch(v: dict, target: Target) -> Array:
    """Block-mean force [N] for a batch of parameter sets (``v`` maps names to arrays of
    shape (walkers,)), nuisances at the fit's values: (walkers, blocks).

    FR is computed at the distinct operating points only and gathered. The bench model
    runs with the walkers as the last (fastest) axis, so every model point's time and
    nuisances are read once for all walkers: 2.6 times faster than vmapping over walkers.
    """
    t = target

    def per_walker(vv):
        fr = friction_ratios_at(vv, t, t.op_load_n, t.op_alpha, t.op_speed_m_s)[t.op_index]
        off = jax.vmap(lambda n, s: _law_at(t.law, vv, n).off_force_n(s))(t.load_n, t.speed_m_s)
        return fr, off

    fr, off = jax.vmap(per_walker)(v)  # (walkers, traces)
    bt = t.block_trace
    timing = TraceTiming(
        startup_s=t.startup_s[..., None],
        on_start_s=t.on_start_s[..., None],
        on_end_s=t.on_end_s[..., None],
    )
    force = mean_force_n(
        t.sub_time_s[..., None],
        off.T[bt][:, None, :],
        (fr * off).T[bt][:, None, :],
        timing,
        v["slope_n_s"][None, None, :],
        v["startup_slope_n_s"][None, None, :],
        t.offset_n[..., None],
        CORNER_N,
    )  # (blocks, sub, walkers)
    return force.mean(axis=1).T


def predict_blocks(v: dict, target: Target) -> Array:
    """Block-mean force [N] for one parameter set (scalars in ``v``): (blocks,)."""
    return predict_blocks_batch({k: jnp.asarray(x)[None] for k, x in v.items()}, target)[0]


def _whiten(x: Array, first: Array, phi) -> Array:
    """AR(1) whitening along axis 0, restarting at every trace's first block."""
    head = jnp.sqrt(1.0 - phi**2)
    shifted = jnp.roll(x, 1, axis=0)
    f = first.reshape((-1,) + (1,) * (x.ndim - 1))
    return jnp.where(f, head * x, x - phi * shifted)


def _student_t_logpdf(u: Array, nu) -> Array:
    return (
        jax.scipy.special.gammaln((nu + 1.0) / 2.0)
        - jax.scipy.special.gammaln(nu / 2.0)
        - 0.5 * jnp.log(nu * jnp.pi)
        - (nu + 1.0) / 2.0 * jnp.log1p(u**2 / nu)
    )


def marginal_loglik_batch(e: Array, v: dict, target: Target) -> tuple[Array, Array]:
    """Log-likelihood of residuals ``e`` (walkers, blocks; model - data) with the
    nuisances integrated out (module docstring), (walkers,); and the nuisance shift at
    its conditional mode, (walkers, traces, 4). ``v`` maps names to (walkers,) arrays.

    With ``w = L e`` the whitened residuals and ``J_w = L J``: ``h = J_w^T w = J^T (L^T w)``
    and ``J_w^T J_w`` comes precomputed (:func:`_gram`), so a call costs two passes over
    the blocks (walkers as the fastest axis) and one 4 x 4 Cholesky per trace.
    """
    t = target
    batch = e.shape[0]
    sigma = v["sigma_n"]
    phi = v.get("phi", jnp.zeros(batch))
    student = t.noise in ("student-t", "ar1-student-t")
    w = _whiten(e.T, t.first, phi)  # (blocks, walkers)
    head = jnp.sqrt(1.0 - phi**2)
    nxt = jnp.where(t.continues[:, None], jnp.roll(w, -1, axis=0), 0.0)
    lt_w = jnp.where(t.first[:, None], head * w, w) - phi * nxt
    h = jax.ops.segment_sum(t.jac_e[:, :, None] * lt_w[:, None, :], t.block_trace, t.n_traces)
    h = jnp.moveaxis(h, -1, 0)  # (walkers, traces, 4)

    def per_walker(x):  # (walkers,) -> broadcast against (walkers, traces, 4, 4)
        return x[:, None, None, None]

    g = t.gram[0] + per_walker(phi) * t.gram[1] + per_walker(phi**2) * t.gram[2]
    # Precision of the nuisances (Fisher information for Student-t), prior included.
    info = (v["nu"] + 1.0) / (v["nu"] + 3.0) if student else jnp.ones(batch)
    scale = info / sigma**2
    prior_prec = 1.0 / NUISANCE_PRIOR_SD**2
    a = g * per_walker(scale) + prior_prec * jnp.eye(g.shape[-1])
    chol = jnp.linalg.cholesky(a)
    y = solve_triangular(chol, (-h * scale[:, None, None])[..., None], lower=True)
    shift = solve_triangular(jnp.swapaxes(chol, -1, -2), y, lower=False)[..., 0]
    log_det = 2.0 * jnp.sum(jnp.log(jnp.diagonal(chol, axis1=-2, axis2=-1)), axis=(1, 2))
    n = e.shape[1]
    p = shift.shape[1] * shift.shape[2]
    if student:
        jw = _whiten(t.jac_e[:, :, None], t.first, phi)  # (blocks, 4, walkers)
        moved = jnp.moveaxis(shift, 0, -1)[t.block_trace]  # (blocks, 4, walkers)
        w_fit = w + jnp.sum(jw * moved, axis=1)
        u = w_fit / sigma
        ll = jnp.sum(_student_t_logpdf(u, v["nu"]), axis=0) - n * jnp.log(sigma)
        ll = ll - 0.5 * prior_prec * jnp.sum(shift**2, axis=(1, 2))
    else:
        # min over the shift of |w + J_w s|^2 / sigma^2 + s^T s / sd^2, in closed form
        ll = -0.5 * n * jnp.log(2.0 * jnp.pi * sigma**2) - 0.5 * jnp.sum(w**2, axis=0) / sigma**2
        ll = ll + 0.5 * jnp.sum(y**2, axis=(1, 2, 3))
    ll = ll - 0.5 * log_det - p * math.log(NUISANCE_PRIOR_SD)
    return ll + 0.5 * t.n_traces * jnp.log1p(-(phi**2)), shift


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


def conditioning_shrinkage(cov_z: np.ndarray, n_shared: int) -> np.ndarray:
    """sd of each shared parameter with the nuisances held fixed, over its marginal sd
    (from the fit's covariance): how much fixing the nuisances would understate."""
    s = slice(0, n_shared)
    rest = slice(n_shared, cov_z.shape[0])
    css, csn, cnn = cov_z[s, s], cov_z[s, rest], cov_z[rest, rest]
    cond = css - csn @ np.linalg.solve(cnn, csn.T)
    return np.sqrt(np.maximum(np.diag(cond), 0.0) / np.diag(css))
