"""The fields a registered part (friction law, coupling law, actuator, noise model) takes
in the simulator's parameter file (``datasets_schema/simulator_params.schema.json``).

The simulator builds the true bench from the same registered classes the fit fits, so a
part declares once which numbers set it: by default its fit parameters (``fit_params``),
some under the file's older names (``gain`` for the coupling gain, ``friction_coefficient``
for mu). The simulator makes each part's typed record and its JSON Schema from these
fields (:mod:`idtool._simulate._records`, :mod:`idtool._simulate._schema`).
"""

from __future__ import annotations

import dataclasses
from typing import Any

from idtool._model._params import Param

__all__ = ["TruthField"]


@dataclasses.dataclass(frozen=True)
class TruthField:
    """One number of a part in the simulator's parameter file.

    Attributes:
        name: the field's name in the file.
        unit: SI unit ("1" for dimensionless).
        description: what it is, in words (the schema's description).
        positive: whether the value must be > 0 (else any number).
        default: the value when the file leaves the field out; None: required.
        bounds: the open interval ``(lo, hi)`` the value must lie in (a noise
            model's parameters: the range its likelihood is defined on), or None.
    """

    name: str
    unit: str
    description: str
    positive: bool = True
    default: float | None = None
    bounds: tuple[float, float] | None = None

    @classmethod
    def of(
        cls,
        param: Param,
        name: str | None = None,
        default: float | None = None,
        *,
        bounded: bool = False,
    ) -> TruthField:
        """The field of the fit parameter ``param`` (under ``name``, default its own):
        positive when the fit's transform keeps it so (``log``); with ``bounded``,
        inside the parameter's open range ``(lo, hi)`` as well."""
        return cls(
            name=param.name if name is None else name,
            unit=param.unit,
            description=param.description,
            positive=param.kind == "log",
            default=default,
            bounds=(param.lo, param.hi) if bounded and param.bounded else None,
        )

    def schema(self) -> dict[str, Any]:
        """The field's JSON Schema: a number, > 0 when :attr:`positive`, inside
        :attr:`bounds` when given."""
        out: dict[str, Any] = {"type": "number"}
        if self.positive:
            out["exclusiveMinimum"] = 0
        if self.bounds is not None:
            out["exclusiveMinimum"], out["exclusiveMaximum"] = self.bounds
        if self.default is not None:
            out["default"] = self.default
        unit = "-" if self.unit == "1" else self.unit
        optional = "" if self.default is None else f"Optional, default {self.default:g}: "
        out["description"] = (
            f"{optional}{self.description[:1].upper()}{self.description[1:]} [{unit}]."
        )
        return out
