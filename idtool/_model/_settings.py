"""A user's settings for the shared parameters: fixed values, bounds, scale, start, prior.

One :class:`ParameterSetting` per parameter, as a row of a PEtab-like parameter table
(:mod:`idtool._fit._parameter_table`) or ``--fix NAME=VALUE`` gives it. The bench model
applies them (:func:`apply_settings`): a fixed parameter leaves the internal vector ``z``
(the fit, the sampler and the AIC/BIC count one parameter fewer) and enters the physics
at its value; a bounded one gets a new range and transform (``lin``: tanh between the
bounds, ``log``: log-sigmoid), which the sampler's default prior follows; a start value
replaces the data-driven start and the multi-start's draws of that parameter.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Iterable, Mapping

from idtool._model._params import Param

__all__ = ["SCALES", "ParameterSetting", "apply_settings", "fixed_values"]

# PEtab's parameterScale values; log10 and log give the same transform (a log-sigmoid
# between the bounds does not depend on the logarithm's base).
SCALES = ("lin", "log", "log10")


@dataclasses.dataclass(frozen=True)
class ParameterSetting:
    """What the user says about one shared parameter (physical units, SI).

    Attributes:
        name: the parameter (``Kt``, ``mu``, ``coupling_gain``, ``slope_n_s``, ...).
        estimate: False fixes it at ``nominal``.
        nominal: the fixed value, or the start value of an estimated parameter.
        lower, upper: its range (default: idtool's, :mod:`idtool._model`).
        scale: ``"lin"`` or ``"log"`` (``"log10"``): the transform between the bounds.
        prior: the sampler's prior ``(dist, a, b)`` in :mod:`idtool._posterior._prior`'s
            terms, or None for the default.
        source: where it was given (file and row, or the option), for messages only.
    """

    name: str
    estimate: bool = True
    nominal: float | None = None
    lower: float | None = None
    upper: float | None = None
    scale: str | None = None
    prior: tuple[str, float, float] | None = None
    source: str = dataclasses.field(default="", compare=False)

    def __post_init__(self):
        if not self.estimate and self.nominal is None:
            raise ValueError(f"{self.name}: a fixed parameter needs its value (nominalValue)")
        if not self.estimate and self.prior is not None:
            raise ValueError(f"{self.name}: a fixed parameter takes no prior")
        if self.scale is not None and self.scale not in SCALES:
            raise ValueError(f"{self.name}: scale {self.scale!r} is not one of {', '.join(SCALES)}")
        for label, x in (("nominal", self.nominal), ("lower", self.lower), ("upper", self.upper)):
            if x is not None and not math.isfinite(x):
                raise ValueError(f"{self.name}: {label} value {x} is not a finite number")

    @property
    def fixed_label(self) -> str:
        """How reports say who fixed it: the rig's data, an assumption, or the user."""
        if self.source.startswith(("rig.", "assumed")):
            return f"fixed: {self.source}"
        return "fixed by the user"

    def apply(self, p: Param) -> Param:
        """``p`` with this setting's range, transform and start (``p`` estimated).

        Raises ValueError when the setting does not fit the parameter: bounds crossed, a
        log scale with a bound at or below zero, a start outside the range, or a
        per-trace nuisance (its transform is not bounded)."""
        if not p.bounded:
            raise ValueError(f"{self.name}: a per-trace nuisance cannot be set")
        lo = p.lo if self.lower is None else self.lower
        hi = p.hi if self.upper is None else self.upper
        scale = self.scale or ("log" if p.kind == "log" else "lin")
        kind = "tanh" if scale == "lin" else "log"
        if not lo < hi:
            raise ValueError(f"{self.name}: lowerBound {lo:g} must be below upperBound {hi:g}")
        if kind == "log" and lo <= 0.0:
            raise ValueError(
                f"{self.name}: a log scale needs a positive lowerBound (got {lo:g}); "
                "give a positive bound or parameterScale lin"
            )
        if self.nominal is not None and not lo <= self.nominal <= hi:
            raise ValueError(
                f"{self.name}: nominalValue {self.nominal:g} lies outside [{lo:g}, {hi:g}]"
            )
        box = p.start_box
        if self.nominal is not None:
            # a start the user gives is where every multi-start begins this parameter
            box = None
        elif box is not None:
            inner = (max(box[0], lo), min(box[1], hi))
            box = inner if inner[0] < inner[1] else (lo, hi)
        start = self.nominal if self.nominal is not None else min(max(p.start, lo), hi)
        nested = p.nested_at if p.nested_at is None or lo <= p.nested_at <= hi else None
        return dataclasses.replace(
            p, kind=kind, lo=lo, hi=hi, start=start, start_box=box, nested_at=nested
        )

    def check_fixed(self, p: Param) -> None:
        """Raise ValueError if the fixed value lies outside the range idtool (or the
        setting) allows the parameter."""
        assert self.nominal is not None
        lo = p.lo if self.lower is None else self.lower
        hi = p.hi if self.upper is None else self.upper
        if not p.bounded:
            raise ValueError(f"{self.name}: a per-trace nuisance cannot be fixed")
        if not lo <= self.nominal <= hi:
            raise ValueError(
                f"{self.name}: the fixed value {self.nominal:g} lies outside [{lo:g}, {hi:g}] "
                f"{p.unit}"
            )

    def to_dict(self) -> dict:
        """For ``fit.json`` (read back by :meth:`from_dict`)."""
        out: dict = {"name": self.name, "estimate": self.estimate}
        for key in ("nominal", "lower", "upper", "scale"):
            if getattr(self, key) is not None:
                out[key] = getattr(self, key)
        if self.prior is not None:
            out["prior"] = list(self.prior)
        if self.source:
            out["source"] = self.source
        return out

    @classmethod
    def from_dict(cls, doc: Mapping) -> ParameterSetting:
        prior = doc.get("prior")
        return cls(
            name=str(doc["name"]),
            estimate=bool(doc.get("estimate", True)),
            nominal=doc.get("nominal"),
            lower=doc.get("lower"),
            upper=doc.get("upper"),
            scale=doc.get("scale"),
            prior=None if prior is None else (str(prior[0]), float(prior[1]), float(prior[2])),
            source=str(doc.get("source", "")),
        )


def apply_settings(
    params: Iterable[Param], settings: Iterable[ParameterSetting]
) -> tuple[Param, ...]:
    """The estimated parameters of ``params`` with ``settings`` applied; the fixed ones
    left out (:func:`fixed_values` gives them). Settings of names not in ``params``
    are ignored here: a setting may name a parameter of another candidate model (the
    power limit's load scale when the constant coupling is fitted too)."""
    by_name = {s.name: s for s in settings}
    out = []
    for p in params:
        s = by_name.get(p.name)
        if s is None:
            out.append(p)
        elif s.estimate:
            out.append(s.apply(p))
        else:
            s.check_fixed(p)
    return tuple(out)


def fixed_values(
    params: Iterable[Param], settings: Iterable[ParameterSetting]
) -> tuple[tuple[str, float], ...]:
    """``(name, value)`` of every parameter of ``params`` that ``settings`` fix."""
    names = {p.name for p in params}
    return tuple(
        (s.name, float(s.nominal))  # type: ignore[arg-type]  # fixed: nominal is set
        for s in settings
        if not s.estimate and s.name in names
    )
