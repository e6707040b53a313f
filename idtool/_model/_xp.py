"""One formula for the host and for JAX: NumPy on plain numbers, JAX under tracing.

A fit's bookkeeping (start values, summaries, delta-method errors) evaluates the same
transforms and coordinates as the jitted model, on a handful of numbers. Done with
``jax.numpy`` there, each operation dispatches a compiled program of its own (~25 ms
to compile on a cold start, ~8 ms to trace and load from the cache on a warm one:
~70 of them cost a cold ``idtool fit`` of the example 1.9 s). NumPy costs
microseconds.
"""

from __future__ import annotations

from types import ModuleType

import jax
import jax.numpy as jnp
import numpy as np

__all__ = ["sigmoid", "softplus", "xp"]


def xp(*arrays: object) -> ModuleType:
    """``jax.numpy`` if any of ``arrays`` is a JAX array or tracer, else ``numpy``."""
    return jnp if any(isinstance(a, jax.Array) for a in arrays) else np


def sigmoid(z):
    """``1 / (1 + exp(-z))``, stable for large ``|z|`` (JAX or NumPy by argument)."""
    if xp(z) is jnp:
        return jax.nn.sigmoid(z)
    return np.exp(-np.logaddexp(0.0, -np.asarray(z, float)))


def softplus(z):
    """``log(1 + exp(z))``, stable for large ``|z|`` (JAX or NumPy by argument)."""
    if xp(z) is jnp:
        return jax.nn.softplus(z)
    return np.logaddexp(0.0, np.asarray(z, float))
