"""The simulator's typed records of the registered parts: one frozen dataclass per
friction law, coupling law, actuator model and noise model, made from the part's
``truth_fields`` (:mod:`idtool._model._truth_fields`).

A bench's ``contact`` is the record of its friction law (``DahlParams`` with
``friction_coefficient`` and ``contact_stiffness_n_m``), its ``coupling`` that of its
coupling law (``PowerLimitedCouplingParams`` with ``gain`` and ``power_load_n``), its
``actuator`` that of its actuator model, its optional ``block_mean_noise`` that of a
noise model (``AR1NoiseParams`` with ``sigma_n`` and ``phi``): each holds exactly its
part's numbers, and builds the part (:meth:`ContactParams.law_at`,
:meth:`CouplingParams.coupling`, :meth:`ActuatorParams.actuator`,
:meth:`BlockNoiseParams.noise`). A part registered later (a test's toy coupling law)
gets its record on first use, so the simulator has no list of parts of its own.

The file names the parts by their registered names; a coupling law of the fit's registry
with ``_`` for ``-`` (``power_limited``, as the files had it before the registries), and
the simulator's truth-only laws (:mod:`idtool._simulate._truth_coupling`) beside them;
a noise model by its registered name as is (``ar1-student-t``, as ``idtool fit --noise``
takes it).
"""

from __future__ import annotations

import dataclasses
import functools
from collections.abc import Mapping
from typing import Any, ClassVar

from jaxtyping import ArrayLike

from idtool._errors import IdtoolError
from idtool._model._actuator import ACTUATORS, AbstractActuator
from idtool._model._coupling import COUPLINGS, AbstractCoupling
from idtool._model._directions import DIRECTIONS, AbstractDirection
from idtool._model._laws import FRICTION_LAWS, AbstractFrictionLaw
from idtool._model._names import DEFAULT_ACTUATOR, DEFAULT_DIRECTION
from idtool._model._noise import NOISE_MODELS, AbstractNoise
from idtool._simulate._truth_coupling import TRUTH_ONLY_COUPLINGS

__all__ = [
    "ActuatorParams",
    "BlockNoiseParams",
    "ContactParams",
    "CouplingParams",
    "actuator_models",
    "actuator_record",
    "contact_record",
    "coupling_laws",
    "coupling_record",
    "friction_laws",
    "noise_models",
    "noise_record",
]


@dataclasses.dataclass(frozen=True, kw_only=True)
class _PartParams:
    """A part's numbers by their file names (its ``truth_fields``)."""

    part: ClassVar[type[Any]]

    def values(self) -> dict[str, float]:
        """The part's numbers by file name."""
        return {f.name: getattr(self, f.name) for f in self.part.truth_fields()}


@dataclasses.dataclass(frozen=True, kw_only=True)
class ContactParams(_PartParams):
    """The true contact: the friction law ``friction_law`` with its numbers (mu as
    ``friction_coefficient`` [-], ...); optionally mu creeping by
    ``level_creep_per_s`` [1/s] of itself per second of sliding
    (:mod:`idtool._simulate._plateau_drift`); the vibration in ``direction`` (a name of
    :data:`idtool.DIRECTIONS`, default along the sliding)."""

    part: ClassVar[type[AbstractFrictionLaw]]
    friction_law: str
    friction_coefficient: float
    level_creep_per_s: float = 0.0
    direction: str = DEFAULT_DIRECTION

    @property
    def direction_model(self) -> type[AbstractDirection]:
        """The direction of vibration's class (:data:`idtool.DIRECTIONS`)."""
        return DIRECTIONS.get(self.direction)

    def law_at(
        self, normal_load_n: ArrayLike, friction_coefficient: ArrayLike | None = None
    ) -> AbstractFrictionLaw:
        """The law under ``normal_load_n`` [N] (``Fc = mu N``), its mu replaced by
        ``friction_coefficient`` when given (a trace's scattered mu)."""
        values: dict[str, Any] = self.values()
        if friction_coefficient is not None:
            values["friction_coefficient"] = friction_coefficient
        return self.part.truth_at_load(values, normal_load_n)


@dataclasses.dataclass(frozen=True, kw_only=True)
class CouplingParams(_PartParams):
    """Horn amplitude -> slip amplitude: the coupling law ``law`` with its numbers."""

    part: ClassVar[type[AbstractCoupling]]
    law: str

    @property
    def in_fit(self) -> bool:
        """Whether the fit ships this law (else the simulation is deliberately misspecified)."""
        return self.law not in TRUTH_ONLY_COUPLINGS

    def coupling(self, max_amplitude_m: float) -> AbstractCoupling:
        """The law; ``max_amplitude_m`` [m], the rig's horn amplitude at 100% command."""
        return self.part.from_truth(self.values(), max_amplitude_m)


@dataclasses.dataclass(frozen=True, kw_only=True)
class ActuatorParams(_PartParams):
    """The pneumatic actuator: when the pull starts [s] and the ``model`` the force
    follows its target by, with its numbers."""

    part: ClassVar[type[AbstractActuator]]
    pull_start_s: float
    model: str = DEFAULT_ACTUATOR

    def actuator(self) -> AbstractActuator:
        """The actuator model."""
        return self.part.from_truth(self.values())


