"""``idtool sample fits/NAME``: posterior of a fit with emcee, diagnostics, PPC."""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import idtool
from idtool._cli._args import load_numerics, registry_names
from idtool._cli._main import EXIT_INTERRUPTED, EXIT_NOT_CONVERGED
from idtool._errors import IdtoolError
from idtool._fit._folder import SAMPLE_JSON
from idtool._posterior._runner import MAX_MINUTES, MAX_STEPS

__all__ = ["register"]


def _run(args: argparse.Namespace) -> int:
    load_numerics()  # first: the collector then skips what it imports
    # local, as in every command: JAX and the figures load only when a command needs them
    from idtool._levels._store import is_levels_fit
    from idtool._posterior._sample import CHAIN_FILE
    from idtool._report._sample_text import POSTERIOR_FILES

    started = time.perf_counter()
    folder = Path(args.fit)
    if is_levels_fit(folder):
        return _run_levels(args, folder, started)
    fit = idtool.load_fit(folder)
    chain = folder / CHAIN_FILE
    if chain.exists() and not (args.resume or args.force):
        raise IdtoolError(f"{chain} exists: pass --resume to continue it or --force to start over")
    if args.checkpoint_s < 0:
        raise IdtoolError(f"--checkpoint-s {args.checkpoint_s:g}: give a number >= 0")
    if args.resume and not chain.exists():
        print(f"idtool sample: no {chain} to resume; starting a new chain")
    if args.force and not args.resume:
        for name in POSTERIOR_FILES:  # a new chain: no output of the old one may survive
            (folder / name).unlink(missing_ok=True)
    try:
        fit.sample(
            walkers=args.walkers,
            steps=args.steps,
            seed=args.seed,
            noise=args.noise,
            priors=args.priors,
            chain_path=chain,
            resume=args.resume,
            progress=not (args.no_progress or args.quiet),
            checkpoint_s=args.checkpoint_s,
            max_steps=args.max_steps,
            max_minutes=args.max_minutes,
        )
    except KeyboardInterrupt:
        saved = f"the steps done so far are in {chain}" if chain.exists() else "nothing saved"
        print(f"idtool sample: interrupted; {saved}; continue with --resume", flush=True)
        return EXIT_INTERRUPTED
    report = fit.save_posterior(command=args.argv)
    assert fit.posterior is not None  # save_posterior refuses otherwise
    if args.json:
        print((folder / SAMPLE_JSON.name).read_text())
    else:
        print(report)
        print(
            f"wrote {folder}/ ({', '.join(POSTERIOR_FILES)}) in "
            f"{time.perf_counter() - started:.1f} s"
        )
    diagnostics = fit.posterior.diagnostics
    if not diagnostics.converged:
        # on stderr, so --quiet and --json keep it: the draws are not to be trusted yet
        how = (
            f"--resume --steps {diagnostics.steps + diagnostics.steps_needed}"
            if args.steps is not None
            else "--resume (raise --max-minutes or --max-steps if it stopped at one)"
        )
        print(
            f"idtool sample: the chain did NOT converge (about {diagnostics.steps_needed} "
            f"more steps needed): its outputs are written, but continue it with {how} "
            "before using them",
            file=sys.stderr,
        )
        return EXIT_NOT_CONVERGED
    return 0


