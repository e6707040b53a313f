"""``idtool report fits/NAME``: the self-contained HTML uncertainty report."""

from __future__ import annotations

import argparse

from idtool._cli._args import number_list
from idtool._cli._plan import add_goal_arguments, goal_options

__all__ = ["register"]


def _run(args: argparse.Namespace) -> int:
    # local, as in every command: JAX and the figures load only when a command needs them
    from idtool._report._html import write_report

    goal = goal_options(args)  # checked before the fit is read
    path = write_report(
        args.fit,
        targets=args.targets,
        loads_n=args.loads or (),
        goal=goal.goal,
        n_pulls=goal.n_pulls,
        at=goal.at,
        half_width=goal.half_width,
        rel=goal.rel,
        weight=goal.weight,
        plan=not args.no_plan,
    )
    print(f"report: {path}")
    return 0


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "report",
        help="write fits/NAME/report.html (self-contained, opens offline)",
        description="Uncertainty report of a fit (and its posterior, if sampled). First "
        "the answer: the friction ratio and reduction at each tested load and amplitude "
        "with 95% bands, and the amplitude needed for each target reduction; then "
        "banners for an unconverged chain, misfit or extrapolation; then the evidence "
        "(estimates, correlations, traces, residuals, corner plot, convergence, curves, "
        "model comparison, provenance) and a sign-off block. When the fit misses the "
        "planning goal (default: every physical parameter to a relative sd of 0.05), "
        "a section 'What to measure next' with the next pulls ('idtool plan''s) and "
        "plan.csv beside the report. Also figures/*.png and report.md. Prints cleanly "
        "to PDF from a browser.",
    )
    p.add_argument("fit", help="a fit folder made by 'idtool fit'")
    p.add_argument(
        "--targets",
        type=number_list,
        help="target friction reductions [%%] for the amplitude table, e.g. 30,50 (default)",
    )
    p.add_argument(
        "--loads",
        type=number_list,
        help="normal loads [N] at which to give the amplitude too, besides the tested "
        "ones, e.g. 300,800 (outside the tested range: flagged as extrapolation)",
    )
    add_goal_arguments(p, "parameters")
    p.add_argument(
        "--no-plan",
        action="store_true",
        help="leave out the goal's check and the section 'What to measure next'",
    )
    p.set_defaults(func=_run)
