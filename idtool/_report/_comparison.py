"""What a comparison of fits is, as data (:func:`idtool.compare_fits`): each compared fit
(:class:`ComparedFit`) and the whole (:class:`ComparisonRecord`: its ``compare.json``
document and text summary), and what it reads of a fit (:class:`FitToCompare`, which
:class:`idtool.Fit` has). Below the HTML page (:mod:`idtool._report._compare_html`) and
the public :class:`~idtool._report._compare.Comparison` that writes it, so that neither
imports the other's module to know the record.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from pathlib import Path
from typing import Protocol

import numpy as np

from idtool._data._dataset import Dataset
from idtool._fit._artefact import FitArtefact
from idtool._fit._result import Estimate
from idtool._model._benchmodel import BenchModel
from idtool._predict._amplitude import AmplitudeFor
from idtool._predict._compare import PairPoint, tested_values
from idtool._predict._predict import Draws, Prediction
from idtool._version import __version__

__all__ = [
    "CURVE_DRAWS",
    "DECISIVE",
    "FIGURES",
    "ComparedFit",
    "ComparisonRecord",
    "FitToCompare",
    "prob",
]

FIGURES = ("fr_vs_amplitude.png", "fr_vs_load.png")
# Draws for the curves and the amplitude inverse (the contact model solved per draw at
# every grid or bisection point): 400, as report.html, puts the 2.5% and 97.5% points
# within about 1% of their limits. The probabilities use every draw.
CURVE_DRAWS = 400
DECISIVE = 0.95  # a probability beyond 0.95 (or below 0.05) names the better fit


class FitToCompare(Protocol):
    """What a comparison reads of a fit (:class:`idtool.Fit` has it): the report stage
    reads fits through this, never the workflow's class itself, which sits above it."""

    @property
    def dataset(self) -> Dataset: ...
    @property
    def model(self) -> BenchModel: ...
    @property
    def folder(self) -> Path | None: ...
    @property
    def estimates(self) -> Mapping[str, Estimate]: ...
    @property
    def warnings(self) -> list[str]: ...
    @property
    def artefact(self) -> FitArtefact: ...
    def draws(self, max_draws: int = 2000, seed: int = 0) -> Draws: ...


def prob(p: float, se: float | None = None, pm: str = "\u00b1") -> str:
    """A probability as ``= 0.734 ± 0.012`` (3 decimals, with its standard error), or
    ``> 0.999`` / ``< 0.001`` (``pm``: the plus-minus sign; "+-" in a terminal)."""
    if p > 0.999 or p < 0.001:
        return "> 0.999" if p > 0.999 else "< 0.001"
    return f"= {p:.3f}" + ("" if se is None else f" {pm} {se:.3f}")


@dataclasses.dataclass(frozen=True, eq=False)
class ComparedFit:
    """One fit of a comparison: its ``label`` (the folder's name), the fit, its draws,
    its ``(mean, new pull)`` FR draws (draws, points) at the comparison's operating
    points, their :class:`~idtool.Prediction` rows, and the amplitude for each target
    reduction at each compared load (target-major)."""

    label: str
    fit: FitToCompare
    draws: Draws
    friction_ratio: tuple[np.ndarray, np.ndarray]
    predictions: tuple[Prediction, ...]
    amplitudes: tuple[AmplitudeFor, ...]

    @property
    def has_posterior(self) -> bool:
        return self.draws.source == "posterior"

    @property
    def converged(self) -> bool:
        """False for a posterior whose chain did not converge (its draws say so)."""
        return "NOT converged" not in self.draws.note

    def tested(self, name: str) -> list[float]:
        return tested_values(self.fit.model.data, name)

    def estimates(self) -> dict[str, dict]:
        """Each physical parameter: median and 95% interval over the posterior's draws,
        or the fit's estimate and interval without a posterior; with its unit."""
        out = {}
        for name in self.fit.model.physical_names:
            e = self.fit.estimates[name]
            if self.has_posterior:
                lo, med, hi = np.percentile(self.draws.values[name], [2.5, 50.0, 97.5])
                value, ci, source = float(med), [float(lo), float(hi)], "posterior"
            else:
                value, ci, source = e.estimate, list(e.ci95), "fit"
            out[name] = {"unit": e.unit, "estimate": value, "ci95": ci, "source": source}
        physical = {p.name for p in self.fit.model.declared_params if p.physical}
        for name, value in self.fit.model.fixed.items():  # held in the fit: by whom, said
            if name not in physical:
                continue
            e = self.fit.estimates[name]
            out[name] = {
                "unit": e.unit,
                "estimate": value,
                "ci95": [value, value],
                "source": "fixed",
                "fixed_by": e.fixed_label or "fixed",
            }
        return out


