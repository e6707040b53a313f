"""Coupling laws the simulator may use as the truth but the fit does not ship.

A coverage study must also see how the fit behaves when its coupling family cannot
represent the truth (model misspecification). The laws here are therefore deliberately
*not* registered in :data:`idtool._model._coupling.COUPLINGS`, so no ``idtool fit
--coupling`` choice names them, and they are shaped unlike the fit's laws and unlike the
saturating laws it may gain later (constant, power-limited, tanh- or exponential-in-
amplitude saturation):

* :class:`LoadExponentialCoupling`: ``a = gain * alpha * A_max * exp(-N / load_scale_n)``.
  The slip amplitude stays proportional to the commanded amplitude at every load (no
  saturation in ``alpha``), and falls exponentially with the normal load instead of as
  ``1 / (alpha N)`` at large ``alpha N`` like the power limit.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import ClassVar

import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

from idtool._model._coupling import AbstractCoupling

__all__ = ["TRUTH_ONLY_COUPLINGS", "LoadExponentialCoupling"]


class LoadExponentialCoupling(AbstractCoupling):
    """Truth only: ``a = gain * alpha * A_max * exp(-N / load_scale_n)`` [m].

    Attributes:
        gain: slip amplitude per commanded horn amplitude at zero load [-].
        load_scale_n: normal load over which the slip amplitude falls by a factor e [N].
    """

    gain: Float[ArrayLike, ""]
    load_scale_n: Float[ArrayLike, ""]
    name: ClassVar[str] = "load_exponential"

    @classmethod
    def from_values(cls, values: Mapping[str, ArrayLike]) -> LoadExponentialCoupling:
        return cls(gain=values["coupling_gain"], load_scale_n=values["load_scale_n"])

    def amplitude_m(
        self,
        amplitude_fraction: Float[ArrayLike, "*b"],
        normal_load_n: Float[ArrayLike, "*b"],
        max_amplitude_m: Float[ArrayLike, ""],
    ) -> Float[Array, "*b"]:
        alpha = jnp.asarray(amplitude_fraction)
        decay = jnp.exp(-jnp.asarray(normal_load_n) / jnp.asarray(self.load_scale_n))
        return jnp.asarray(self.gain * alpha * max_amplitude_m * decay)


# The simulator parameter file's name of each truth-only law (``coupling.law``).
TRUTH_ONLY_COUPLINGS: dict[str, type[AbstractCoupling]] = {
    "load_exponential": LoadExponentialCoupling,
}
