"""``idtool compare fits/A fits/B``: materials (or sessions) side by side in one report."""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path

from idtool._atomic import refuse_existing
from idtool._cli._args import number_list
from idtool._errors import IdtoolError
from idtool._fit._folder import FIT_JSON

__all__ = ["register"]


def _check(name: str, values: list[float] | None, lo: float, hi: float) -> None:
    for v in values or []:
        if not lo < v <= hi:
            raise IdtoolError(f"{name} {v:g}: must lie in ({lo:g}, {hi:g}]")


def _run(args: argparse.Namespace) -> int:
    # local: the comparison imports JAX, which the other commands' start-up must not
    from idtool._entry import compare_fits
    from idtool._report._compare import TARGETS, default_out

    # Everything that can be refused is refused before the fits are read and compared
    # (tens of seconds), and nothing is written then.
    if len(args.fits) < 2:
        raise IdtoolError(f"give at least two fit folders to compare (got {len(args.fits)})")
    _check("--load", args.load, 0.0, math.inf)
    _check("--amplitude", args.amplitude, 0.0, 1.0)
    _check("--speed", None if args.speed is None else [args.speed], 0.0, math.inf)
    for t in args.targets or []:
        if not 0.0 < t < 100.0:
            raise IdtoolError(f"--targets {t:g}: give reductions [%] in (0, 100)")
    if args.draws < 10:
        raise IdtoolError(f"--draws {args.draws}: give at least 10")
    for folder in args.fits:
        if not (Path(folder) / FIT_JSON.name).is_file():
            raise IdtoolError(f"{folder}: not a fit folder (no fit.json); run 'idtool fit' first")
    out = Path(args.out) if args.out else default_out(args.fits)
    refuse_existing(out, args.force)

    comparison = compare_fits(
        args.fits,
        args.load,
        args.amplitude,
        speed_m_s=args.speed,
        targets=args.targets or TARGETS,
        max_draws=args.draws,
        seed=args.seed,
    )
    page = comparison.write(out, force=args.force, figures=not args.no_figures)
    if args.json:
        print(json.dumps(comparison.to_dict(figures=not args.no_figures), indent=1))
    else:
        print(comparison.summary())
        print(f"compare: {page}")
    return 0


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "compare",
        help="fits side by side: which material reduces friction more (compare.html)",
        description="Compare two or more fits (materials, or sessions) in one report: the "
        "physical estimates side by side with 95% intervals; at each load x amplitude "
        "each fit's friction ratio, the difference in reduction [percentage points] and "
        "the probability that the first fit (the reference) reduces friction more than "
        "each other one, from independent draws of their posteriors (without a "
        "posterior: Gaussian draws on the fit's covariance, flagged); the amplitude each "
        "needs for the target reductions; FR against amplitude and load with every fit's "
        "band overlaid. Writes compare.html (self-contained), compare.json and the "
        "figures into --out. Fits from different rigs are refused. Fits of friction "
        "tables (kind: levels) are compared at the conditions every table measured "
        "(--load and --speed move them): compare.txt, compare.json, fr_by_condition.png.",
    )
    p.add_argument("fits", nargs="+", metavar="FIT", help="fit folders; the first is the reference")
    p.add_argument(
        "--load",
        type=number_list,
        help="normal load(s) [N], e.g. 450,670 (default: the loads every fit tested)",
    )
    p.add_argument(
        "--amplitude",
        type=number_list,
        help="commanded amplitude fraction(s) in (0, 1] (default: the ones every fit tested)",
    )
    p.add_argument("--speed", type=float, help="pull speed [m/s] (default: the fits' common one)")
    p.add_argument(
        "--targets",
        type=number_list,
        help="target friction reductions [%%] for the amplitude table, e.g. 30,50 (default)",
    )
    p.add_argument("--out", help="output folder (default: compare-A-B beside the first fit)")
    p.add_argument("--force", action="store_true", help="replace an existing --out")
    p.add_argument("--json", action="store_true", help="print compare.json")
    p.add_argument(
        "--no-figures",
        action="store_true",
        help="leave out the two figures (FR against amplitude and load): their curves "
        "solve every fit's contact model per draw at 100 points, most of the time of "
        "comparing sdof fits",
    )
    p.add_argument("--draws", type=int, default=2000, help="draws per fit (default 2000)")
    p.add_argument("--seed", type=int, default=0, help="seed of the draws (default 0)")
    p.set_defaults(func=_run)