@dataclasses.dataclass(frozen=True, eq=False)
class ComparisonRecord:
    """Fits side by side (:func:`idtool.compare_fits`), as data. ``pairs``: (reference
    label, other label, one :class:`~idtool._predict._compare.PairPoint` per operating
    point of ``grid``); ``banners``: what must be read first (unconverged chains,
    misfit, extrapolation); ``warnings``: those and every other doubt."""

    fits: tuple[ComparedFit, ...]
    load_n: tuple[float, ...]
    amplitude: tuple[float, ...]
    speed_m_s: float
    targets: tuple[float, ...]
    pairs: tuple[tuple[str, str, tuple[PairPoint, ...]], ...]
    banners: tuple[str, ...]
    warnings: tuple[str, ...]
    seed: int
    created_utc: str
    id: str

    @property
    def grid(self) -> np.ndarray:
        """The operating points (load [N], amplitude fraction, speed [m/s]), load-major."""
        rows = [(n, a, self.speed_m_s) for n in self.load_n for a in self.amplitude]
        return np.array(rows, float)

    def to_dict(self, figures: bool = True) -> dict:
        """The ``compare.json`` document; ``figures``: whether the figures are written
        beside it (:meth:`idtool.Comparison.write`), else ``"figures"`` is empty."""
        return {
            "idtool_version": __version__,
            "id": self.id,
            "created_utc": self.created_utc,
            "seed": self.seed,
            "reference": self.fits[0].label,
            "fits": [_fit_doc(f) for f in self.fits],
            "operating_points": {
                "normal_load_n": list(self.load_n),
                "amplitude_fraction": list(self.amplitude),
                "pull_speed_m_s": self.speed_m_s,
            },
            "probabilities": [
                {"a": a, "b": b, "points": [p.to_dict() for p in pts]} for a, b, pts in self.pairs
            ],
            "predictions": {f.label: [p.to_dict() for p in f.predictions] for f in self.fits},
            "targets_percent": list(self.targets),
            "amplitudes": {f.label: [a.to_dict() for a in f.amplitudes] for f in self.fits},
            "estimates": {f.label: f.estimates() for f in self.fits},
            "figures": list(FIGURES) if figures else [],
            "banners": list(self.banners),
            "warnings": list(self.warnings),
        }

    def summary(self) -> str:
        """The probabilities and differences as lines of text, then the warnings."""
        lines = []
        for a, b, pts in self.pairs:
            for p in pts:
                med, lo, hi = p.reduction_difference
                lines.append(
                    f"{a} vs {b} at {p.normal_load_n:g} N, amplitude {p.amplitude_fraction:.0%}: "
                    f"P({a} reduces friction more) {prob(p.probability, p.standard_error, '+-')}; "
                    f"reduction {a} - {b} = {med:+.1f} points "
                    f"[{lo:+.1f}, {hi:+.1f}]"
                )
        return "\n".join(lines + [f"warning: {w}" for w in self.warnings])


def _fit_doc(f: ComparedFit) -> dict:
    ds, rig, model = f.fit.dataset, f.fit.dataset.rig, f.fit.model
    return {
        "label": f.label,
        "folder": None if f.fit.folder is None else str(f.fit.folder),
        "material": ds.material,
        "dataset": {"name": ds.name, "sha256": ds.sha256, "traces": len(ds.traces)},
        "rig": {
            "vibration_frequency_hz": rig.vibration_frequency_hz,
            "max_amplitude_m": rig.max_amplitude_m,
        },
        "model": {"law": model.law.name, "coupling": model.coupling.name},
        "tested": {
            "normal_load_n": f.tested("normal_load_n"),
            "amplitude_fraction": f.tested("amplitude_fraction"),
            "pull_speed_m_s": f.tested("pull_speed_m_s"),
        },
        "posterior": f.has_posterior,
        "draws": {"source": f.draws.source, "note": f.draws.note, "n": f.draws.n},
        "warnings": f.fit.warnings,
    }
