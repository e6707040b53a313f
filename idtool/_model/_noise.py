"""Noise models of the block-mean residuals, registered in ``NOISE_MODELS``.

A noise model says how the residuals ``e = model - data`` [N] of one trace's block means
are distributed: how they are correlated within a trace and how the innovations ``eps``
are distributed. The correlation is a linear, exact-likelihood whitening ``w = L e``
within each trace (``L`` lower triangular, one per trace, set by the model's
*correlation state*: a fixed-length float array, :attr:`AbstractNoise.state_params`;
``[phi]`` for AR(1), empty for independent noise), after which ``w = sigma eps`` are
independent. What each stage asks of it:

* the fit (least squares, :mod:`idtool._fit._fit`): :meth:`AbstractNoise.whiten`
  inside its compiled programs, :meth:`AbstractNoise.estimate_state` from the
  unwhitened residuals (:meth:`AbstractNoise.unwhiten`) between rounds, and
  :meth:`AbstractNoise.trace_log_det` (``log |det L|`` of a trace) in its
  log-likelihood;
* the sampler (:mod:`idtool._posterior._likelihood`): :attr:`AbstractNoise.params` in
  the sampled vector, :meth:`AbstractNoise.innovation_logpdf` and
  :meth:`AbstractNoise.nuisance_information`, and the whitened nuisances' normal
  equations (:meth:`AbstractNoise.nuisance_equations`, from what
  :meth:`AbstractNoise.gram_terms` precomputes once);
* the posterior predictive check: :meth:`AbstractNoise.draw_innovations`, coloured by
  :meth:`AbstractNoise.unwhiten`.

Registered models:

* ``ar1`` (default): Gaussian AR(1), ``e_t = phi e_{t-1} + sigma eps_t`` within each
  trace with a stationary first block. The load cell at 1 kHz has correlated noise;
  block means over 40 ms keep a lag-1 correlation of about 0.5, and an
  independent-noise likelihood then counts every block as new information and gives
  intervals about ``sqrt((1 + phi) / (1 - phi))`` ~ 1.8x too narrow
  (tests/test_sample.py measures it);
* ``gaussian``: independent Gaussian noise;
* ``student-t``: independent Student-t noise (sigma its scale, nu its degrees of freedom);
* ``ar1-student-t``: AR(1) with Student-t innovations (the first block of each trace
  uses the Gaussian stationary scaling, an approximation).

A heavy-tailed model is fitted by least squares like its Gaussian counterpart (the
estimates stay consistent); its tails enter the posterior. A new model is one subclass
and one registration (CONTRIBUTING.md, "A noise model"; tests/test_toy_noise.py adds an
AR(2) model from outside the package).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import ClassVar

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from idtool._model._names import DEFAULT_NOISE
from idtool._model._params import Param
from idtool._model._truth_fields import TruthField
from idtool._registry import Registry

__all__ = [
    "DEFAULT_NOISE",
    "NOISE_MODELS",
    "NU",
    "PHI",
    "SIGMA",
    "AbstractNoise",
    "NoiseState",
    "ar1_coefficient",
    "whiten",
]

NOISE_MODELS: Registry[type[AbstractNoise]] = Registry("noise model")

# A correlation state: (k,) or (k, *batch) (one column per walker or draw), JAX or NumPy;
# a bare number is AR(1)'s phi (the callers from before the state)
NoiseState = Array | np.ndarray | float

SIGMA = Param("sigma_n", "N", "log", 1e-6, 1e4, description="innovation scale of the block means")
PHI = Param("phi", "1", "tanh", -1.0, 1.0, description="AR(1) coefficient of the block means")
NU = Param("nu", "1", "log", 1.0, 1000.0, description="Student-t degrees of freedom")


def whiten(e: Array, first: Array, phi) -> Array:
    """AR(1) whitening along axis 0: ``e_t - phi e_{t-1}`` within a trace and
    ``sqrt(1 - phi^2) e_t`` at each trace's first block (``first``), exact likelihood.
    ``phi`` broadcasts against ``e``'s trailing axes (one per walker in the sampler)."""
    head = jnp.sqrt(1.0 - phi**2)
    shifted = jnp.roll(e, 1, axis=0)
    f = first.reshape((-1,) + (1,) * (e.ndim - 1))
    return jnp.where(f, head * e, e - phi * shifted)


