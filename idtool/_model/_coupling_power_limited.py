"""The power-limited coupling: ``a = gain * alpha * A_max / sqrt(1 + (alpha N / P)^2)``.

At small ``alpha N`` it is the constant law; at large ``alpha N`` the amplitude saturates
at ``gain * A_max * P / N``: it no longer grows with the commanded amplitude and falls
with the normal load, as the paper reports. ``P -> inf`` recovers the constant law.
"""

from __future__ import annotations

from typing import ClassVar

import jax.numpy as jnp
from jaxtyping import ArrayLike, Float

from idtool._model._coupling import COUPLINGS, GAIN, AbstractCoupling, load_scale_param
from idtool._model._params import Param

__all__ = ["PowerLimitedCoupling"]


@COUPLINGS.register("power-limited")
class PowerLimitedCoupling(AbstractCoupling):
    """``a = gain * alpha * A_max / sqrt(1 + (alpha N / P)^2)`` [m].

    Attributes:
        gain: small-signal coupling (dimensionless), as in the constant law.
        power_load_n: load scale P [N] of the power limit; larger is weaker.
    """

    gain: Float[ArrayLike, ""]
    power_load_n: Float[ArrayLike, ""]
    fit_params: ClassVar[tuple[Param, ...]] = (
        GAIN,
        load_scale_param("power_load_n", "load scale P of the power limit"),
    )

    @classmethod
    def from_values(cls, values):
        return cls(gain=values["coupling_gain"], power_load_n=values["power_load_n"])

    def amplitude_m(self, amplitude_fraction, normal_load_n, max_amplitude_m):
        alpha = jnp.asarray(amplitude_fraction)
        x = alpha * jnp.asarray(normal_load_n) / self.power_load_n
        return self.gain * alpha * max_amplitude_m / jnp.sqrt(1.0 + x**2)
