"""``idtool study fits/NAME --truths 100 --out studies/NAME``: simulation-based checks of
a design (and a plan's pulls) on Dask."""

from __future__ import annotations

import argparse
import os
from pathlib import Path

from idtool._cli._args import LazyChoices
from idtool._errors import IdtoolError

__all__ = ["register"]


def _jax_config() -> dict[str, object]:
    """The CLI's compilation cache for the workers (:mod:`idtool._cli._cache`), or none."""
    from idtool._cli._cache import compilation_cache_settings

    path = os.environ.get("IDTOOL_CACHE_DIR", os.path.expanduser("~/.cache/idtool/jax"))
    return compilation_cache_settings(path) if path else {}


def _run(args: argparse.Namespace) -> int:
    # the options and the folders are checked before the fit is read
    if args.truths < 1:
        raise IdtoolError(f"--truths {args.truths}: give at least 1")
    if args.scheduler is None and args.workers < 1:
        raise IdtoolError(f"--workers {args.workers}: give at least 1")
    if args.uniform and args.plan is None:
        raise IdtoolError("--uniform needs --plan PLAN_DIR (the plan whose uniform grid to run)")
    if args.plan is not None and not (Path(args.plan) / "plan.json").is_file():
        raise IdtoolError(
            f"--plan {args.plan}: no plan.json there; give a folder 'idtool plan' wrote"
        )
    if args.params is not None and not Path(args.params).is_file():
        raise IdtoolError(f"--params {args.params}: no such file; give a simulator parameter file")
    if Path(args.out).exists() and not args.force:
        raise IdtoolError(f"{args.out} already exists; pass --force to replace it")
    if not (Path(args.fit) / "fit.json").is_file():
        raise IdtoolError(f"{args.fit}: no fit.json there; give a folder 'idtool fit' wrote")
    import idtool
    from idtool._study._study import partial_folder, study

    fit = idtool.load_fit(args.fit)
    result = study(
        fit,
        args.truths,
        args.out,
        plan=args.plan,
        uniform=args.uniform,
        departure=args.departure,
        sample=args.sample,
        workers=args.workers,
        scheduler=args.scheduler,
        seed=args.seed,
        force=args.force,
        params=args.params,
        progress=not (args.no_progress or args.quiet),
        stop_after=args.stop_after,
        jax_config=_jax_config(),
    )
    if result.summary is None:
        print(
            f"stopped after {len(result.records)} of {args.truths} tasks; their records are in "
            f"{partial_folder(args.out)}/records.jsonl: run the same command to resume"
        )
        return 0
    print(result.text)
    print(f"wrote {args.out}/summary.txt, summary.json, study.png, records.jsonl")
    return 0


def _departures() -> tuple[str, ...]:
    from idtool._study._study import DEPARTURES  # imports JAX: read when needed

    return DEPARTURES


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "study",
        help="simulation-based check of a design: band width, coverage, SBC ranks, law wins",
        description="Draw truths from a fit (its posterior if sampled, else its covariance; "
        "the coupling laws by their weights), simulate the fit's design (plus a plan's "
        "pulls) for each, fit (and sample) with the defaults, and report the achieved FR "
        "band half-width against the expected, the coverage of the 95%% intervals, the "
        "SBC rank statistics and how often the true coupling law wins. The fits run on "
        "Dask: a local cluster of --workers processes, or the cluster at --scheduler. "
        "Records stream to OUT.partial/records.jsonl as they finish: the same command "
        "resumes an interrupted study.",
    )
    p.add_argument("fit", help="fit folder, e.g. fits/NAME")
    p.add_argument("--out", required=True, help="output folder, e.g. studies/NAME")
    p.add_argument("--plan", help="an 'idtool plan' folder: its pulls are simulated too")
    p.add_argument(
        "--uniform",
        action="store_true",
        help="simulate the plan's uniform grid of as many pulls instead of its pulls",
    )
    p.add_argument("--truths", type=int, default=100, help="truths (fits) to run (default 100)")
    p.add_argument(
        "--departure",
        choices=LazyChoices(_departures),
        metavar="KIND",  # argparse reads the choices for a missing metavar: JAX at --help
        default="clean",
        help="the simulated bench's departure from the fit's model: %(choices)s (default "
        "clean: none)",
    )
    p.add_argument(
        "--sample",
        action=argparse.BooleanOptionalAction,
        default=False,
        help="also sample each fit's posterior until converged (minutes a fit; default off)",
    )
    p.add_argument("--workers", type=int, default=2, help="local worker processes (default 2)")
    p.add_argument(
        "--scheduler", metavar="ADDRESS", help="a Dask scheduler's address, e.g. tcp://host:8786"
    )
    p.add_argument(
        "--params", help="simulator parameter file: load cell, actuator, timing (the example's)"
    )
    p.add_argument("--seed", type=int, default=0, help="the study's seed (default 0)")
    p.add_argument("--stop-after", type=int, metavar="N", help="stop after N tasks (resume later)")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.add_argument("--force", action="store_true", help="replace --out if it exists")
    p.set_defaults(func=_run)
