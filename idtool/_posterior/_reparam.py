"""The interface of a levels posterior sampled on other coordinates (issue 26): along a
profiled ridge (:class:`~idtool._posterior._ridge.RidgeTarget`) or with the
discrepancy's funnel opened (:class:`~idtool._posterior._funnel.FunnelTarget`).

The walkers hold ``x``; ``to_internal`` maps them to the base target's internal vectors
``theta`` and ``from_internal`` back; ``log_posterior_batch`` is the base's density at
``theta(x)`` plus the log-determinant of the map's Jacobian; ``to_doc`` records the map
in ``chain.h5`` (with its formula), so that a resumed chain and a reader without idtool
rebuild it. The parameters, their names and priors are the base's.
"""

from __future__ import annotations

import abc
from typing import Any

import equinox as eqx
from jaxtyping import Array

from idtool._model._params import Param

__all__ = ["AbstractReparameterised"]


class AbstractReparameterised(eqx.Module):
    """A levels target on the walkers' own coordinates (module docstring)."""

    base: eqx.AbstractVar[Any]  # the LevelsTarget

    @property
    def params(self) -> tuple[Param, ...]:
        return self.base.params

    @property
    def names(self) -> tuple[str, ...]:
        return self.base.names

    @property
    def priors(self) -> tuple[Any, ...]:
        return self.base.priors

    @abc.abstractmethod
    def to_internal(self, x: Array) -> Array:
        """Internal vectors ``theta`` (..., ndim) of the walkers' ``x``."""

    @abc.abstractmethod
    def from_internal(self, theta: Array) -> Array:
        """The walkers' ``x`` of internal vectors ``theta`` (..., ndim)."""

    @abc.abstractmethod
    def log_posterior_batch(self, x: Array) -> Array:
        """The base's log-posterior at ``theta(x)`` plus ``log |d theta / d x|``."""

    @abc.abstractmethod
    def to_doc(self) -> dict:
        """The map as data, with its formula (recorded with the chain)."""
