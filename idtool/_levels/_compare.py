"""Friction tables' fits side by side (``idtool compare`` on fits of kind ``levels``).

Which material reduces friction more, from two or more table fits
(:class:`~idtool._levels._result.LevelsFit`): at each compared condition (normal load,
amplitude, sliding speed, frequency) each fit's friction ratio with its 95% band at a
new condition, the difference in reduction ``FR_other - FR_ref`` [percentage points]
and the probability that the first fit (the reference) reduces friction more,
``P(FR_ref < FR_other)``, from independent draws of the fits: the posterior's when
sampled, else Gaussian on the fit's covariance (internal scale), flagged. Each draw's
FR carries its own discrepancy (``exp(s_d z)``, the mean at a new condition, as the
fit's bands), so two tables whose model misses differ by more than the model says.

A condition where a fit's prediction is not bounded by its table (it moves along a
direction the data do not inform, :attr:`LevelsPrediction.pinned`) gets no
probability: the comparison says so rather than give one the covariance cannot back.
"""

from __future__ import annotations

import dataclasses
import json
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from idtool._atomic import atomic_output_dir
from idtool._errors import IdtoolError
from idtool._lawfit._profile import json_number as _json_number
from idtool._levels._result import LevelsFit
from idtool._version import __version__

__all__ = ["TableComparison", "compare_tables"]

FIGURE = "fr_by_condition.png"
DECISIVE = 0.95  # beyond 0.95 (or below 0.05) the comparison names the better fit


def _conditions(fits: Sequence[LevelsFit]) -> tuple[np.ndarray, str | None]:
    """The conditions (n, 4: load [N], amplitude [m], speed [m/s], frequency [Hz])
    every table measured, else the reference table's (and a note saying so)."""

    def rows(fit: LevelsFit) -> set[tuple[float, ...]]:
        t = fit.table
        keys = zip(
            t.normal_load_n,
            t.amplitude_m,
            t.sliding_speed_m_s,
            t.vibration_frequency_hz,
            strict=True,
        )
        return {tuple(float(x) for x in key) for key in keys}

    common = set.intersection(*(rows(f) for f in fits))
    note = None
    if not common:
        common = rows(fits[0])
        note = (
            "no condition is in every table: compared at the reference table's conditions "
            "(the others' fits predict there)"
        )
    return np.array(sorted(common), float), note


def _draws(fit: LevelsFit, cond: np.ndarray, n_draws: int, seed: int) -> tuple[np.ndarray, str]:
    """FR draws (n_draws, n) at the conditions, each with its draw of the discrepancy,
    and where this fit's came from (``posterior`` or ``covariance``). After a model
    choice the models kept share the draws by their BIC weights (the alternates'
    Gaussian on their covariances), shuffled: as the fit's predictions average them."""
    if not fit.alternates:
        return _model_draws(fit, cond, n_draws, seed)
    models = (fit, *fit.alternates)
    w = np.array([r.bic_weight for r in fit.ranking[: len(models)]])
    # exactly n_draws (they are paired with the other fits'): largest remainders
    share = n_draws * w / w.sum()
    counts = np.floor(share).astype(int)
    counts[np.argsort(counts - share)[: n_draws - counts.sum()]] += 1
    seeds = np.random.SeedSequence(seed).spawn(len(models) + 1)
    parts = [
        _model_draws(m, cond, int(c), int(s.generate_state(1)[0]))
        for m, c, s in zip(models, counts, seeds, strict=False)
        if c > 0
    ]
    pooled = np.concatenate([d for d, _ in parts])
    order = np.random.default_rng(seeds[-1]).permutation(pooled.shape[0])
    return pooled[order], parts[0][1]


