"""The exponentially saturating coupling: ``a = gain * A_max * (P / N) (1 - exp(-alpha N / P))``.

A second saturating shape beside the power limit, with the same two asymptotes: the
constant law ``gain * alpha * A_max`` at small ``alpha N / P`` (the first-order term of
the exponential) and the ceiling ``gain * A_max * P / N`` at large ``alpha N / P``,
which falls with the normal load. The knee between them is softer: at ``alpha N = P``
the amplitude is ``1 - 1/e = 63%`` of the constant law's, against ``1/sqrt(2) = 71%``
under the power limit, and the approach to the ceiling is exponential, not algebraic.
It is the law of a horn whose delivered slip relaxes towards a power-limited ceiling
at a rate proportional to the remaining headroom. ``P -> inf`` recovers the constant
law, so it nests it; the power-limited law does not nest it nor it the power limit, and
BIC tells the two apart where the data reach the knee.
"""

from __future__ import annotations

from typing import ClassVar

import jax.numpy as jnp
from jaxtyping import ArrayLike, Float

from idtool._model._coupling import COUPLINGS, GAIN, AbstractCoupling, load_scale_param
from idtool._model._params import Param

__all__ = ["ExponentialCoupling"]


@COUPLINGS.register("exponential")
class ExponentialCoupling(AbstractCoupling):
    """``a = gain * A_max * (P / N) * (1 - exp(-alpha N / P))`` [m].

    Attributes:
        gain: small-signal coupling (dimensionless), as in the constant law.
        saturation_load_n: load scale P [N] of the saturation; larger is weaker.
    """

    gain: Float[ArrayLike, ""]
    saturation_load_n: Float[ArrayLike, ""]
    fit_params: ClassVar[tuple[Param, ...]] = (
        GAIN,
        # up to 1e7 N: its first-order departure from the constant law (x / 2, not the
        # power limit's x^2 / 2) must be able to vanish on data that do not saturate
        load_scale_param("saturation_load_n", "load scale P of the exponential saturation", hi=1e7),
    )

    @classmethod
    def from_values(cls, values):
        return cls(gain=values["coupling_gain"], saturation_load_n=values["saturation_load_n"])

    def amplitude_m(self, amplitude_fraction, normal_load_n, max_amplitude_m):
        alpha = jnp.asarray(amplitude_fraction)
        x = alpha * jnp.asarray(normal_load_n) / self.saturation_load_n
        # alpha (1 - e^-x) / x, written with expm1 so that x -> 0 (zero load or
        # amplitude) keeps full precision: -expm1(-x) / x -> 1
        ratio = jnp.where(x > 0.0, -jnp.expm1(-x) / jnp.where(x > 0.0, x, 1.0), 1.0)
        return self.gain * alpha * max_amplitude_m * ratio
