"""``idtool compare``: materials (or sessions) side by side in one report.

:func:`idtool.compare_fits` (:mod:`idtool._entry`, which reads the fit folders) hands
:func:`compare` two or more fits and, at the compared loads x amplitudes,
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
from idtool._errors import IdtoolError
from idtool._fit._folder import FIT_JSON
from idtool._posterior._store import POSTERIOR_FILE
from idtool._predict._amplitude import AmplitudeFor
from idtool._predict._compare import (
    comparability,
    compare_at,
    tested_values,
    thinned,
)
from idtool._predict._predict import (
    Draws,
    extrapolation_notes,
    friction_ratio_draws,
    predictions_from_draws,
)
from idtool._predict._tables import amplitude_table
from idtool._report._compare_figures import Curve, compare_figures
from idtool._report._compare_html import SECTIONS, compare_html
from idtool._report._comparison import (
    CURVE_DRAWS,
    ComparedFit,
    ComparisonRecord,
    FitToCompare,
)
from idtool._report._page import now_utc, options_bytes, report_id

__all__ = [
    "SECTIONS",
    "TARGETS",
    "ComparedFit",
    "Comparison",
    "compare",
    "compare_request",
    "default_out",
]

TARGETS = (30.0, 50.0)


@dataclasses.dataclass(frozen=True, eq=False)
class Comparison(ComparisonRecord):
    """Fits side by side (:func:`idtool.compare_fits`). ``pairs``: (reference label, other
    label, one :class:`~idtool._predict._compare.PairPoint` per operating point of
    ``grid``); ``banners``: what must be read first (unconverged chains, misfit,
    extrapolation); ``warnings``: those and every other doubt."""

    def write(self, out: str | os.PathLike, *, force: bool = False, figures: bool = True) -> Path:
        """Write ``compare.html``, ``compare.json`` and the figures into the folder
        ``out`` all or nothing; an existing ``out`` is replaced only with ``force``.
        ``figures=False`` leaves out the figures (FR against amplitude and load, every
        fit's band overlaid): their curves solve each fit's contact model for up to 400
        draws at 100 points, most of the time of a comparison of sdof fits; the page then
        says so and ``compare.json`` lists no figures. Returns the path of
        ``compare.html``."""
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
            paths = (
                compare_figures(curves, self.load_n, self.amplitude, self.speed_m_s, tmp)
                if figures
                else []
            )
            (tmp / "compare.html").write_text(compare_html(self, paths))
            doc = json.dumps(self.to_dict(figures=figures), indent=1, allow_nan=False)
            (tmp / "compare.json").write_text(doc + "\n")
        return Path(out) / "compare.html"


def _label(item: FitToCompare | str | os.PathLike) -> str:
    if isinstance(item, str | os.PathLike):
        return Path(item).resolve().name
    return item.folder.resolve().name if item.folder is not None else item.dataset.name


def default_out(fits: Sequence[str | os.PathLike]) -> Path:
    """``compare-A-B`` beside the first fit folder (A, B the folders' names)."""
    return Path(fits[0]).resolve().parent / ("compare-" + "-".join(_label(f) for f in fits))


def _common(fits: Sequence[FitToCompare], name: str) -> tuple[list[float], str]:
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


def compare_request(
    fits: Sequence[FitToCompare | str | os.PathLike], targets: Sequence[float], max_draws: int
) -> tuple[list[str], list[float]]:
    """The checks of :func:`idtool.compare_fits` that come before any fit is read: the
    fits' labels (their folders' names, numbered where two agree) and the targets;
    IdtoolError for fewer than two fits, a target outside (0, 100), too few draws or
    the same folder twice."""
    if len(fits) < 2:
        raise IdtoolError(f"give at least two fits to compare (got {len(fits)})")
    targets = [float(t) for t in targets]
    for t in targets:
        if not 0.0 < t < 100.0:
            raise IdtoolError(f"target reduction {t:g}%: give one in (0, 100)")
    if max_draws < 10:
        raise IdtoolError(f"max_draws = {max_draws}: give at least 10")
    labels = [_label(f) for f in fits]
    folders = [str(Path(f).resolve()) for f in fits if isinstance(f, str | os.PathLike)]
    if len(set(folders)) < len(folders):
        raise IdtoolError("the same fit folder is given twice: give different fits")
    labels = [x if labels.count(x) == 1 else f"{x} ({i + 1})" for i, x in enumerate(labels)]
    return labels, targets


def compare(
    loaded: Sequence[FitToCompare],
    labels: Sequence[str],
    load_n: float | Sequence[float] | None = None,
    amplitude: float | Sequence[float] | None = None,
    *,
    speed_m_s: float | None = None,
    targets: Sequence[float] = TARGETS,
    max_draws: int = 2000,
    seed: int = 0,
) -> Comparison:
    """:func:`idtool.compare_fits` of fits read already (``labels`` and ``targets`` from
    :func:`compare_request`)."""
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
    fit: FitToCompare,
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


def _fit_bytes(fit: FitToCompare) -> list[bytes]:
    """What identifies a fit's answers: its ``fit.json`` and ``posterior.nc``."""
    if fit.folder is None:
        return [json.dumps(fit.artefact.doc, sort_keys=True).encode()]
    return [
        (fit.folder / name).read_bytes()
        for name in (FIT_JSON.name, POSTERIOR_FILE)
        if (fit.folder / name).is_file()
    ]
