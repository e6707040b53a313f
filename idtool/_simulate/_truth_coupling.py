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
* :class:`TanhCeilingCoupling`: ``a = gain * A_max * c * tanh(alpha / c)`` with the ceiling
  ``c = sqrt(ceiling_load_n / N)``. The constant law at small ``alpha``; a ceiling
  ``gain * A_max * c`` that falls as ``N^-1/2`` (the shipped saturating laws' falls as
  ``1 / N``, the load-power law's small-signal gain as ``N^-beta`` times that), reached
  through a tanh knee, sharper than the power limit's algebraic and the exponential
  law's soft one.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import ClassVar

import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

from idtool._model._coupling import GAIN, AbstractCoupling
from idtool._model._params import Param
from idtool._registry import Registry

__all__ = ["TRUTH_ONLY_COUPLINGS", "LoadExponentialCoupling", "TanhCeilingCoupling"]

# Registered under the simulator parameter file's name (``coupling.law``); the simulator
# reads these beside :data:`idtool._model._coupling.COUPLINGS`.
TRUTH_ONLY_COUPLINGS: Registry[type[AbstractCoupling]] = Registry("truth-only coupling law")


@TRUTH_ONLY_COUPLINGS.register("load_exponential")
class LoadExponentialCoupling(AbstractCoupling):
    """Truth only: ``a = gain * alpha * A_max * exp(-N / load_scale_n)`` [m].

    Attributes:
        gain: slip amplitude per commanded horn amplitude at zero load [-].
        load_scale_n: normal load over which the slip amplitude falls by a factor e [N].
    """

    gain: Float[ArrayLike, ""]
    load_scale_n: Float[ArrayLike, ""]
    fit_params: ClassVar[tuple[Param, ...]] = (
        GAIN,
        Param(
            "load_scale_n",
            "N",
            "log",
            1.0,
            1e5,
            description="normal load over which the slip amplitude falls by a factor e",
        ),
    )

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


@TRUTH_ONLY_COUPLINGS.register("tanh_ceiling")
class TanhCeilingCoupling(AbstractCoupling):
    """Truth only: ``a = gain * A_max * c * tanh(alpha / c)``, ``c = sqrt(L / N)`` [m].

    Attributes:
        gain: slip amplitude per commanded horn amplitude at small amplitude [-].
        ceiling_load_n: load scale L [N]: at the load L the ceiling is the full command.
    """

    gain: Float[ArrayLike, ""]
    ceiling_load_n: Float[ArrayLike, ""]
    fit_params: ClassVar[tuple[Param, ...]] = (
        GAIN,
        Param(
            "ceiling_load_n",
            "N",
            "log",
            1.0,
            1e5,
            description="load scale L of the ceiling c = sqrt(L / N) of the commanded "
            "amplitude fraction",
        ),
    )

    @classmethod
    def from_values(cls, values: Mapping[str, ArrayLike]) -> TanhCeilingCoupling:
        return cls(gain=values["coupling_gain"], ceiling_load_n=values["ceiling_load_n"])

    def amplitude_m(
        self,
        amplitude_fraction: Float[ArrayLike, "*b"],
        normal_load_n: Float[ArrayLike, "*b"],
        max_amplitude_m: Float[ArrayLike, ""],
    ) -> Float[Array, "*b"]:
        alpha = jnp.asarray(amplitude_fraction)
        # the ceiling as a commanded fraction; a zero load (no contact) has none
        c = jnp.sqrt(jnp.asarray(self.ceiling_load_n) / jnp.maximum(normal_load_n, 1e-9))
        return jnp.asarray(self.gain * max_amplitude_m * c * jnp.tanh(alpha / c))
