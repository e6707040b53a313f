"""Closed-form limits of the vibrated contact (model notes §4).

These are independent of the numerical solvers and serve as their checks.
All take the velocity ratio VR = v / (a w) >= 0 (dimensionless).
"""

from __future__ import annotations

import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

__all__ = [
    "coulomb_friction_ratio",
    "coulomb_perpendicular_friction_ratio",
    "coulomb_power_ratio",
    "dahl_small_lambda_friction_ratio",
    "ellipk",
    "mean_abs_slip_rate",
]


def coulomb_friction_ratio(vr: Float[ArrayLike, "*b"]) -> Float[Array, "*b"]:
    """Coulomb, vibration along the sliding: FR = (2/pi) arcsin(VR), 1 for VR >= 1."""
    vr = jnp.asarray(vr, float)
    return jnp.where(vr < 1.0, 2.0 / jnp.pi * jnp.arcsin(jnp.clip(vr, 0.0, 1.0)), 1.0)


def mean_abs_slip_rate(vr: Float[ArrayLike, "*b"]) -> Float[Array, "*b"]:
    """Cycle mean of |VR + cos(theta)|: (2/pi)(sqrt(1 - VR^2) + VR arcsin VR), VR for VR >= 1."""
    vr = jnp.asarray(vr, float)
    c = jnp.clip(vr, 0.0, 1.0)
    below = 2.0 / jnp.pi * (jnp.sqrt(1.0 - c**2) + c * jnp.arcsin(c))
    return jnp.where(vr < 1.0, below, vr)


def coulomb_power_ratio(vr: Float[ArrayLike, "*b"]) -> Float[Array, "*b"]:
    """Coulomb power dissipation ratio: mean |V| / v = mean_abs_slip_rate(VR) / VR."""
    vr = jnp.asarray(vr, float)
    return mean_abs_slip_rate(vr) / vr


def dahl_small_lambda_friction_ratio(vr: Float[ArrayLike, "*b"]) -> Float[Array, "*b"]:
    """Dahl as Lambda -> 0: FR = VR / ((2/pi)(sqrt(1 - VR^2) + VR arcsin VR)).

    About (pi/2) VR for small VR: Dahl creeps, so even an amplitude below the
    pre-sliding length Fc/Kt lowers the mean friction.
    """
    vr = jnp.asarray(vr, float)
    return vr / mean_abs_slip_rate(vr)


def ellipk(m: Float[ArrayLike, "*b"]) -> Float[Array, "*b"]:
    """Complete elliptic integral of the first kind K(m), parameter convention, m < 1.

    By the arithmetic-geometric mean, K(m) = pi / (2 AGM(1, sqrt(1 - m))); 16 steps of
    the quadratically converging AGM reach double precision for 1 - m down to 1e-12.
    """
    a = jnp.ones_like(jnp.asarray(m, float))
    b = jnp.sqrt(1.0 - jnp.asarray(m, float))
    for _ in range(16):
        a, b = 0.5 * (a + b), jnp.sqrt(a * b)
    return jnp.pi / (2.0 * a)


def coulomb_perpendicular_friction_ratio(vr: Float[ArrayLike, "*b"]) -> Float[Array, "*b"]:
    """Coulomb, in-plane vibration perpendicular to the sliding.

    FR = (2/pi) VR / sqrt(1 + VR^2) K(1 / (1 + VR^2)), K the complete elliptic integral
    of the first kind with parameter m; it tends to 1 only as VR -> infinity.
    """
    vr = jnp.asarray(vr, float)
    return 2.0 / jnp.pi * vr / jnp.sqrt(1.0 + vr**2) * ellipk(1.0 / (1.0 + vr**2))
