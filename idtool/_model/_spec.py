"""Which model a fit is: one typed record of the registered names of its parts.

A candidate of the model choice is named in ``fit.json`` (``model_comparison``,
``coupling_laws``) and in the run's progress by its key ``law/coupling/actuator/offset``,
then ``/level`` unless the levels are steady (so keys stay what they were before the
level models), then ``@direction`` unless the vibration is along the sliding (so the
candidates of ``direction="auto"`` have keys of their own, and an along fit's keys stay
what they were). :meth:`ModelSpec.key` writes it and :meth:`ModelSpec.from_key` reads it:
the one place the key's format lives, everything else passes the record. The key does
not name the noise model: every candidate of a run shares it.
"""

from __future__ import annotations

import dataclasses

from idtool._data._blocks import FitData
from idtool._model._benchmodel import BenchModel, bench_model
from idtool._model._names import DEFAULT_DIRECTION, DEFAULT_NOISE
from idtool._model._settings import ParameterSetting

__all__ = ["ModelSpec"]

_SEPARATOR = "/"
_DIRECTION = "@"
# the level model a key leaves out (keys written before the level models name none)
_STEADY = "steady"


@dataclasses.dataclass(frozen=True)
class ModelSpec:
    """Which model a fit is, by registered name: friction law, coupling law, noise,
    actuator, offset and level models, the user's parameter settings and the direction
    of vibration."""

    law: str
    coupling: str
    noise: str
    actuator: str
    offset: str
    level: str
    settings: tuple[ParameterSetting, ...] = ()
    direction: str = DEFAULT_DIRECTION

    @property
    def key(self) -> str:
        """The candidate's name, ``law/coupling/actuator/offset[/level][@direction]``
        (as in ``fit.json``'s ``model_comparison`` and ``coupling_laws``)."""
        parts = [self.law, self.coupling, self.actuator, self.offset]
        if self.level != _STEADY:
            parts.append(self.level)
        key = _SEPARATOR.join(parts)
        return key if self.direction == DEFAULT_DIRECTION else f"{key}{_DIRECTION}{self.direction}"

    @classmethod
    def from_key(
        cls,
        key: str,
        noise: str = DEFAULT_NOISE,
        settings: tuple[ParameterSetting, ...] = (),
        direction: str = DEFAULT_DIRECTION,
    ) -> ModelSpec:
        """The spec named by ``key`` (:attr:`key`; a key of four parts, written before
        the level models, has steady levels), with the ``noise`` model and ``settings``
        the key does not name; ``direction`` where the key names none (a key written
        before the direction was part of it)."""
        key, named, direction_named = key.partition(_DIRECTION)
        direction = direction_named if named else direction
        law, coupling, actuator, offset, *rest = key.split(_SEPARATOR)
        level = rest[0] if rest else _STEADY
        return cls(law, coupling, noise, actuator, offset, level, settings, direction)

    def build(self, data: FitData) -> BenchModel:
        """The :class:`BenchModel` of ``data`` this spec names."""
        return bench_model(
            data,
            self.law,
            self.coupling,
            self.noise,
            self.actuator,
            self.offset,
            self.settings,
            self.level,
            self.direction,
        )