@dataclasses.dataclass(frozen=True, kw_only=True)
class BlockNoiseParams(_PartParams):
    """Block-mean noise drawn from the registered noise model ``model`` with its numbers
    (``sigma_n`` [N], the innovation scale, and the model's own), added on the fit's
    blocks (:mod:`idtool._simulate._block_noise`)."""

    part: ClassVar[type[AbstractNoise]]
    model: str

    def noise(self) -> AbstractNoise:
        """The noise model (stateless: its numbers are :meth:`values`)."""
        return self.part()


def friction_laws() -> dict[str, type[AbstractFrictionLaw]]:
    """The friction laws the simulator simulates, by file name."""
    return {name: FRICTION_LAWS.get(name) for name in FRICTION_LAWS}


def coupling_laws() -> dict[str, type[AbstractCoupling]]:
    """The coupling laws the simulator simulates, by file name: the fit's, then the
    truth-only ones."""
    out = {name.replace("-", "_"): COUPLINGS.get(name) for name in COUPLINGS}
    return out | {name: TRUTH_ONLY_COUPLINGS.get(name) for name in TRUTH_ONLY_COUPLINGS}


def actuator_models() -> dict[str, type[AbstractActuator]]:
    """The actuator models the simulator simulates, by file name."""
    return {name: ACTUATORS.get(name) for name in ACTUATORS}


def noise_models() -> dict[str, type[AbstractNoise]]:
    """The noise models the simulator draws block-mean noise from, by file name (the
    registered name)."""
    return {name: NOISE_MODELS.get(name) for name in NOISE_MODELS}


@functools.cache
def _record(base: Any, part: Any) -> type[_PartParams]:
    """The record of ``part``: ``base``'s fields, then the part's truth fields."""
    taken = {f.name for f in dataclasses.fields(base)}
    fields: list[tuple[str, type, Any]] = [
        (
            f.name,
            float,
            dataclasses.field(default=f.default) if f.default is not None else dataclasses.field(),
        )
        for f in part.truth_fields()
        if f.name not in taken
    ]
    name = f"{part.__name__}Params"
    cls = dataclasses.make_dataclass(
        name, fields, bases=(base,), frozen=True, kw_only=True, namespace={"part": part}
    )
    cls.__module__ = __name__
    cls.__doc__ = f"The simulator's record of {part.__module__}.{part.__qualname__}."
    globals().setdefault(name, cls)  # found by name, so a record pickles
    return cls


def _build(base: Any, part: Any, kind: Mapping[str, str], section: Mapping[str, Any]) -> Any:
    """The record of ``part`` from its file ``section``, ``kind`` the field naming it."""
    numbers = {f.name: float(section[f.name]) for f in part.truth_fields() if f.name in section}
    common = {
        k: v if isinstance(v, str) else float(v)  # a name (the contact's direction) as is
        for k, v in section.items()
        if k not in numbers and k not in kind
    }
    return _record(base, part)(**kind, **common, **numbers)


def contact_record(section: Mapping[str, Any]) -> ContactParams:
    """The contact record of a file's ``contact`` section (checked by the schema)."""
    name = section["friction_law"]
    law = _choose(friction_laws(), name, "friction law")
    return _build(ContactParams, law, {"friction_law": name}, section)  # type: ignore[return-value]


def coupling_record(section: Mapping[str, Any]) -> CouplingParams:
    """The coupling record of a file's ``coupling`` section (checked by the schema)."""
    name = section["law"]
    law = _choose(coupling_laws(), name, "coupling law")
    return _build(CouplingParams, law, {"law": name}, section)  # type: ignore[return-value]


def actuator_record(section: Mapping[str, Any]) -> ActuatorParams:
    """The actuator record of a file's ``actuator`` section (checked by the schema)."""
    name = section.get("model", DEFAULT_ACTUATOR)
    model = _choose(actuator_models(), name, "actuator model")
    return _build(ActuatorParams, model, {"model": name}, section)  # type: ignore[return-value]


def noise_record(section: Mapping[str, Any]) -> BlockNoiseParams:
    """The block-noise record of a file's ``block_mean_noise`` section (checked by the
    schema)."""
    name = section["model"]
    model = _choose(noise_models(), name, "noise model")
    return _build(BlockNoiseParams, model, {"model": name}, section)  # type: ignore[return-value]


def _choose(parts: Mapping[str, type[Any]], name: str, kind: str) -> type[Any]:
    try:
        return parts[name]
    except KeyError:
        raise IdtoolError(f"unknown {kind} {name!r}: choose one of {', '.join(parts)}") from None


def __getattr__(name: str) -> type[_PartParams]:
    """A part's record by its class name (``DahlParams``), made on first use: how a
    record pickled in one process is found in another (a worker of a study)."""
    kinds = (
        (ContactParams, friction_laws()),
        (CouplingParams, coupling_laws()),
        (ActuatorParams, actuator_models()),
        (BlockNoiseParams, noise_models()),
    )
    for base, parts in kinds:
        for part in parts.values():
            if f"{part.__name__}Params" == name:
                return _record(base, part)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