def ar1_coefficient(e: np.ndarray, first: np.ndarray) -> float:
    """Pooled lag-1 autocorrelation of residuals ``e`` within traces (``first``: True at
    each trace's first block), clipped to [-0.99, 0.99]."""
    e = np.asarray(e)
    num = np.sum((e[1:] * e[:-1])[~np.asarray(first)[1:]])
    return float(np.clip(num / np.sum(e**2), -0.99, 0.99))


def _per_trace(x: Array, block_trace: Array, n_traces: int) -> Array:
    """Sum of ``x`` (blocks, ...) over each trace's blocks: (traces, ...)."""
    return jax.ops.segment_sum(x, block_trace, n_traces)


class AbstractNoise(eqx.Module):
    """A noise model (module docstring). Stateless: its parameters are sampled or
    passed in, and the class itself is static in every compiled program.

    The defaults are those of independent noise (no correlation state, ``L = I``) with
    Gaussian innovations; a correlated model overrides :attr:`state_params`,
    :meth:`whiten`, :meth:`unwhiten`, :meth:`estimate_state` and :meth:`trace_log_det`
    (the sampler's nuisance equations then whiten the Jacobian per draw, exactly).
    """

    name: ClassVar[str] = ""
    params: ClassVar[tuple[Param, ...]] = (SIGMA,)
    # The correlation state's parameters, in the state's order: a subset of ``params``
    # (the sampler samples them; the fit estimates them from its residuals).
    state_params: ClassVar[tuple[Param, ...]] = ()
    gaussian: ClassVar[bool] = True
    description: ClassVar[str] = ""

    @classmethod
    def truth_fields(cls) -> tuple[TruthField, ...]:
        """The model's numbers in the simulator's parameter file (its
        ``block_mean_noise`` section): :attr:`params` under their own names, each inside
        its open range (where the model's whitening is defined, ``|phi| < 1``)."""
        return tuple(TruthField.of(p, bounded=True) for p in cls.params)

    @property
    def autoregressive(self) -> bool:
        """Whether the residuals are correlated (the fit then estimates the state)."""
        return bool(self.state_params)

    def initial_state(self) -> Float[np.ndarray, " k"]:
        """The state before any residuals are seen: uncorrelated (zeros)."""
        return np.zeros(len(self.state_params))

    def state_of(self, values: Mapping[str, Array | np.ndarray]) -> Array:
        """The state from parameter values by name, shaped (k, *batch) where the values
        are shaped ``batch`` (one per walker in the sampler)."""
        batch = jnp.shape(values["sigma_n"])
        if not self.state_params:
            return jnp.zeros((0, *batch))
        return jnp.stack([jnp.broadcast_to(values[p.name], batch) for p in self.state_params])

    def state_by_name(self, state: NoiseState) -> dict[str, float]:
        """The state as plain floats by parameter name (``fit.json``'s
        ``noise.parameters``)."""
        s = np.atleast_1d(np.asarray(state, float))
        return {p.name: float(s[i]) for i, p in enumerate(self.state_params)}

    def state_from_names(self, values: Mapping[str, float]) -> Float[np.ndarray, " k"]:
        """The state from values by name; a parameter missing there is 0 (uncorrelated
        in that coefficient)."""
        return np.array([float(values.get(p.name, 0.0)) for p in self.state_params])

    def whiten(self, e: Array, first: Array, state: NoiseState) -> Array:
        """Whitened residuals ``w = L e`` along axis 0 (blocks; ``first`` True at each
        trace's first block), exact likelihood; ``state`` (k, *batch) broadcasts against
        ``e``'s trailing axes."""
        return e

    def unwhiten(self, w: np.ndarray, first: np.ndarray, state: NoiseState) -> np.ndarray:
        """``e = L^-1 w`` along the last axis (blocks), NumPy: residuals from whitened
        ones, and coloured noise from innovations (the predictive check); ``state`` (k,)
        or (k, rows) for rows of ``w``."""
        return np.array(w, float)

    def estimate_state(self, e: np.ndarray, first: np.ndarray) -> Float[np.ndarray, " k"]:
        """The fit's estimate of the state from (unwhitened) residuals ``e`` [N]."""
        return self.initial_state()

    def state_settled(self, old: np.ndarray, new: np.ndarray) -> bool:
        """Whether a re-estimated state is close enough to the one the parameters were
        fitted with to stop refitting: every coefficient within 0.02 (the estimates then
        move far less than their errors)."""
        return bool(np.all(np.abs(np.asarray(new) - np.asarray(old)) < 0.02))

    def state_sd(self, state: np.ndarray, n_blocks: int) -> Float[np.ndarray, " k"]:
        """Asymptotic standard errors of the state's coefficients from ``n_blocks``
        blocks (the sampler's start spread): ``1 / sqrt(n)`` unless overridden."""
        return np.full(len(self.state_params), 1.0 / math.sqrt(n_blocks))

    def stationary_sd_factor(self, state: NoiseState) -> float:
        """The residuals' stationary sd in units of sigma (1 for independent noise):
        the report's band around the fit."""
        return 1.0

    def trace_log_det(self, state: NoiseState) -> Array:
        """``log |det L|`` of one trace's whitening (at least as many blocks as the
        state's length), shaped like ``state[0]``: the log-likelihood's Jacobian term."""
        return jnp.zeros(jnp.shape(state)[1:])

    def gram_terms(
        self, jac: np.ndarray, first: np.ndarray, block_trace: np.ndarray, n_traces: int
    ) -> np.ndarray:
        """What :meth:`nuisance_equations` precomputes from the nuisance Jacobian ``jac``
        (blocks, groups) once per target, (terms, traces, groups, groups): here ``J^T J``
        per trace, which is the whitened Gram of independent noise."""
        out = np.zeros((1, n_traces, jac.shape[1], jac.shape[1]))
        np.add.at(out[0], block_trace, np.einsum("ti,tj->tij", jac, jac))
        return out

    def nuisance_equations(
        self,
        w: Float[Array, "blocks walkers"],
        jac: Float[Array, "blocks groups"],
        gram: Array,
        first: Array,
        continues: Array,
        block_trace: Array,
        state: NoiseState,
    ) -> tuple[Array, Array]:
        """The whitened nuisances' normal equations per walker and trace: ``h = J_w^T w``
        (walkers, traces, groups) and ``J_w^T J_w`` (walkers, traces, groups, groups),
        with ``J_w = L J`` (:mod:`idtool._posterior._likelihood`). ``gram``: what
        :meth:`gram_terms` precomputed; ``continues``: the next block is of the same
        trace. A correlated model without a Gram of its own whitens ``J`` per walker."""
        n_traces = gram.shape[1]
        if not self.state_params:  # L = I: J^T J is the precomputed Gram
            h = _per_trace(jac[:, :, None] * w[:, None, :], block_trace, n_traces)
            g = jnp.broadcast_to(gram[0], (w.shape[1], *gram.shape[1:]))
            return jnp.moveaxis(h, -1, 0), g
        jw = self.whiten(jac[:, :, None], first, state)  # (blocks, groups, walkers)
        h = _per_trace(jw * w[:, None, :], block_trace, n_traces)
        g = _per_trace(jw[:, :, None, :] * jw[:, None, :, :], block_trace, n_traces)
        return jnp.moveaxis(h, -1, 0), jnp.moveaxis(g, -1, 0)

    def innovation_logpdf(self, u: Array, values: dict[str, Array]) -> Array:
        """Log-density of standardised innovations ``u = eps / sigma`` (elementwise,
        without the ``-log sigma`` of the scale)."""
        return -0.5 * u**2 - 0.5 * jnp.log(2.0 * jnp.pi)

    def nuisance_information(self, values: dict[str, Array]) -> Array:
        """Fisher information of one standardised innovation about a location shift
        (1 for Gaussian noise): scales the nuisances' precision."""
        return jnp.ones_like(values["sigma_n"])

    def draw_innovations(
        self, rng: np.random.Generator, values: dict[str, np.ndarray], n: int
    ) -> np.ndarray:
        """Standardised innovations for replicated traces: (draws, n)."""
        return rng.standard_normal((np.size(values["sigma_n"]), n))

    def simulate(
        self, rng: np.random.Generator, values: dict[str, np.ndarray], first: np.ndarray
    ) -> Float[np.ndarray, "draws blocks"]:
        """Noise of the block means [N] for parameter values by name ((draws,) arrays):
        innovations ``sigma eps`` (:meth:`draw_innovations`) coloured by ``L^-1``
        (:meth:`unwhiten`) within each trace (``first``). The posterior predictive
        check's replicated noise, and the simulator's block-mean noise
        (:func:`idtool._simulate._block_noise.with_block_noise`)."""
        sigma = np.asarray(values["sigma_n"], float)[:, None]
        eps = self.draw_innovations(rng, values, np.size(first)) * sigma
        return self.unwhiten(eps, np.asarray(first), np.asarray(self.state_of(values)))