def _model_draws(
    fit: LevelsFit, cond: np.ndarray, n_draws: int, seed: int
) -> tuple[np.ndarray, str]:
    """:func:`_draws` of ``fit``'s own model."""
    import jax

    rng = np.random.default_rng(seed)
    m = fit.model
    alpha = cond[:, 1] / fit.table.reference_amplitude_m
    if fit.posterior is not None:
        theta, sds = fit.posterior.thetas(m, n_draws)
        disc = sds["discrepancy_fr"]
        source = "posterior"
    else:
        o = fit.optimum
        # eigh, not Cholesky: the covariance is singular along directions the table does
        # not inform (a pseudo-inverse there); those points are not compared (pinned)
        val, vec = np.linalg.eigh(0.5 * (o.cov_theta + o.cov_theta.T))
        root = vec * np.sqrt(np.clip(val, 0.0, None))
        theta = o.theta + rng.standard_normal((n_draws, o.theta.size)) @ root.T
        disc = np.full(n_draws, o.sds["discrepancy_fr"])
        source = "covariance"
    fr = np.asarray(
        jax.vmap(lambda th: m.fr_at(th, cond[:, 0], alpha, cond[:, 2], cond[:, 3]))(
            np.asarray(theta, float)
        )
    )
    return fr * np.exp(disc[:, None] * rng.standard_normal(fr.shape)), source


