"""Figures of the uncertainty report (PNG files; matplotlib is imported on first use)."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np

from idtool._fit._summary import TraceFit
from idtool._plotting import MAX_WIDTH_IN, save_figure, subplots
from idtool._predict._amplitude import amplitude_for_reduction
from idtool._predict._mixture import law_medians
from idtool._predict._predict import Draws, predict_friction_ratio

__all__ = [
    "amplitude_map_figure",
    "corner_figure",
    "correlation_figure",
    "friction_ratio_figures",
    "walker_figure",
]


def _save(fig, path: Path) -> Path:
    return save_figure(fig, path)


def _label(name: str, unit: str) -> str:
    """An axis label with its unit: ``Kt [N/m]``, dimensionless as ``[-]``."""
    return f"{name} [{'-' if unit in ('', '1') else unit}]"


def correlation_figure(names: list[str], matrix: np.ndarray, path: Path) -> Path:
    """Heat map of the fit's correlation matrix, values written in the cells."""
    n = len(names)
    fig, ax = subplots(figsize=(min(1.1 * n + 2.5, MAX_WIDTH_IN), min(1.0 * n + 2.0, 11.0)))
    im = ax.imshow(matrix, vmin=-1, vmax=1, cmap="RdBu_r")
    ax.set_xticks(range(n), names, rotation=40, ha="right")
    ax.set_yticks(range(n), names)
    for i in range(n):
        for j in range(n):
            ax.text(j, i, f"{matrix[i, j]:+.2f}", ha="center", va="center", fontsize=9)
    bar = fig.colorbar(im, ax=ax, shrink=0.8)
    bar.set_label("correlation [-]")
    return _save(fig, path)


def corner_figure(
    values: dict[str, np.ndarray], names: list[str], units: dict[str, str], path: Path
) -> Path:
    """Corner plot: 1-D histograms on the diagonal, titled with the median and the 95%
    interval (dashed lines at its ends), 2-D scatter below it; axes in ``units``."""
    n = len(names)
    side = min(2.3 * n, MAX_WIDTH_IN)
    fig, axes = subplots(n, n, figsize=(side, side), squeeze=False)
    for i, yi in enumerate(names):
        for j, xj in enumerate(names):
            ax = axes[i, j]
            if j > i:
                ax.axis("off")
                continue
            if i == j:
                lo, med, hi = np.percentile(values[xj], [2.5, 50.0, 97.5])
                ax.hist(values[xj], bins=40, color="C0", alpha=0.8)
                for q in (lo, hi):
                    ax.axvline(q, color="k", ls="--", lw=0.8)
                unit = units.get(xj, "")
                unit = "" if unit in ("", "1") else f" {unit}"
                ax.set_title(f"{xj} = {med:.3g}{unit}\n95% [{lo:.3g}, {hi:.3g}]", fontsize=9)
                ax.set_yticks([])
            else:
                ax.plot(values[xj], values[yi], ",", alpha=0.3, color="C0")
            ax.locator_params(nbins=3)
            ax.tick_params(labelsize=9)
            if i == n - 1:
                ax.set_xlabel(_label(xj, units.get(xj, "")))
                ax.tick_params(axis="x", labelrotation=45)
            else:
                ax.set_xticklabels([])
            if j == 0 and i > 0:
                ax.set_ylabel(_label(yi, units.get(yi, "")))
            elif j > 0:
                ax.set_yticklabels([])
    return _save(fig, path)


def walker_figure(
    chains: dict[str, np.ndarray], names: list[str], units: dict[str, str], path: Path
) -> Path:
    """Every walker's path per parameter (``chains[name]`` is walkers x steps)."""
    fig, axes = subplots(len(names), 1, figsize=(10, 1.6 * len(names)), sharex=True)
    for ax, name in zip(np.atleast_1d(axes), names, strict=True):
        ax.plot(chains[name].T, lw=0.3, alpha=0.5, color="k")
        ax.set_ylabel(_label(name, units.get(name, "")), rotation=0, ha="right", va="center")
        ax.locator_params(axis="y", nbins=3)
    np.atleast_1d(axes)[-1].set_xlabel("step after burn-in [steps]")
    return _save(fig, path)


