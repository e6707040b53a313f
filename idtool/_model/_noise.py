"""Noise models of the block-mean residuals, registered in ``NOISE_MODELS``.

A noise model says how the residuals ``e = model - data`` of one trace's block means
are distributed: whether they are autoregressive (``e_t = phi e_{t-1} + sigma eps_t``
within each trace, stationary first block) and how the innovations ``eps`` are
distributed. The fit (least squares) uses :meth:`AbstractNoise.estimate_phi` and the
AR(1) whitening; the sampler adds :attr:`AbstractNoise.params` to the sampled vector and
uses :meth:`AbstractNoise.innovation_logpdf` and
:meth:`AbstractNoise.nuisance_information` in the marginal likelihood; the posterior
predictive check draws replicated noise with :meth:`AbstractNoise.draw_innovations`.

* ``ar1`` (default): Gaussian AR(1). The load cell at 1 kHz has correlated noise; block
  means over 40 ms keep a lag-1 correlation of about 0.5, and an independent-noise
  likelihood then counts every block as new information and gives intervals about
  ``sqrt((1 + phi) / (1 - phi))`` ~ 1.8x too narrow (tests/test_sample.py measures it);
* ``gaussian``: independent Gaussian noise;
* ``student-t``: independent Student-t noise (sigma its scale, nu its degrees of freedom);
* ``ar1-student-t``: AR(1) with Student-t innovations (the first block of each trace
  uses the Gaussian stationary scaling, an approximation).

A heavy-tailed model is fitted by least squares like its Gaussian counterpart (the
estimates stay consistent); its tails enter the posterior.
"""

from __future__ import annotations

from typing import ClassVar

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array

from idtool._model._names import DEFAULT_NOISE
from idtool._model._params import Param
from idtool._registry import Registry

__all__ = [
    "DEFAULT_NOISE",
    "NOISE_MODELS",
    "NU",
    "PHI",
    "SIGMA",
    "AbstractNoise",
    "ar1_coefficient",
    "whiten",
]

NOISE_MODELS: Registry[type[AbstractNoise]] = Registry("noise model")

SIGMA = Param("sigma_n", "N", "log", 1e-6, 1e4, description="innovation scale of the block means")
PHI = Param("phi", "1", "tanh", -1.0, 1.0, description="AR(1) coefficient of the block means")
NU = Param("nu", "1", "log", 1.0, 1000.0, description="Student-t degrees of freedom")


def whiten(e: Array, first: Array, phi) -> Array:
    """AR(1) whitening along axis 0: ``e_t - phi e_{t-1}`` within a trace and
    ``sqrt(1 - phi^2) e_t`` at each trace's first block (``first``), exact likelihood."""
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


class AbstractNoise(eqx.Module):
    """A noise model (module docstring). Stateless: its parameters are sampled, and the
    class itself is static in every compiled program."""

    name: ClassVar[str] = ""
    params: ClassVar[tuple[Param, ...]] = (SIGMA,)
    autoregressive: ClassVar[bool] = False
    gaussian: ClassVar[bool] = True
    description: ClassVar[str] = ""

    def phi(self, values: dict[str, Array]) -> Array:
        """AR(1) coefficient (zero for independent noise), shaped like ``sigma_n``."""
        if self.autoregressive:
            return values["phi"]
        return jnp.zeros_like(values["sigma_n"])

    def estimate_phi(self, e: np.ndarray, first: np.ndarray) -> float:
        """The fit's estimate of phi from residuals (zero for independent noise)."""
        return ar1_coefficient(e, first) if self.autoregressive else 0.0

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


class _StudentT(AbstractNoise):
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


@NOISE_MODELS.register("ar1")
class AR1Noise(AbstractNoise):
    params: ClassVar[tuple[Param, ...]] = (SIGMA, PHI)
    autoregressive: ClassVar[bool] = True
    description: ClassVar[str] = "Gaussian AR(1) within each trace"


@NOISE_MODELS.register("gaussian")
class GaussianNoise(AbstractNoise):
    description: ClassVar[str] = "independent Gaussian"


@NOISE_MODELS.register("student-t")
class StudentTNoise(_StudentT):
    params: ClassVar[tuple[Param, ...]] = (SIGMA, NU)
    description: ClassVar[str] = "independent Student-t"


@NOISE_MODELS.register("ar1-student-t")
class AR1StudentTNoise(_StudentT):
    params: ClassVar[tuple[Param, ...]] = (SIGMA, PHI, NU)
    autoregressive: ClassVar[bool] = True
    description: ClassVar[str] = "AR(1) with Student-t innovations"