@dataclasses.dataclass(frozen=True)
class TableComparison:
    """A comparison of table fits (:func:`compare_tables`).

    Attributes:
        labels: each fit's name (its folder's, else its table's); the first is the
            reference.
        conditions: (n, 4) load [N], amplitude [m], speed [m/s], frequency [Hz].
        fr: (fits, n) each fit's median FR (over its draws) [-].
        band: (fits, n, 2) its 95% band at a new condition [-].
        pinned: (fits, n) where its table bounds the prediction.
        diff_pp: (fits - 1, n) median of ``FR_other - FR_ref`` in percentage points:
            how much more the reference reduces friction.
        prob_ref_lower: (fits - 1, n) ``P(FR_ref < FR_other)`` (NaN where either is not
            pinned), and ``prob_se`` its Monte Carlo standard error.
        sources: per fit, ``posterior`` or ``covariance``.
        estimates: per fit, each physical parameter's (estimate, ci95, unit).
        warnings: what the reader must know.
    """

    labels: tuple[str, ...]
    conditions: np.ndarray
    fr: np.ndarray
    band: np.ndarray
    pinned: np.ndarray
    diff_pp: np.ndarray
    prob_ref_lower: np.ndarray
    prob_se: np.ndarray
    sources: tuple[str, ...]
    estimates: tuple[dict[str, tuple[float, tuple[float, float], str]], ...]
    warnings: tuple[str, ...]
    draws: int
    seed: int

    def to_dict(self, figures: bool = True) -> dict[str, Any]:
        """``compare.json``: SI units, one entry per condition."""
        rows = []
        for j, (n, a, v, f) in enumerate(self.conditions):
            row: dict[str, Any] = {
                "normal_load_n": float(n),
                "amplitude_m": float(a),
                "sliding_speed_m_s": float(v),
                "vibration_frequency_hz": float(f),
                "fits": {
                    label: {
                        "fr": float(self.fr[i, j]),
                        "fr_ci95": [float(x) for x in self.band[i, j]],
                        "pinned": bool(self.pinned[i, j]),
                    }
                    for i, label in enumerate(self.labels)
                },
                "against_reference": {
                    label: {
                        "reduction_difference_pp": float(self.diff_pp[i - 1, j]),
                        "probability_reference_reduces_more": _num(self.prob_ref_lower[i - 1, j]),
                        "probability_se": _num(self.prob_se[i - 1, j]),
                    }
                    for i, label in enumerate(self.labels)
                    if i
                },
            }
            rows.append(row)
        return {
            "kind": "levels",
            "idtool_version": __version__,
            "reference": self.labels[0],
            "fits": [
                {
                    "label": label,
                    "draws_from": source,
                    "estimates": {
                        name: {
                            "estimate": e,
                            "ci95": [_json_number(x) for x in ci],
                            "unit": unit,
                        }
                        for name, (e, ci, unit) in est.items()
                    },
                }
                for label, source, est in zip(
                    self.labels, self.sources, self.estimates, strict=True
                )
            ],
            "conditions": rows,
            "warnings": list(self.warnings),
            "draws": self.draws,
            "seed": self.seed,
            "figures": [FIGURE] if figures else [],
        }

    def summary(self) -> str:
        """The text summary (``compare.txt``)."""
        ref = self.labels[0]
        lines = [f"idtool {__version__}: comparison of friction-table fits; reference {ref}"]
        for label, source in zip(self.labels, self.sources, strict=True):
            lines.append(f"  {label}: draws from its {source}")
        lines += ["", "[[Estimates]] (95% intervals)"]
        names = list(dict.fromkeys(n for est in self.estimates for n in est))
        for name in names:
            cells = []
            for label, est in zip(self.labels, self.estimates, strict=True):
                if name in est:
                    e, (lo, hi), unit = est[name]
                    cells.append(f"{label} {e:.4g} [{lo:.3g}, {hi:.3g}] {unit}".rstrip())
            lines.append(f"  {name:15s} " + "; ".join(cells))
        lines += ["", "[[Friction ratio]] median [95% band at a new condition]"]
        for j, (n, a, v, f) in enumerate(self.conditions):
            head = (
                f"  N {n:7.4g} N  a {a * 1e6:6.3g} um  v {v * 1e3:6.3g} mm/s  f {f / 1e3:5.3g} kHz:"
            )
            cells = [
                f"{label} {self.fr[i, j]:.3f} [{self.band[i, j, 0]:.3f}, {self.band[i, j, 1]:.3f}]"
                if self.pinned[i, j]
                else f"{label} {self.fr[i, j]:.3f} (not bounded by its table)"
                for i, label in enumerate(self.labels)
            ]
            lines.append(head + " " + "; ".join(cells))
            for i, label in enumerate(self.labels[1:]):
                p = self.prob_ref_lower[i, j]
                if not np.isfinite(p):
                    says = "no probability: a prediction the tables do not bound"
                else:
                    says = f"P({ref} reduces more) " + (
                        ("> 0.999" if p > 0.999 else "< 0.001")
                        if p > 0.999 or p < 0.001
                        else f"= {p:.3f} +- {self.prob_se[i, j]:.3f}"
                    )
                    if p > DECISIVE or p < 1 - DECISIVE:
                        says += f": {ref if p > DECISIVE else label} reduces more"
                lines.append(
                    f"      {ref} vs {label}: {self.diff_pp[i, j]:+.1f} pp reduction; {says}"
                )
        if self.warnings:
            lines += ["", "[[Warnings]]"] + [f"  - {w}" for w in self.warnings]
        return "\n".join(lines)

    def write(self, out: str | Path, *, force: bool = False, figures: bool = True) -> Path:
        """Write ``compare.txt``, ``compare.json`` and, with ``figures``, the FR per
        condition with each fit's band (:data:`FIGURE`) into folder ``out``, all or
        nothing (an existing folder only with ``force``); returns ``compare.txt``."""
        with atomic_output_dir(out, force=force) as tmp:
            (tmp / "compare.txt").write_text(self.summary() + "\n")
            doc = self.to_dict(figures)
            (tmp / "compare.json").write_text(json.dumps(doc, indent=1) + "\n")
            if figures:
                self.plot(tmp / FIGURE)
        return Path(out) / "compare.txt"

    def plot(self, path: str | Path) -> Path:
        """FR at each condition, each fit's median and 95% band side by side."""
        import matplotlib

        matplotlib.use("Agg", force=False)
        import matplotlib.pyplot as plt

        n_fits, n = self.fr.shape
        fig, ax = plt.subplots(figsize=(min(12.0, max(5.0, 0.7 * n + 2.0)), 4.0))
        width = 0.8 / n_fits
        x = np.arange(n)
        for i, label in enumerate(self.labels):
            xi = x - 0.4 + width * (i + 0.5)
            lo, hi = self.band[i, :, 0], self.band[i, :, 1]
            ok = self.pinned[i]
            ax.errorbar(
                xi[ok],
                self.fr[i, ok],
                yerr=[self.fr[i, ok] - lo[ok], hi[ok] - self.fr[i, ok]],
                fmt="o",
                capsize=3,
                label=label,
            )
            if (~ok).any():
                ax.plot(xi[~ok], self.fr[i, ~ok], "x", color="grey")
        ticks = [
            f"{c[0]:.3g} N\n{c[1] * 1e6:.3g} um\n{c[2] * 1e3:.3g} mm/s" for c in self.conditions
        ]
        ax.set_xticks(x, ticks, fontsize=8)
        ax.set_ylabel("friction ratio FR [-]")
        ax.set_title("FR with its 95% band at a new condition", fontsize=10)
        ax.legend(fontsize=8)
        fig.tight_layout()
        fig.savefig(path, dpi=120)
        plt.close(fig)
        return Path(path)


