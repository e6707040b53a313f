"""Figures without pyplot, for the library's own PNG files.

A library function that writes a figure must not switch the caller's matplotlib
backend (a notebook's inline plots would stop) nor leave figures in pyplot's registry:
:func:`subplots` builds a bare ``matplotlib.figure.Figure``, whose ``savefig`` renders
with Agg whatever the backend. matplotlib is imported here, on first use only.

Print size: :func:`save_figure` renders at 96 dpi, CSS's pixels per inch, so a figure
shown at its own size in report.html (it is at most :data:`MAX_WIDTH_IN` wide, under
the report's column) shows its text at the point size it was drawn with; every text of
the report's figures is at least :data:`MIN_FONT_PT` (tests/test_report.py checks).

A command that computes before it draws imports matplotlib meanwhile
(:func:`import_in_background`).
"""

from __future__ import annotations

import importlib
import threading
from pathlib import Path
from typing import Any, Literal

__all__ = [
    "DPI",
    "MAX_WIDTH_IN",
    "MIN_FONT_PT",
    "MODULES",
    "import_in_background",
    "save_figure",
    "subplots",
]

DPI = 96
MAX_WIDTH_IN = 11.0  # 1056 px: report.html's column is 1068 px, so never scaled down
MIN_FONT_PT = 9.0

# What drawing and saving a figure imports (0.4-0.8 s, most of it matplotlib's own)
MODULES = ("matplotlib.figure", "matplotlib.backends.backend_agg", "PIL.PngImagePlugin")


def import_in_background(modules: tuple[str, ...] = MODULES) -> threading.Thread:
    """Start importing ``modules`` (default :data:`MODULES`) in a daemon thread and
    return it (join it before drawing, or not: an import the caller makes meanwhile
    waits for the thread's).

    For a command that fits and then draws (``idtool fit``): the fit's main thread
    spends most of its time waiting for XLA's programs, which run without Python's
    lock, so the imports cost it little there, where they cost 0.4-0.8 s of wall time
    before the first figure. An import that fails is left for the drawing to raise."""

    def run() -> None:
        for name in modules:
            try:
                importlib.import_module(name)
            except Exception:  # the drawing imports it again and says why
                return

    thread = threading.Thread(target=run, name="idtool-import-matplotlib", daemon=True)
    thread.start()
    return thread


def subplots(
    *args: Any,
    figsize: tuple[float, float],
    layout: Literal["constrained", "compressed", "tight"] | None = None,
    **kw: Any,
):
    """``(figure, axes)`` as ``pyplot.subplots`` gives them, outside pyplot."""
    from matplotlib.figure import Figure

    if figsize[0] > MAX_WIDTH_IN:
        raise ValueError(f"figsize: {figsize[0]:g} in is wider than {MAX_WIDTH_IN:g} in")
    fig = Figure(figsize=figsize, layout=layout)
    return fig, fig.subplots(*args, **kw)


def save_figure(fig, path: str | Path, *, tight: bool = True, **kw: Any) -> Path:
    """Write ``fig`` to ``path`` at :data:`DPI` (``tight``: lay it out first); ``kw``
    go to ``savefig`` (e.g. ``format`` for a temporary file name)."""
    if tight:
        fig.tight_layout()
    fig.savefig(path, dpi=DPI, **kw)
    return Path(path)
