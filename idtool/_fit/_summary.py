"""What a fit reports besides its state, as typed records (:class:`FitSummary`): the
traces' friction ratios, the derived quantities, the correlations, the model
comparison and why the model was chosen, the levels model's sds and lack of fit, and the
provenance. Read from the ``fit.json`` document (any schema version: fields a version 1
document lacks take their empty values), so the report and ``compare`` read a fit's
artefact (:mod:`idtool._fit._artefact`), never its JSON."""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from typing import Any

import numpy as np

from idtool._fit._result import Estimate

__all__ = [
    "Criteria",
    "FitSummary",
    "Provenance",
    "TraceFit",
    "VariabilitySummary",
    "estimate_of_doc",
    "fit_summary",
]


@dataclasses.dataclass(frozen=True)
class TraceFit:
    """One fitted trace: its operating point (load [N], commanded amplitude fraction,
    speed [m/s]), the model's friction ratio there and its standard error, and the
    trace's own friction ratio fitted from it alone (levels model; None when off, or
    when its ON window ends before the force settles: ``measured`` False)."""

    id: str
    normal_load_n: float
    amplitude_fraction: float
    pull_speed_m_s: float
    friction_ratio: float
    friction_ratio_se: float
    free_friction_ratio: float | None = None
    free_friction_ratio_se: float | None = None
    measured: bool = False
    levels_model: bool = False  # the free friction ratio was estimated (levels model on)

    def own(self) -> tuple[float, float] | None:
        """The trace's own friction ratio and its 95% half-width: fitted from the trace
        alone, or the model's at the trace for a noise-only fit; None when not measured."""
        if not self.levels_model:
            return self.friction_ratio, 1.96 * self.friction_ratio_se
        if not self.measured or self.free_friction_ratio is None:
            return None
        return self.free_friction_ratio, 1.96 * float(self.free_friction_ratio_se or 0.0)


@dataclasses.dataclass(frozen=True)
class Criteria:
    """A candidate model's key (law/coupling/actuator/offset[/level]), AIC, BIC, log
    likelihood and parameter count."""

    model: str
    aic: float
    bic: float
    loglik: float
    n_params: int


@dataclasses.dataclass(frozen=True)
class VariabilitySummary:
    """The levels model's relative sds (name -> (estimate, 95% lower, upper)) and the
    physical model's lack-of-fit test (chi2 on dof degrees of freedom, p-value)."""

    sds: dict[str, tuple[float, float, float]]
    chi2: float
    dof: int
    p_value: float


@dataclasses.dataclass(frozen=True)
class Provenance:
    """Where a fit came from: the dataset (name, sha256, path, fitted traces), the
    command, seed, package versions, idtool's version and when (UTC)."""

    dataset: dict[str, Any]
    command: str
    seed: int
    versions: dict[str, Any]
    idtool_version: str
    created_utc: str


@dataclasses.dataclass(frozen=True)
class FitSummary:
    """What a fit reports besides its state (module docstring)."""

    traces: tuple[TraceFit, ...]
    derived: dict[str, tuple[Estimate, str]]
    correlation_names: tuple[str, ...]
    correlation: np.ndarray
    model_comparison: tuple[Criteria, ...]
    choice: str
    variability: VariabilitySummary | None
    provenance: Provenance


def estimate_of_doc(name: str, e: Mapping[str, Any]) -> Estimate:
    """The :class:`~idtool.Estimate` ``name`` as ``fit.json`` records it."""
    return Estimate(
        name,
        e["unit"],
        float(e["estimate"]),
        float(e["std_error"]),
        (float(e["ci95"][0]), float(e["ci95"][1])),
        bool(e.get("at_bound", False)),
        bool(e.get("fixed", False)),
        str(e.get("fixed_by", "fixed by the user" if e.get("fixed") else "")),
        str(e.get("one_sided", "")),
    )


def _trace(t: Mapping[str, Any]) -> TraceFit:
    free = t.get("free_friction_ratio")
    fr = t["friction_ratio"]
    return TraceFit(
        id=str(t["id"]),
        normal_load_n=float(t["normal_load_n"]),
        amplitude_fraction=float(t["amplitude_fraction"]),
        pull_speed_m_s=float(t["pull_speed_m_s"]),
        friction_ratio=float(fr["estimate"]),
        friction_ratio_se=float(fr["std_error"]),
        free_friction_ratio=None if free is None else free.get("estimate"),
        free_friction_ratio_se=None if free is None else free.get("std_error"),
        measured=bool(free is not None and free.get("measured")),
        levels_model=free is not None,
    )


def _variability(doc: Mapping[str, Any]) -> VariabilitySummary | None:
    var = doc.get("variability", {"on": False})
    if not var.get("on"):
        return None
    lof = var["lack_of_fit"]
    return VariabilitySummary(
        sds={
            name: (float(v["estimate"]), float(v["ci95"][0]), float(v["ci95"][1]))
            for name, v in var["sds"].items()
        },
        chi2=float(lof["chi2"]),
        dof=int(lof["dof"]),
        p_value=float(lof["p_value"]),
    )


def fit_summary(doc: Mapping[str, Any]) -> FitSummary:
    """The :class:`FitSummary` of a ``fit.json`` document."""
    corr = doc.get("correlation", {"names": [], "matrix": []})
    names = tuple(corr["names"])
    return FitSummary(
        traces=tuple(_trace(t) for t in doc.get("traces", [])),
        derived={
            name: (estimate_of_doc(name, e), str(e.get("description", "")))
            for name, e in doc.get("derived", {}).items()
        },
        correlation_names=names,
        correlation=np.array(corr["matrix"], float).reshape(len(names), len(names)),
        model_comparison=tuple(
            Criteria(m["model"], m["aic"], m["bic"], m["loglik"], int(m["n_params"]))
            for m in doc.get("model_comparison", [])
        ),
        choice=str(doc.get("choice", "")),
        variability=_variability(doc),
        provenance=Provenance(
            dataset=dict(doc["dataset"]),
            command=str(doc.get("command", "-")),
            seed=int(doc.get("seed", 0)),
            versions=dict(doc.get("versions", {})),
            idtool_version=str(doc.get("idtool_version", "-")),
            created_utc=str(doc.get("created_utc", "-")),
        ),
    )
