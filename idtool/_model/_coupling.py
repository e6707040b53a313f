"""Coupling laws: commanded horn amplitude -> effective contact slip amplitude (notes §5).

The bench vibrates the webbing normal to the sliding, while the contact model
(:func:`idtool.prescribed_cycle_average`) needs a slip amplitude along it. The link is
an effective coupling to identify from the traces. Two nested laws:

* :class:`ConstantCoupling`: ``a = gain * alpha * A_max``;
* :class:`PowerLimitedCoupling`: ``a = gain * alpha * A_max / sqrt(1 + (alpha N / P)^2)``.
  At small ``alpha N`` it is the constant law; at large ``alpha N`` the amplitude
  saturates at ``gain * A_max * P / N``: it no longer grows with the commanded amplitude
  and falls with the normal load, as the paper reports (the welder's power limits the
  effect; 50% and 70% amplitude differ little at 450 N). ``P -> inf`` recovers the
  constant law, so the two are nested.

``alpha`` is the commanded amplitude fraction in [0, 1], ``A_max`` the horn's maximum
amplitude [m], ``N`` the normal load [N].
"""

from __future__ import annotations

import abc
from collections.abc import Mapping
from typing import ClassVar

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

from idtool._model._params import Param
from idtool._registry import Registry

__all__ = ["COUPLINGS", "GAIN", "AbstractCoupling", "ConstantCoupling", "PowerLimitedCoupling"]

COUPLINGS: Registry[type[AbstractCoupling]] = Registry("coupling law")

GAIN = Param(
    "coupling_gain",
    "1",
    "log",
    1e-5,
    1.0,
    physical=True,
    start=0.01,
    description="slip amplitude per commanded horn amplitude (small-signal)",
)


class AbstractCoupling(eqx.Module):
    """Maps an operating point to the effective slip amplitude [m].

    Every law has a dimensionless ``gain`` that the amplitude is proportional to (the
    fit places its start through a velocity ratio below 1, see
    :func:`idtool._fit._starts.start_point`) and declares its parameters in
    ``fit_params``, ``coupling_gain`` first.
    """

    gain: eqx.AbstractVar[Float[ArrayLike, ""]]
    name: ClassVar[str] = ""
    fit_params: ClassVar[tuple[Param, ...]] = (GAIN,)

    @classmethod
    @abc.abstractmethod
    def from_values(cls, values: Mapping[str, Array]) -> AbstractCoupling:
        """The law from parameter values by name (its ``fit_params``)."""

    @abc.abstractmethod
    def amplitude_m(
        self,
        amplitude_fraction: Float[ArrayLike, "*b"],
        normal_load_n: Float[ArrayLike, "*b"],
        max_amplitude_m: Float[ArrayLike, ""],
    ) -> Float[Array, "*b"]:
        """Effective slip amplitude [m] seen by the contact model."""


@COUPLINGS.register("constant")
class ConstantCoupling(AbstractCoupling):
    """``a = gain * alpha * A_max``; ``gain`` is dimensionless."""

    gain: Float[ArrayLike, ""]

    @classmethod
    def from_values(cls, values):
        return cls(gain=values["coupling_gain"])

    def amplitude_m(self, amplitude_fraction, normal_load_n, max_amplitude_m):
        shape = jnp.broadcast_shapes(jnp.shape(amplitude_fraction), jnp.shape(normal_load_n))
        return jnp.broadcast_to(
            self.gain * jnp.asarray(amplitude_fraction) * max_amplitude_m, shape
        )


@COUPLINGS.register("power-limited")
class PowerLimitedCoupling(AbstractCoupling):
    """``a = gain * alpha * A_max / sqrt(1 + (alpha N / P)^2)``.

    Attributes:
        gain: small-signal coupling (dimensionless), as in :class:`ConstantCoupling`.
        power_load_n: load scale P [N] of the power limit; larger is weaker.
    """

    gain: Float[ArrayLike, ""]
    power_load_n: Float[ArrayLike, ""]
    fit_params: ClassVar[tuple[Param, ...]] = (
        GAIN,
        Param(
            "power_load_n",
            "N",
            "log",
            1.0,
            1e5,
            physical=True,
            start=300.0,
            start_box=(20.0, 2000.0),
            description="load scale P of the power limit",
        ),
    )

    @classmethod
    def from_values(cls, values):
        return cls(gain=values["coupling_gain"], power_load_n=values["power_load_n"])

    def amplitude_m(self, amplitude_fraction, normal_load_n, max_amplitude_m):
        alpha = jnp.asarray(amplitude_fraction)
        x = alpha * jnp.asarray(normal_load_n) / self.power_load_n
        return self.gain * alpha * max_amplitude_m / jnp.sqrt(1.0 + x**2)