def friction_ratio_figures(
    draws: Draws, points: Sequence[TraceFit], speed_m_s: float, out: Path
) -> tuple[Path, Path]:
    """FR against amplitude (per load) and against load (per amplitude): the median, the
    95% band of the mean FR (dark) and of the next pull (light, scatter added); over
    them each trace's own friction ratio (:meth:`~idtool._fit._summary.TraceFit.own`:
    estimated from that trace alone, with its 95% interval from its own noise), or the
    model's per-trace FR when the levels model is off. The tested range of the x axis
    (the dataset's amplitudes, or loads) is shaded grey: outside it the curves are the
    model's extrapolation."""
    loads = sorted({p.normal_load_n for p in points})
    alphas = sorted({p.amplitude_fraction for p in points})
    amp_grid = np.linspace(0.05, 1.0, 16)
    load_grid = np.linspace(0.5 * min(loads), 1.5 * max(loads), 16)

    def band(ls, als):
        preds = predict_friction_ratio(draws, ls, als, [speed_m_s])
        med = np.array([p.median for p in preds])
        lo, hi = (np.array([p.ci95[j] for p in preds]) for j in (0, 1))
        new = [p.new_trace or (p.median, p.ci95) for p in preds]
        new_lo, new_hi = (np.array([n[1][j] for n in new]) for j in (0, 1))
        return med, lo, hi, new_lo, new_hi, law_medians(preds)

    def marks(ax, key, value, x_key):
        sel = [
            (getattr(p, x_key), o)
            for p in points
            if getattr(p, key) == value and (o := p.own()) is not None
        ]
        if sel:
            ax.errorbar(
                [x for x, _ in sel],
                [o[0] for _, o in sel],
                [o[1] for _, o in sel],
                fmt="o",
                ms=4,
                color="k",
                zorder=3,
            )

    def panel(groups, x_grid, curve, key, x_key, label, xlabel, title, path, tested):
        # One curve and band per group (a load, or an amplitude) against x_grid; the
        # tested range of x shaded: outside it the curves extrapolate the model
        fig, ax = subplots(figsize=(6, 4))
        ax.axvspan(min(tested), max(tested), color="0.9", lw=0, zorder=0)
        ax.text(
            0.5 * (min(tested) + max(tested)),
            0.02,
            "tested",
            ha="center",
            va="bottom",
            fontsize=9,
            color="0.35",
        )
        styles = ("--", ":", "-.")
        laws: list[str] = []
        for c, value in enumerate(groups):
            med, lo, hi, new_lo, new_hi, by_law = curve(value)
            ax.fill_between(x_grid, new_lo, new_hi, color=f"C{c}", alpha=0.12, lw=0)
            ax.fill_between(x_grid, lo, hi, color=f"C{c}", alpha=0.35, lw=0)
            ax.plot(x_grid, med, color=f"C{c}", label=label(value))
            # averaged over coupling laws: each law's own median curve, thin
            for j, m in enumerate(by_law.values()):
                ax.plot(x_grid, m, styles[j % len(styles)], color=f"C{c}", lw=0.9)
            laws = list(by_law)
            marks(ax, key, value, x_key)
        for j, law in enumerate(laws):  # one legend entry per law's line style
            ax.plot([], [], styles[j % len(styles)], color="0.3", lw=0.9, label=f"{law} law")
        ax.set(xlabel=xlabel, ylabel="friction ratio FR [-]", ylim=(0, 1.05))
        ax.legend(title=title, fontsize=9)
        what = "averaged over coupling laws (thin lines: each law)\n" if laws else ""
        ax.set_title(
            f"{what}dark: mean FR 95%; light: next pull 95%; points: each trace;\n"
            "grey: the tested range (outside it the model extrapolates)",
            fontsize=9,
        )
        return _save(fig, path)

    p1 = panel(
        loads,
        amp_grid,
        lambda load: band([load], amp_grid),
        "normal_load_n",
        "amplitude_fraction",
        lambda load: f"{load:g} N",
        "commanded amplitude fraction [-]",
        "normal load",
        out / "fr_vs_amplitude.png",
        alphas,
    )
    p2 = panel(
        alphas,
        load_grid,
        lambda alpha: band(load_grid, [alpha]),
        "amplitude_fraction",
        "normal_load_n",
        lambda alpha: f"{100 * alpha:.0f}%",
        "normal load [N]",
        "amplitude",
        out / "fr_vs_load.png",
        loads,
    )
    return p1, p2


def amplitude_map_figure(
    draws: Draws, targets: tuple[float, ...], loads: np.ndarray, speed_m_s: float, path: Path
) -> tuple[Path, list]:
    """Amplitude needed for each target reduction against load, median and 95% band;
    loads where the target is out of reach are left blank and said so."""
    fig, ax = subplots(figsize=(6, 4))
    rows = []
    for c, target in enumerate(targets):
        res = amplitude_for_reduction(draws, target, loads, [speed_m_s])
        rows += res
        med = np.array([r.amplitude[0] if r.reachable else np.nan for r in res])
        lo = np.array([r.amplitude[1] if r.reachable else np.nan for r in res])
        # The upper band edge is infinite where some draws cannot reach the target.
        hi = np.array([min(r.amplitude[2], 1.05) if r.reachable else np.nan for r in res])
        ax.fill_between(loads, lo, hi, color=f"C{c}", alpha=0.25)
        ax.plot(loads, med, color=f"C{c}", label=f"{target:g}% reduction")
    ax.axhline(1.0, color="k", lw=0.8, ls="--")
    ax.set(xlabel="normal load [N]", ylabel="amplitude fraction needed [-]", ylim=(0, 1.1))
    ax.legend()
    return _save(fig, path), rows