def _num(x: float) -> float | None:
    return float(x) if np.isfinite(x) else None


def compare_tables(
    fits: Sequence[LevelsFit],
    labels: Sequence[str],
    *,
    load_n: Sequence[float] | None = None,
    speed_m_s: Sequence[float] | None = None,
    max_draws: int = 2000,
    seed: int = 0,
) -> TableComparison:
    """Compare table fits (module docstring) at the conditions every table measured
    (else the reference's), with the loads [N] or speeds [m/s] replaced by ``load_n``
    or ``speed_m_s`` when given (every combination with the other values).

    Raises:
        IdtoolError: fewer than two fits, or fewer than 10 draws.
    """
    if len(fits) < 2:
        raise IdtoolError(f"give at least two fits to compare (got {len(fits)})")
    if max_draws < 10:
        raise IdtoolError(f"--draws {max_draws}: give at least 10")
    cond, note = _conditions(fits)
    warnings = [note] if note else []
    for col, given in ((0, load_n), (2, speed_m_s)):
        if given is not None:
            rest = np.unique(np.delete(cond, col, axis=1), axis=0)
            cond = np.array([np.insert(r, col, g) for g in given for r in rest], float)
    seeds = [int(s.generate_state(1)[0]) for s in np.random.SeedSequence(seed).spawn(len(fits))]
    draws, sources, pinned, estimates = [], [], [], []
    for fit, label, s in zip(fits, labels, seeds, strict=True):
        d, source = _draws(fit, cond, max_draws, s)
        draws.append(d)
        sources.append(source)
        pred = fit.predict(cond[:, 0], cond[:, 2], amplitude_m=cond[:, 1], frequency_hz=cond[:, 3])
        pinned.append(np.asarray(pred.pinned, bool))
        estimates.append(
            {
                name: (float(e.estimate), (float(e.ci95[0]), float(e.ci95[1])), e.unit)
                for name, e in fit.estimates.items()
            }
        )
        if source == "covariance":
            warnings.append(
                f"{label}: not sampled: its draws are Gaussian on the fit's covariance "
                "(idtool sample for the posterior's)"
            )
        for w in fit.warnings:
            warnings.append(f"{label} (its fit): {w}")
    fr = np.stack([np.median(d, axis=0) for d in draws])
    band = np.stack([np.percentile(d, [2.5, 97.5], axis=0).T for d in draws])
    pin = np.stack(pinned)
    n = min(d.shape[0] for d in draws)
    diff, prob, se = [], [], []
    for i in range(1, len(fits)):
        delta = draws[i][:n] - draws[0][:n]  # FR_other - FR_ref: the reference's advantage
        p = np.mean(delta > 0, axis=0)
        ok = pin[0] & pin[i]
        diff.append(100.0 * np.median(delta, axis=0))
        prob.append(np.where(ok, p, np.nan))
        se.append(np.where(ok, np.sqrt(np.maximum(p * (1 - p), 0.25 / n) / n), np.nan))
    if not pin.all():
        warnings.append(
            "a prediction its table does not bound (marked; no probability there): the data "
            "leave a direction of the parameters open that moves FR at that condition"
        )
    return TableComparison(
        labels=tuple(labels),
        conditions=cond,
        fr=fr,
        band=band,
        pinned=pin,
        diff_pp=np.stack(diff),
        prob_ref_lower=np.stack(prob),
        prob_se=np.stack(se),
        sources=tuple(sources),
        estimates=tuple(estimates),
        warnings=tuple(warnings),
        draws=n,
        seed=seed,
    )
