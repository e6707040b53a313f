"""Sine and cosine of the contact's phase grid, as polynomials XLA:CPU vectorises.

The cycle average (:mod:`idtool._model._contact`) evaluates cosines and sines at every
step of its phase grid: 2 x 256 steps per operating point, three trigonometric calls per
step, for every walker of the sampler and every Jacobian column of the fit. XLA:CPU
calls a scalar routine for each (11-34 ns per element on this project's 2-core
machine, as slow as NumPy's), where the polynomial below runs in 1.2-2.8 ns: the
friction-ratio kernel took 2.2-2.7x less time on 240 operating points (3.8-5.5 ms ->
1.6-2.6 ms), with friction ratios equal to 2e-16 and gradients to 4e-15 of their
largest value (``benchmarks/bench_trig.py``).

Method (Cody & Waite 1980): the argument is reduced by the nearest multiple ``q`` of
pi/2, with pi/2 split in three doubles so that ``r = x - q pi/2`` keeps full precision;
on ``|r| <= pi/4`` the Taylor series of sine (to r^17) and cosine (to r^16) are below
one rounding of 1 (their first omitted terms are 8e-20 and 2e-18); the quadrant
``q mod 4`` picks the sign and the function. Within 2.3e-16 (two roundings of a value
of size 1) of NumPy's for ``|x| <= 1e6`` (``tests/test_trig.py``), far beyond the
phases used here (0 to 4 pi). Not for general use: no handling of infinities or of
huge arguments.
"""

from __future__ import annotations

import math

import jax.numpy as jnp
from jaxtyping import Array, ArrayLike

__all__ = ["cos", "sin"]

# pi/2 in three parts (fdlibm's __ieee754_rem_pio2): the first two have 33 bits, so
# their products with q (|q| < 2^20) are exact, and the third carries the rest
_PIO2_1 = 1.57079632673412561417e00
_PIO2_2 = 6.07710050630396597660e-11
_PIO2_2T = 2.02226624879595063154e-21
# Taylor coefficients, highest power first (Horner): sin(r) / r and cos(r) in r^2
_SIN = tuple((-1) ** k / math.factorial(2 * k + 1) for k in range(8, -1, -1))
_COS = tuple((-1) ** k / math.factorial(2 * k) for k in range(8, -1, -1))


def _horner(z: Array, coefficients: tuple[float, ...]) -> Array:
    acc = jnp.full_like(z, coefficients[0])
    for c in coefficients[1:]:
        acc = acc * z + c
    return acc


def _reduced(x: ArrayLike) -> tuple[Array, Array, Array]:
    """Quadrant ``q mod 4`` of ``x`` and sin, cos of its remainder on [-pi/4, pi/4]."""
    x = jnp.asarray(x, float)
    q = jnp.round(x * (2.0 / math.pi))
    r = ((x - q * _PIO2_1) - q * _PIO2_2) - q * _PIO2_2T
    z = r * r
    return jnp.mod(q, 4.0), r * _horner(z, _SIN), _horner(z, _COS)


def cos(x: ArrayLike) -> Array:
    """``cos(x)`` elementwise (module docstring: accuracy, range)."""
    m, s, c = _reduced(x)
    return jnp.where(m == 0.0, c, jnp.where(m == 1.0, -s, jnp.where(m == 2.0, -c, s)))


def sin(x: ArrayLike) -> Array:
    """``sin(x)`` elementwise (module docstring: accuracy, range)."""
    m, s, c = _reduced(x)
    return jnp.where(m == 0.0, s, jnp.where(m == 1.0, c, jnp.where(m == 2.0, -s, -c)))
