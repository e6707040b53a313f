"""Figures of ``idtool compare``: every fit's friction-ratio band on the same axes.

FR against the commanded amplitude (one panel per compared load) and against the
normal load (one panel per compared amplitude): per fit its median and the 95% band of
the mean FR (the discrepancy included, as in the report), each in its own colour; its
tested range as a bar of that colour above FR = 1 (FR never exceeds 1, so the bars hide
no curve), ticked at each tested value; the compared operating points as dotted lines.
matplotlib is imported on first use (:mod:`idtool._plotting`).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from idtool._plotting import MAX_WIDTH_IN, save_figure, subplots
from idtool._predict._predict import Draws, friction_ratio_draws

__all__ = ["Curve", "compare_figures"]

_GRID = 25  # points per curve
_STYLES = ("-", "--", "-.", ":")  # one per fit: equal curves stay visible, print in grey
_PANEL_IN = 3.6  # width and height of one panel [in]


@dataclass(frozen=True)
class Curve:
    """What one fit contributes: its label, draws and tested loads [N] and amplitudes."""

    label: str
    draws: Draws
    tested_loads_n: Sequence[float]
    tested_amplitudes: Sequence[float]


def _bands(curve: Curve, loads, amps, speed_m_s: float) -> np.ndarray:
    """(median, 2.5%, 97.5%) of the mean FR at the points ``(loads[i], amps[i])``."""
    mean, _ = friction_ratio_draws(
        curve.draws, loads, amps, np.full(np.size(loads), speed_m_s, float)
    )
    return np.percentile(mean, [50.0, 2.5, 97.5], axis=0)


def _panels(n: int):
    cols = min(n, 3)
    rows = math.ceil(n / cols)
    fig, axes = subplots(
        rows,
        cols,
        figsize=(min(_PANEL_IN * cols + 0.6, MAX_WIDTH_IN), _PANEL_IN * rows + 1.0),
        squeeze=False,
        layout="constrained",
    )
    for ax in axes.ravel()[n:]:
        ax.axis("off")
    return fig, axes.ravel()[:n]


def _figure(
    curves: Sequence[Curve],
    panels: Sequence[float],
    x_grid: np.ndarray,
    point: Callable[[float, float], tuple[float, float]],
    stated: Sequence[float],
    tested: Sequence[Sequence[float]],
    xlabel: str,
    title: str,
    path: Path,
    speed_m_s: float,
) -> Path:
    """One panel per value of ``panels``; ``point(x, v)`` gives (load, amplitude)."""
    fig, axes = _panels(len(panels))
    # every fit's bands at every panel's grid in one call per fit
    xs = np.array([point(x, v) for v in panels for x in x_grid], float)
    bands = [_bands(c, xs[:, 0], xs[:, 1], speed_m_s) for c in curves]
    top = 1.04 + 0.05 * len(curves)
    for k, (ax, value) in enumerate(zip(axes, panels, strict=True)):
        cols = slice(k * x_grid.size, (k + 1) * x_grid.size)
        for i, (curve, band) in enumerate(zip(curves, bands, strict=True)):
            med, lo, hi = band[:, cols]
            ax.fill_between(x_grid, lo, hi, color=f"C{i}", alpha=0.3, lw=0)
            style = _STYLES[i % len(_STYLES)]
            ax.plot(x_grid, med, style, color=f"C{i}", label=f"{curve.label}: median, 95% band")
            seen = sorted(tested[i])
            y = 1.04 + 0.05 * i
            ax.plot([seen[0], seen[-1]], [y, y], color=f"C{i}", lw=3, solid_capstyle="butt")
            ax.plot(seen, [y] * len(seen), "|", color=f"C{i}", ms=9, mew=2)
        for x in stated:
            ax.axvline(x, color="0.3", ls=":", lw=1)
        ax.axhline(1.0, color="0.6", lw=0.6)
        ax.set(xlabel=xlabel, ylabel="friction ratio FR [-]", ylim=(0.0, top + 0.02))
        ax.set_xlim(x_grid[0], x_grid[-1])
        ax.set_title(title.format(value), fontsize=10)
    handles, labels = axes[0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="outside lower center", ncols=min(len(curves), 3))
    fig.suptitle(
        "mean FR, median and 95% band per fit; bars above FR = 1: each fit's tested "
        "range;\ndotted: the compared operating points",
        fontsize=9,
    )
    return save_figure(fig, path, tight=False)


def compare_figures(
    curves: Sequence[Curve],
    loads_n: Sequence[float],
    amplitudes: Sequence[float],
    speed_m_s: float,
    out: Path,
) -> tuple[Path, Path]:
    """``fr_vs_amplitude.png`` (a panel per load of ``loads_n`` [N]) and
    ``fr_vs_load.png`` (a panel per amplitude fraction of ``amplitudes``) in ``out``."""
    # FR falls steeply at small amplitudes and flattens: points spaced evenly in log
    amp_grid = np.geomspace(0.03, 1.0, _GRID)
    seen = [*loads_n, *(v for c in curves for v in c.tested_loads_n)]
    load_grid = np.linspace(0.5 * min(seen), 1.5 * max(seen), _GRID)
    p1 = _figure(
        curves,
        loads_n,
        amp_grid,
        lambda x, load: (load, x),
        amplitudes,
        [c.tested_amplitudes for c in curves],
        "commanded amplitude fraction [-]",
        "at {:g} N",
        out / "fr_vs_amplitude.png",
        speed_m_s,
    )
    p2 = _figure(
        curves,
        amplitudes,
        load_grid,
        lambda x, alpha: (x, alpha),
        loads_n,
        [c.tested_loads_n for c in curves],
        "normal load [N]",
        "at amplitude {:.0%}",
        out / "fr_vs_load.png",
        speed_m_s,
    )
    return p1, p2
