"""Load-cell offset models: what the load cell reads with no force on it (issue 10).

A load cell's zero is not fixed: it moves between pulls (each trace has its own offset,
measured by the baseline before the pull) and, on a warming bridge or amplifier, drifts
slowly within a pull. A drift the fit does not model lands in the levels: the OFF level,
read seconds after the baseline, carries ``drift x elapsed time`` (0.25-0.5 N on the
simulated drift bench, 0.2-0.4% of mu at 450 N, random from pull to pull), and mu's
interval, built from the load cell's noise, misses the truth. Two nested models,
registered in :data:`OFFSETS`:

* ``constant`` (:class:`ConstantOffset`): one offset per trace, ``offset_n`` [N];
* ``drift`` (:class:`DriftingOffset`): plus a linear drift per trace,
  ``offset_drift_n_s`` [N/s], from the trace's first block on. Zero drift is the
  constant model, so the fit chooses between them by BIC where the data ask for it
  (``offset="auto"``, :func:`idtool._fit._run.fit_dataset`).

Each model declares its per-trace parameters (:attr:`AbstractOffset.trace_params`: name,
unit, internal scale; ``offset_n`` first in every model) and computes the offset from
their values, broadcast to the model's time points.
"""

from __future__ import annotations

import abc
from collections.abc import Mapping
from typing import ClassVar

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

from idtool._model._names import DEFAULT_OFFSET
from idtool._registry import Registry

__all__ = ["DEFAULT_OFFSET", "OFFSETS", "AbstractOffset", "ConstantOffset", "DriftingOffset"]

OFFSETS: Registry[type[AbstractOffset]] = Registry("load-cell offset model")

# (name, unit, internal scale): the internal value times the scale is the step from the
# data-driven centre. 0.01 N/s: a drift of 0.01 N/s moves a 12 s trace by 0.12 N, a
# fifth of the load cell's noise; the simulated drift bench's sd is 0.05 N/s.
OFFSET_N = ("offset_n", "N", 1.0)
OFFSET_DRIFT_N_S = ("offset_drift_n_s", "N/s", 0.01)


class AbstractOffset(eqx.Module):
    """A load-cell offset model (module docstring)."""

    name: ClassVar[str] = ""
    trace_params: ClassVar[tuple[tuple[str, str, float], ...]] = (OFFSET_N,)

    @staticmethod
    @abc.abstractmethod
    def offset_n(
        values: Mapping[str, Float[ArrayLike, "*b"]],
        time_s: Float[ArrayLike, "*b"],
        start_s: Float[ArrayLike, "*b"],
    ) -> Float[Array, "*b"]:
        """The offset [N] at ``time_s`` [s] from the trace's ``trace_params`` values
        (broadcast to the time points); ``start_s`` [s] is its first block's time."""


@OFFSETS.register("constant")
class ConstantOffset(AbstractOffset):
    """One offset per trace [N]."""

    @staticmethod
    def offset_n(values, time_s, start_s):
        return jnp.asarray(values["offset_n"])


@OFFSETS.register("drift")
class DriftingOffset(AbstractOffset):
    """One offset per trace [N] at its first block, drifting linearly at
    ``offset_drift_n_s`` [N/s] through the trace."""

    trace_params = (OFFSET_N, OFFSET_DRIFT_N_S)

    @staticmethod
    def offset_n(values, time_s, start_s):
        elapsed = jnp.asarray(time_s) - jnp.asarray(start_s)
        return jnp.asarray(values["offset_n"]) + jnp.asarray(values["offset_drift_n_s"]) * elapsed
