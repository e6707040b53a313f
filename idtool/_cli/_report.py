"""``idtool report fits/NAME``: the self-contained HTML uncertainty report."""

from __future__ import annotations

import argparse

__all__ = ["register"]


def _run(args: argparse.Namespace) -> int:
    from idtool._report._html import write_report

    path = write_report(args.fit)
    print(f"report: {path}")
    return 0


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "report",
        help="write fits/NAME/report.html (self-contained, opens offline)",
        description="Uncertainty report of a fit (and its posterior, if sampled): "
        "estimates, correlations, traces, residuals, corner plot, convergence, friction "
        "ratio against amplitude and load, amplitude needed for a target reduction, model "
        "comparison, provenance. Also figures/*.png and report.md.",
    )
    p.add_argument("fit", help="a fit folder made by 'idtool fit'")
    p.set_defaults(func=_run)
