"""``idtool compare``: materials (or sessions) side by side in one report.

:func:`compare_fits` reads two or more fits and, at the compared loads x amplitudes,
gives each fit's friction ratio, the probability that the first fit (the reference)
reduces friction more than each other fit with the difference in reduction points
(:mod:`idtool._predict._compare`), the amplitude each needs for the target reductions,
and the physical estimates side by side. With more than two fits every probability is
the reference's against one other fit (n - 1 comparisons, not all pairs: a
qualification weighs candidates against the current material; swap the order for
another reference). :meth:`Comparison.write` writes ``compare.html`` (self-contained,
the look and print rules of ``report.html``), ``compare.json`` and the figures as PNG.
"""

from __future__ import annotations

import dataclasses
import json
import os
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from idtool._atomic import atomic_output_dir
from idtool._diagnostic import BANNER_CODES, banner_label, reworded, with_code
from idtool._entry import load_fit
from idtool._errors import IdtoolError
from idtool._posterior._store import POSTERIOR_FILE
from idtool._predict._amplitude import AmplitudeFor
from idtool._predict._compare import (
    PairPoint,
    comparability,
    compare_at,
    tested_values,
    thinned,
)
from idtool._predict._predict import (
    Draws,
    Prediction,
    extrapolation_notes,
    friction_ratio_draws,
    predictions_from_draws,
)
from idtool._predict._tables import amplitude_table
from idtool._report._compare_html import SECTIONS, compare_html, prob
from idtool._report._page import now_utc, options_bytes, report_id
from idtool._version import __version__
from idtool._workflow import Fit

__all__ = ["SECTIONS", "TARGETS", "ComparedFit", "Comparison", "compare_fits", "default_out"]

TARGETS = (30.0, 50.0)
FIGURES = ("fr_vs_amplitude.png", "fr_vs_load.png")
# Draws for the curves and the amplitude inverse (the contact model solved per draw at
# every grid or bisection point): 400, as report.html, puts the 2.5% and 97.5% points
# within about 1% of their limits. The probabilities use every draw.
CURVE_DRAWS = 400


@dataclasses.dataclass(frozen=True, eq=False)
class ComparedFit:
    """One fit of a comparison: its ``label`` (the folder's name), the fit, its draws,
    its ``(mean, new pull)`` FR draws (draws, points) at the comparison's operating
    points, their :class:`~idtool.Prediction` rows, and the amplitude for each target
    reduction at each compared load (target-major)."""

    label: str
    fit: Fit
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
class Comparison:
    """Fits side by side (:func:`compare_fits`). ``pairs``: (reference label, other
    label, one :class:`~idtool._predict._compare.PairPoint` per operating point of
    ``grid``); ``banners``: what must be read first (unconverged chains, misfit,
    extrapolation); ``warnings``: those and every other doubt."""

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

    def to_dict(self) -> dict:
        """The ``compare.json`` document."""
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
            "figures": list(FIGURES),
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

    def write(self, out: str | os.PathLike, *, force: bool = False) -> Path:
        """Write ``compare.html``, ``compare.json`` and the figures into the folder
        ``out`` all or nothing; an existing ``out`` is replaced only with ``force``.
        Returns the path of ``compare.html``."""
        from idtool._report._compare_figures import Curve, compare_figures

        curves = [
            Curve(
                f.label,
                thinned(f.draws, CURVE_DRAWS),
                f.tested("normal_load_n"),
                f.tested("amplitude_fraction"),
            )
            for f in self.fits
        ]
        with atomic_output_dir(out, force=force) as tmp:
            paths = compare_figures(curves, self.load_n, self.amplitude, self.speed_m_s, tmp)
            (tmp / "compare.html").write_text(compare_html(self, paths))
            doc = json.dumps(self.to_dict(), indent=1, allow_nan=False)
            (tmp / "compare.json").write_text(doc + "\n")
        return Path(out) / "compare.html"


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


def _label(item: Fit | str | os.PathLike) -> str:
    if isinstance(item, Fit):
        return item.folder.resolve().name if item.folder is not None else item.dataset.name
    return Path(item).resolve().name


