"""The constant coupling: ``a = gain * alpha * A_max`` (notes §5)."""

from __future__ import annotations

import jax.numpy as jnp
from jaxtyping import ArrayLike, Float

from idtool._model._coupling import COUPLINGS, AbstractCoupling

__all__ = ["ConstantCoupling"]


@COUPLINGS.register("constant")
class ConstantCoupling(AbstractCoupling):
    """``a = gain * alpha * A_max`` [m]; ``gain`` is dimensionless."""

    gain: Float[ArrayLike, ""]

    @classmethod
    def from_values(cls, values):
        return cls(gain=values["coupling_gain"])

    def amplitude_m(self, amplitude_fraction, normal_load_n, max_amplitude_m):
        shape = jnp.broadcast_shapes(jnp.shape(amplitude_fraction), jnp.shape(normal_load_n))
        return jnp.broadcast_to(
            self.gain * jnp.asarray(amplitude_fraction) * max_amplitude_m, shape
        )