class _StudentT(AbstractNoise):
    """Student-t innovations (nu degrees of freedom, ``NU``)."""

    gaussian: ClassVar[bool] = False

    def innovation_logpdf(self, u, values):
        nu = values["nu"]
        return (
            jax.scipy.special.gammaln((nu + 1.0) / 2.0)
            - jax.scipy.special.gammaln(nu / 2.0)
            - 0.5 * jnp.log(nu * jnp.pi)
            - (nu + 1.0) / 2.0 * jnp.log1p(u**2 / nu)
        )

    def nuisance_information(self, values):
        nu = values["nu"]
        return (nu + 1.0) / (nu + 3.0)

    def draw_innovations(self, rng, values, n):
        return rng.standard_t(np.asarray(values["nu"])[:, None], size=(values["nu"].size, n))


def _phi(state) -> Array:
    """The AR(1) coefficient of a state (k = 1, batch...); a bare number is phi itself
    (the callers from before the state: tests, benchmarks)."""
    return state if jnp.ndim(state) == 0 else state[0]


class _AR1(AbstractNoise):
    """AR(1) within each trace, stationary first block: state ``[phi]``."""

    state_params: ClassVar[tuple[Param, ...]] = (PHI,)

    def whiten(self, e, first, state):
        return whiten(e, first, _phi(state))

    def unwhiten(self, w, first, state):
        # e_1 = w_1 / sqrt(1 - phi^2), e_t = w_t + phi e_(t-1) within a trace
        phi = np.asarray(_phi(np.asarray(state, float)))  # () or (rows,)
        head = np.sqrt(1.0 - phi**2)
        w = np.asarray(w, float)
        e = np.array(w)
        for t in range(e.shape[-1]):
            e[..., t] = w[..., t] / head if first[t] else w[..., t] + phi * e[..., t - 1]
        return e

    def estimate_state(self, e, first):
        return np.array([ar1_coefficient(e, first)])

    def state_sd(self, state, n_blocks):
        return np.sqrt((1.0 - np.asarray(state, float) ** 2) / n_blocks)

    def stationary_sd_factor(self, state):
        # 1 / sqrt(1 - phi^2), held finite next to a unit root
        return float(1.0 / np.sqrt(1.0 - min(float(_phi(state)) ** 2, 0.999)))

    def trace_log_det(self, state):
        return 0.5 * jnp.log1p(-(_phi(state) ** 2))

    def gram_terms(self, jac, first, block_trace, n_traces):
        # J_w^T J_w as a quadratic in phi (gram[0] + phi gram[1] + phi^2 gram[2]):
        # (J_t - phi J_{t-1}) within a trace and sqrt(1 - phi^2) J_t at its first block,
        # expanded, so the sampler never re-whitens J
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
            np.add.at(out[k], block_trace, terms[k])
        return out

    def nuisance_equations(self, w, jac, gram, first, continues, block_trace, state):
        # h = J_w^T w = J^T (L^T w): two passes over the blocks, no whitened J
        phi = _phi(state)
        head = jnp.sqrt(1.0 - phi**2)
        nxt = jnp.where(continues[:, None], jnp.roll(w, -1, axis=0), 0.0)
        lt_w = jnp.where(first[:, None], head * w, w) - phi * nxt
        h = _per_trace(jac[:, :, None] * lt_w[:, None, :], block_trace, gram.shape[1])
        g = gram[0] + phi[:, None, None, None] * gram[1] + (phi**2)[:, None, None, None] * gram[2]
        return jnp.moveaxis(h, -1, 0), g


@NOISE_MODELS.register("ar1")
class AR1Noise(_AR1):
    params: ClassVar[tuple[Param, ...]] = (SIGMA, PHI)
    description: ClassVar[str] = "Gaussian AR(1) within each trace"


@NOISE_MODELS.register("gaussian")
class GaussianNoise(AbstractNoise):
    description: ClassVar[str] = "independent Gaussian"


@NOISE_MODELS.register("student-t")
class StudentTNoise(_StudentT):
    params: ClassVar[tuple[Param, ...]] = (SIGMA, NU)
    description: ClassVar[str] = "independent Student-t"


@NOISE_MODELS.register("ar1-student-t")
class AR1StudentTNoise(_AR1, _StudentT):
    params: ClassVar[tuple[Param, ...]] = (SIGMA, PHI, NU)
    description: ClassVar[str] = "AR(1) with Student-t innovations"
