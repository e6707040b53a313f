"""Which model a fit is: one typed record of the registered names of its parts.

A candidate of the model choice is named in ``fit.json`` (``model_comparison``,
``coupling_laws``) and in the run's progress by its key ``law/coupling/actuator/offset``,
then ``/level`` unless the levels are steady (so keys stay what they were before the
level models). :meth:`ModelSpec.key` writes it and :meth:`ModelSpec.from_key` reads it:
the one place the key's format lives, everything else passes the record. The key names
neither the noise model nor the direction of vibration: every candidate of a run shares
them.
"""

from __future__ import annotations

import dataclasses

from idtool._data._blocks import FitData
from idtool._model._benchmodel import BenchModel, bench_model
from idtool._model._names import DEFAULT_DIRECTION, DEFAULT_NOISE
from idtool._model._settings import ParameterSetting

__all__ = ["ModelSpec"]

_SEPARATOR = "/"
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
        """The candidate's name, ``law/coupling/actuator/offset[/level]`` (as in
        ``fit.json``'s ``model_comparison`` and ``coupling_laws``)."""
        parts = [self.law, self.coupling, self.actuator, self.offset]
        if self.level != _STEADY:
            parts.append(self.level)
        return _SEPARATOR.join(parts)

    @classmethod
    def from_key(
        cls,
        key: str,
        noise: str = DEFAULT_NOISE,
        settings: tuple[ParameterSetting, ...] = (),
        direction: str = DEFAULT_DIRECTION,
    ) -> ModelSpec:
        """The spec named by ``key`` (:attr:`key`; a key of four parts, written before
        the level models, has steady levels), with the ``noise`` model, ``settings`` and
        ``direction`` the key does not name."""
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
