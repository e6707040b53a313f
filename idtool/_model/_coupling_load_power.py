"""The power-limited coupling with a load exponent:
``a = gain * alpha * A_max * (N_REF / N)^beta / sqrt(1 + (alpha N / P)^2)``.

The shipped saturating laws fix how the slip amplitude depends on the normal load: not
at all below the knee, ``1 / N`` above it. A bench whose contact damps the horn more
under a heavier load (the webbing pressed harder against the horn's face) loses slip
amplitude with the load at every commanded amplitude, and the fit can then only bend
FR's load dependence through Kt (Lambda = Kt a / (mu N)): Kt came out 0.25-0.4x its
truth, outside its interval, on simulated benches whose coupling falls exponentially
with the load. The exponent ``beta`` lets the data set that dependence, so that Kt's
interval carries what the load dependence leaves unknown. ``beta = 0`` is the power
limit, which it nests; ``beta = 0`` and ``P -> inf``, the constant law.
"""

from __future__ import annotations

from typing import ClassVar

import jax.numpy as jnp
from jaxtyping import ArrayLike, Float

from idtool._model._coupling import COUPLINGS, GAIN, AbstractCoupling, load_scale_param
from idtool._model._params import Param

__all__ = ["LoadPowerCoupling"]

# The reference load of the exponent [N]: the middle of the paper's loads (270-670 N),
# so that ``gain`` keeps its meaning (the small-signal coupling there) whatever beta.
N_REF = 450.0


@COUPLINGS.register("load-power")
class LoadPowerCoupling(AbstractCoupling):
    """``a = gain * alpha * A_max * (N_REF / N)^beta / sqrt(1 + (alpha N / P)^2)`` [m].

    Attributes:
        gain: small-signal coupling at the reference load ``N_REF`` = 450 N [-].
        load_exponent: beta [-], how fast the small-signal coupling falls with the load.
        power_load_n: load scale P [N] of the power limit; larger is weaker.
    """

    gain: Float[ArrayLike, ""]
    load_exponent: Float[ArrayLike, ""]
    power_load_n: Float[ArrayLike, ""]
    fit_params: ClassVar[tuple[Param, ...]] = (
        GAIN,
        Param(
            "load_exponent",
            "1",
            "tanh",
            -2.0,
            4.0,
            physical=True,
            start=0.0,
            nested_at=0.0,
            description="exponent beta of the small-signal coupling's fall with the load",
        ),
        load_scale_param("power_load_n", "load scale P of the power limit"),
    )

    @classmethod
    def from_values(cls, values):
        return cls(
            gain=values["coupling_gain"],
            load_exponent=values["load_exponent"],
            power_load_n=values["power_load_n"],
        )

    def amplitude_m(self, amplitude_fraction, normal_load_n, max_amplitude_m):
        alpha = jnp.asarray(amplitude_fraction)
        load = jnp.asarray(normal_load_n)
        x = alpha * load / self.power_load_n
        # (N_REF / N)^beta; a zero load (no contact) keeps the small-signal gain finite
        beta = jnp.asarray(self.load_exponent)
        fall = jnp.exp(-beta * jnp.log(jnp.maximum(load, 1e-9) / N_REF))
        return self.gain * alpha * max_amplitude_m * fall / jnp.sqrt(1.0 + x**2)