def default_out(fits: Sequence[str | os.PathLike]) -> Path:
    """``compare-A-B`` beside the first fit folder (A, B the folders' names)."""
    return Path(fits[0]).resolve().parent / ("compare-" + "-".join(_label(f) for f in fits))


def _common(fits: list[Fit], name: str) -> tuple[list[float], str]:
    """The values of ``name`` every fit tested, else the first fit's, with a warning."""
    seen = [tested_values(f.model.data, name) for f in fits]
    common = [v for v in seen[0] if all(any(np.isclose(v, w) for w in s) for s in seen[1:])]
    if common:
        return common, ""
    what = "load" if name == "normal_load_n" else "amplitude"
    return seen[0], f"no {what} was tested by every fit: compared at the first fit's"


def _numbers(name: str, values, lo: float, hi: float) -> list[float]:
    out = [float(v) for v in np.atleast_1d(np.asarray(values, float))]
    for v in out:
        if not (np.isfinite(v) and lo < v <= hi):
            raise IdtoolError(f"{name} {v:g}: must lie in ({lo:g}, {hi:g}]")
    return out


def compare_fits(
    fits: Sequence[Fit | str | os.PathLike],
    load_n: float | Sequence[float] | None = None,
    amplitude: float | Sequence[float] | None = None,
    *,
    speed_m_s: float | None = None,
    targets: Sequence[float] = TARGETS,
    max_draws: int = 2000,
    seed: int = 0,
) -> Comparison:
    """Compare two or more fits (fit folders or :class:`~idtool.Fit`) at the loads
    ``load_n`` [N] x commanded amplitude fractions ``amplitude`` (default: the values
    every fit tested, else the first fit's) and ``speed_m_s`` [m/s] (default: the fits'
    common pull speed). The first fit is the reference: the probability that it reduces
    friction more than each other fit, from ``max_draws`` independent draws of each
    (posterior, else the fit's covariance: flagged), and the amplitude each needs for
    ``targets`` [% reduction]. Fits from different rigs are refused (IdtoolError)."""
    if len(fits) < 2:
        raise IdtoolError(f"give at least two fits to compare (got {len(fits)})")
    targets = [float(t) for t in targets]
    for t in targets:
        if not 0.0 < t < 100.0:
            raise IdtoolError(f"target reduction {t:g}%: give one in (0, 100)")
    if max_draws < 10:
        raise IdtoolError(f"max_draws = {max_draws}: give at least 10")
    labels = [_label(f) for f in fits]
    folders = [str(Path(f).resolve()) for f in fits if not isinstance(f, Fit)]
    if len(set(folders)) < len(folders):
        raise IdtoolError("the same fit folder is given twice: give different fits")
    labels = [x if labels.count(x) == 1 else f"{x} ({i + 1})" for i, x in enumerate(labels)]
    loaded = [f if isinstance(f, Fit) else load_fit(f) for f in fits]
    warnings = comparability(
        labels,
        [f.dataset.rig for f in loaded],
        [f.model.law.name for f in loaded],
        [f.dataset.sha256 for f in loaded],
        [f.model.data for f in loaded],
    )
    loads, amps = load_n, amplitude
    for name, given in (("normal_load_n", load_n), ("amplitude_fraction", amplitude)):
        if given is None:
            values, note = _common(loaded, name)
            warnings += [note] if note else []
            loads, amps = (values, amps) if name == "normal_load_n" else (loads, values)
    # each value once, in the order given
    loads = list(dict.fromkeys(_numbers("load [N]", loads, 0.0, np.inf)))
    amps = list(dict.fromkeys(_numbers("amplitude fraction", amps, 0.0, 1.0)))
    if speed_m_s is None:
        speeds = sorted({s for f in loaded for s in tested_values(f.model.data, "pull_speed_m_s")})
        if len(speeds) > 1:
            raise IdtoolError(f"the fits were pulled at several speeds {speeds} m/s: give one")
        speed_m_s = speeds[0]
    speed = _numbers("speed [m/s]", speed_m_s, 0.0, np.inf)[0]

    # Independent random streams per fit: the same seed in every fit would give Gaussian
    # (no-posterior) draws from the same standard normals, correlating the two sides.
    seeds = [int(s.generate_state(1)[0]) for s in np.random.SeedSequence(seed).spawn(len(loaded))]
    grid = np.array([(n, a, speed) for n in loads for a in amps], float)
    compared, banners = [], []
    for label, fit, s in zip(labels, loaded, seeds, strict=True):
        draws = fit.draws(max_draws, s)
        one, first, doubts = _compare_one(label, fit, draws, loads, amps, speed, targets)
        compared.append(one)
        banners += first
        warnings += doubts
    ref = compared[0]
    pairs = tuple(
        (ref.label, c.label, tuple(compare_at(grid, ref.friction_ratio, c.friction_ratio, seed)))
        for c in compared[1:]
    )
    options = options_bytes(
        load_n=loads, amplitude=amps, speed_m_s=speed, targets=targets, draws=max_draws, seed=seed
    )
    cid = report_id(*(b for f in loaded for b in _fit_bytes(f)), options)
    return Comparison(
        tuple(compared), tuple(loads), tuple(amps), speed, tuple(targets), pairs,
        tuple(banners), tuple(warnings), seed, now_utc(), cid,
    )  # fmt: skip


