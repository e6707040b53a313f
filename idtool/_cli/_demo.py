"""``idtool demo``: the whole path on the shipped example dataset, into ``fits/demo/``.

validate -> fit -> a short sampling run -> predict -> report, each step exactly the
command a user would type (this module only strings them together).
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

from idtool._atomic import refuse_existing
from idtool._cli._main import EXIT_NOT_CONVERGED, main
from idtool._data._example import example_dataset_path

__all__ = ["register"]


def _run(args: argparse.Namespace) -> int:
    out = Path(args.out)
    refuse_existing(out, args.force)
    data = str(example_dataset_path())
    seed = str(args.seed)
    steps_arg = [] if args.steps is None else ["--steps", str(args.steps)]
    steps = [
        ["validate", data],
        ["fit", data, "--out", str(out), "--seed", seed, "--force"],
        ["sample", str(out), "--seed", seed, "--no-progress", *steps_arg],
        ["predict", str(out), "--load", "270,450,670", "--amplitude", "0.5,0.7"],
        ["predict", str(out), "--load", "450,670", "--target-reduction", "50"],
        ["report", str(out)],
    ]
    started = time.perf_counter()
    final = 0
    for argv in steps:
        print(f"\n$ idtool {' '.join(argv)}", flush=True)
        status = main(argv)
        if status == EXIT_NOT_CONVERGED:  # go on: predict and report say so too
            final = status
        elif status:
            return status
    print(f"\ndemo finished in {time.perf_counter() - started:.0f} s")
    print(f"report: {(out / 'report.html').resolve()}")
    return final


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "demo",
        help="run validate, fit, sample, predict and report on the example dataset",
        description="The whole idtool path on the shipped example dataset.",
    )
    p.add_argument("--out", default="fits/demo", help="output folder (default fits/demo)")
    p.add_argument(
        "--steps",
        type=int,
        default=None,
        help="a fixed number of sampling steps (default: sample until converged)",
    )
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--force", action="store_true", help="replace an existing --out")
    p.set_defaults(func=_run)