def _run_levels(args: argparse.Namespace, folder: Path, started: float) -> int:
    """A friction table's fit (kind: levels): its own likelihood, through the same
    sampler (:meth:`idtool.LevelsFit.sample`)."""
    from idtool._levels._result import CHAIN_H5, POSTERIOR_FILES

    if args.noise is not None:
        raise IdtoolError(
            f"{folder} is the fit of a friction table (kind: levels): --noise applies to "
            "traces only (a table is sampled on its own likelihood); leave it out"
        )
    fit = idtool.load_levels_fit(folder)
    chain = folder / CHAIN_H5
    if chain.exists() and not (args.resume or args.force):
        raise IdtoolError(f"{chain} exists: pass --resume to continue it or --force to start over")
    if args.checkpoint_s < 0:
        raise IdtoolError(f"--checkpoint-s {args.checkpoint_s:g}: give a number >= 0")
    if args.resume and not chain.exists():
        print(f"idtool sample: no {chain} to resume; starting a new chain")
    if args.force and not args.resume:
        for name in POSTERIOR_FILES:  # a new chain: no output of the old one may survive
            (folder / name).unlink(missing_ok=True)
    try:
        post = fit.sample(
            walkers=args.walkers, steps=args.steps, seed=args.seed, priors=args.priors,
            chain_path=chain, resume=args.resume, progress=not (args.no_progress or args.quiet),
            checkpoint_s=args.checkpoint_s, max_steps=args.max_steps,
            max_minutes=args.max_minutes,
        )  # fmt: skip
    except KeyboardInterrupt:
        saved = f"the steps done so far are in {chain}" if chain.exists() else "nothing saved"
        print(f"idtool sample: interrupted; {saved}; continue with --resume", flush=True)
        return EXIT_INTERRUPTED
    report = fit.save_posterior(folder, command=args.argv)
    if args.json:
        print((folder / SAMPLE_JSON.name).read_text())
    else:
        print(report)
        print(
            f"wrote {folder}/ ({', '.join(POSTERIOR_FILES)}) in "
            f"{time.perf_counter() - started:.1f} s"
        )
    if not post.converged:
        d = post.diagnostics
        print(
            f"idtool sample: the chain did NOT converge (about {d['steps_needed']} more steps "
            "needed): its outputs are written, but continue it with --resume before using them",
            file=sys.stderr,
        )
        return EXIT_NOT_CONVERGED
    return 0


def _positive_int(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not an integer") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"{value}: give a positive integer")
    return value


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "sample",
        help="sample the posterior of a fit with emcee",
        description="Posterior of a fit's physical, bench and noise parameters with emcee "
        "(per-trace nuisances integrated out), checkpointed to fits/NAME/chain.h5; writes "
        "posterior.nc (ArviZ InferenceData), sample.json, report_sample.txt and ppc.png.",
    )
    p.add_argument("fit", help="fit folder written by 'idtool fit', e.g. fits/NAME")
    p.add_argument(
        "--walkers",
        type=_positive_int,
        help="walkers (default 16 on the levels model, 32 with --noise or --variability off)",
    )
    p.add_argument(
        "--steps",
        type=_positive_int,
        default=None,
        help="a fixed total chain length (default: sample until converged: kept chain >= 50 "
        "tau with tau settled, split R-hat <= 1.01 and bulk ESS >= 400 for every parameter)",
    )
    p.add_argument(
        "--max-steps",
        type=_positive_int,
        default=MAX_STEPS,
        help=f"without --steps: stop after this many steps in all (default {MAX_STEPS})",
    )
    p.add_argument(
        "--max-minutes",
        type=float,
        default=MAX_MINUTES,
        help=f"without --steps: stop after this many minutes of sampling (default {MAX_MINUTES:g})",
    )
    p.add_argument("--seed", type=int, help="random seed (default 0)")
    p.add_argument(
        "--resume",
        action="store_true",
        help="continue chain.h5 (until converged, or up to --steps in total)",
    )
    p.add_argument("--force", action="store_true", help="discard an existing chain.h5")
    p.add_argument(
        "--noise",
        choices=registry_names("NOISE_MODELS"),
        metavar="MODEL",
        default=None,
        help="noise model of the block means, %(choices)s (default: the fit's, ar1 unless told; "
        "load-cell noise is correlated, independent noise gives falsely tight posteriors)",
    )
    p.add_argument("--priors", help="TOML or JSON file overriding default priors")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.add_argument(
        "--json",
        action="store_true",
        help="print sample.json (the diagnostics) instead of the report",
    )
    p.add_argument(
        "--checkpoint-s",
        type=float,
        default=20.0,
        help="seconds between checkpoints of chain.h5 (default 20)",
    )
    p.set_defaults(func=_run)
