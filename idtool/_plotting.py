"""Figures without pyplot, for the library's own PNG files.

A library function that writes a figure must not switch the caller's matplotlib
backend (a notebook's inline plots would stop) nor leave figures in pyplot's registry:
:func:`subplots` builds a bare ``matplotlib.figure.Figure``, whose ``savefig`` renders
with Agg whatever the backend. matplotlib is imported here, on first use only.
"""

from __future__ import annotations

from typing import Any, Literal

__all__ = ["subplots"]


def subplots(
    *args: Any,
    figsize: tuple[float, float],
    layout: Literal["constrained", "compressed", "tight"] | None = None,
    **kw: Any,
):
    """``(figure, axes)`` as ``pyplot.subplots`` gives them, outside pyplot."""
    from matplotlib.figure import Figure

    fig = Figure(figsize=figsize, layout=layout)
    return fig, fig.subplots(*args, **kw)