def _compare_one(
    label: str,
    fit: Fit,
    draws: Draws,
    loads: Sequence[float],
    amps: Sequence[float],
    speed_m_s: float,
    targets: Sequence[float],
) -> tuple[ComparedFit, list[str], list[str]]:
    """One fit at the operating points ``loads`` [N] x ``amps`` at ``speed_m_s`` [m/s]
    (load-major) and the amplitude for each of ``targets`` [%] at each load
    (target-major): the :class:`ComparedFit`, its banners (extrapolation, misfit, an
    unconverged chain) and its warnings."""
    data = fit.model.data
    speed = [speed_m_s]
    grid = np.array([(n, a, speed_m_s) for n in loads for a in amps], float)
    fr = friction_ratio_draws(draws, *grid.T)
    amp_rows: list[AmplitudeFor] = []
    amp_notes: list[str] = []
    notes = [f"{label}: {n}" for n in extrapolation_notes(data, loads, amps, speed)]
    for target in targets:
        rows = amplitude_table(thinned(draws, CURVE_DRAWS), data, target, loads, speed)
        amp_rows += rows.rows
        # its load and speed notes are the operating points' (above) again
        amp_notes += [
            reworded(n, f"{label}, {target:g}% reduction: {n}")
            for n in with_code(rows.warnings, "extrapolation")
            if n.values.get("quantity") == "needed amplitude fraction"
        ]
    # Banners for what undermines the answer table (a compared point outside the tested
    # range); a needed amplitude beyond it is marked in its own cell, and warned below.
    banners = [n.removesuffix(": extrapolation") + ": extrapolated" for n in notes]
    banners += [
        f"{label}: {banner_label(w).lower()}: {w}" for w in with_code(fit.warnings, *BANNER_CODES)
    ]
    warnings = []
    if draws.source != "posterior":
        warnings.append(f"{label}: {draws.note}")
    elif "NOT converged" in draws.note:
        banners.append(
            f"{label}: the posterior chain did NOT converge: its bands and probabilities "
            "are not to be trusted yet (idtool sample FIT --resume --steps N)"
        )
    warnings += notes + amp_notes + [f"{label} (its fit): {w}" for w in fit.warnings]
    preds = tuple(predictions_from_draws(grid, *fr))
    return ComparedFit(label, fit, draws, fr, preds, tuple(amp_rows)), banners, warnings


def _fit_bytes(fit: Fit) -> list[bytes]:
    """What identifies a fit's answers: its ``fit.json`` and ``posterior.nc``."""
    if fit.folder is None:
        return [json.dumps(fit.to_json(), sort_keys=True).encode()]
    return [
        (fit.folder / name).read_bytes()
        for name in ("fit.json", POSTERIOR_FILE)
        if (fit.folder / name).is_file()
    ]
