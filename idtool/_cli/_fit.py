"""``idtool fit DATASET --out fits/NAME``: identify Kt, mu and the coupling."""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import idtool
from idtool._atomic import refuse_existing
from idtool._cli._args import add_law_argument, load_numerics, registry_names
from idtool._errors import IdtoolError
from idtool._model._names import BY_DESIGN, DEFAULT_DIRECTION, DEFAULT_NOISE
from idtool._plotting import MODULES, import_in_background

__all__ = ["register"]

# Imported in a background thread while the fit waits for XLA: the figures' modules
# and scipy.special, which the levels model's lack-of-fit p-value calls once
# (idtool._fit._variability: 0.15-0.25 s of import on the fit's path otherwise).
LATE_IMPORTS = (*MODULES, "scipy.special")


def _run(args: argparse.Namespace) -> int:
    load_numerics()  # first: the collector then skips what it imports

    started = time.perf_counter()
    refuse_existing(args.out, args.force)  # before minutes of fitting, not after
    from idtool._data._levels import is_levels_dataset

    if is_levels_dataset(args.dataset):
        return _run_levels(args, started)
    dataset = idtool.load_dataset(Path(args.dataset))
    for w in dataset.warnings:  # on stderr: stdout may be the --json document
        print(f"idtool fit: {w}", file=sys.stderr)
    # matplotlib's imports while the fit waits for XLA (fit.save draws two figures)
    drawing = import_in_background(LATE_IMPORTS)
    fit = idtool.fit(
        dataset,
        law=args.law,
        coupling=args.coupling,
        noise=args.noise,
        variability=args.variability == "on",
        actuator=args.actuator,
        offset=args.offset,
        level=args.level,
        direction=args.direction,
        seed=args.seed,
        starts=args.starts,
        compare_laws=args.compare_laws,
        profile=args.profile,
        mains_hz=args.mains_hz,
        progress=None if args.quiet else _progress,
        traces=args.traces,
        parameters=args.parameters,
        fix=_fixed(args.fix),
    )
    drawing.join()  # fit.save draws: its imports done, not raced
    fit.save(args.out, force=args.force, command=args.argv)
    if args.json:  # fit.json as written, for scripts (the report is in report.txt)
        print(json.dumps(fit.to_json(), indent=1))
        return 0
    print(fit.report())
    print(
        f"wrote {args.out}/ (fit.json, report.txt, traces.png, residuals.png) in "
        f"{time.perf_counter() - started:.1f} s"
    )
    return 0


def _run_levels(args: argparse.Namespace, started: float) -> int:
    """A steady-state friction table (kind: levels): :func:`idtool.fit_levels`; the
    trace fit's options that a table has no use for are refused, not ignored."""
    unused = [
        f"--{name.replace('_', '-')}"
        for name in ("noise", "actuator", "offset", "level", "traces", "parameters", "fix")
        if getattr(args, name, None) not in (None, "auto", DEFAULT_NOISE, False)
    ]
    if unused:
        raise IdtoolError(
            f"{args.dataset} is a friction table (kind: levels): {', '.join(unused)} "
            "apply to traces only; leave them out"
        )
    fit = idtool.fit_levels(
        args.dataset,
        law=args.law,
        coupling=args.coupling,
        direction=args.direction,
        seed=args.seed,
    )
    fit.save(args.out, force=args.force, command=args.argv)
    if args.json:
        print(json.dumps(fit.to_json(args.argv), indent=1))
        return 0
    print(fit.report())
    figure = ", fr_vs_speed.png" if fit.spans_speeds else ""
    print(
        f"wrote {args.out}/ (fit.json, report.txt{figure}) in {time.perf_counter() - started:.1f} s"
    )
    return 0


def _fixed(items: list[str] | None) -> dict[str, float] | None:
    """``--fix NAME=VALUE`` options as a mapping (an unreadable one: located error)."""
    # local, as in every command: JAX and the figures load only when a command needs them
    from idtool._fit._parameter_table import parse_fix

    settings = parse_fix(items or [])
    return {s.name: float(s.nominal) for s in settings if s.nominal is not None} or None


def _progress(line: str) -> None:
    # stderr: stdout carries the report (or the --json document)
    print(f"idtool fit: {line}", file=sys.stderr, flush=True)


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "fit",
        help="fit Kt, mu and the coupling to a dataset",
        description="Joint least-squares fit of the bench model to every trace of a v1 "
        "dataset (multi-start Levenberg-Marquardt, AR(1) noise, Gauss-Newton intervals). "
        "On a friction table (a dataset of kind 'levels', from import-levels): Kt, mu and "
        "the coupling through its friction ratios, with --law, --coupling, --direction "
        "and --seed (docs/how-to/levels-table.md).",
    )
    p.add_argument("dataset", help="dataset folder (or its dataset.json)")
    p.add_argument("--out", required=True, help="output folder, e.g. fits/NAME")
    add_law_argument(p)
    p.add_argument(
        "--coupling",
        choices=registry_names("COUPLINGS", "auto", BY_DESIGN),
        metavar="LAW",
        default=BY_DESIGN,
        help="coupling law: %(choices)s. auto fits every coupling law and keeps the "
        f"lowest BIC; {BY_DESIGN} (default) fits power-limited (the paper's finding), and "
        "also load-power where some load and amplitude were pulled at two or more speeds "
        "(they pin Kt whatever the law; the lower BIC is kept)",
    )
    p.add_argument(
        "--actuator",
        choices=registry_names("ACTUATORS", "auto"),
        metavar="MODEL",
        default="auto",
        help="how the force follows its target, %(choices)s: slope (constant slopes), lag "
        "(first-order lag with a rate limit); default auto fits both and keeps the lower BIC",
    )
    p.add_argument(
        "--offset",
        choices=registry_names("OFFSETS", "auto"),
        metavar="MODEL",
        default="auto",
        help="the load-cell offset within a trace, %(choices)s: constant, drift (linear, "
        "per trace); default auto fits both and keeps the lower BIC",
    )
    p.add_argument(
        "--level",
        choices=registry_names("LEVEL_MODELS", "auto"),
        metavar="MODEL",
        default="auto",
        help="how the friction levels move within their plateaus, %(choices)s: steady, "
        "relaxing (the ON level relaxes from its cold-horn value with a time constant), "
        "creeping (the friction grows in proportion through the pull); default auto fits "
        "steady and tries the others only where its plateaus drift, keeping the lower BIC",
    )
    p.add_argument(
        "--direction",
        choices=registry_names("DIRECTIONS", "auto"),
        metavar="DIRECTION",
        default=DEFAULT_DIRECTION,
        help="direction of the vibration relative to the sliding, %(choices)s: along "
        f"(default {DEFAULT_DIRECTION}, the seed paper's model), transverse (in the contact "
        "plane, across the sliding), normal (out of plane: the indentation oscillates); "
        "auto fits every direction (with every coupling law fitted) and keeps the lowest "
        "BIC, the others kept by BIC weight for predictions (2-5x the time of a fit "
        "along on the example)",
    )
    p.add_argument(
        "--noise",
        choices=registry_names("NOISE_MODELS"),
        metavar="MODEL",
        default=DEFAULT_NOISE,
        help=f"noise model of the block means: %(choices)s (default {DEFAULT_NOISE})",
    )
    p.add_argument(
        "--variability",
        choices=("on", "off"),
        default="on",
        help="pull-to-pull scatter and operating-point discrepancy in the intervals and "
        "bands (default on; off gives the noise-only model, for comparison)",
    )
    p.add_argument("--compare-laws", action="store_true", help="also fit and rank LuGre/Dahl")
    p.add_argument(
        "--profile", action="store_true", help="profile likelihood of each physical parameter"
    )
    p.add_argument("--seed", type=int, default=0, help="seed of the multi-start points")
    p.add_argument("--starts", type=int, default=8, help="multi-start points (default 8)")
    p.add_argument(
        "--mains-hz",
        type=float,
        default=None,
        help="mains frequency [Hz] (50 or 60); default: rig.mains_frequency_hz of the "
        "dataset, else the hum found in the traces, else 50",
    )
    p.add_argument(
        "--traces",
        metavar="PATTERN",
        help="fit only the traces whose ids match these shell patterns, comma-separated; "
        "'!' excludes (e.g. '*,!*_T2.5' holds the 2.5 s pulls out for 'idtool "
        "validate-fit'); fit.json lists the fitted traces",
    )
    p.add_argument(
        "--fix",
        action="append",
        metavar="NAME=VALUE",
        help="hold a shared parameter at a value, SI units (e.g. --fix mu=0.3); repeatable; "
        "not estimated, not sampled, not counted in AIC/BIC",
    )
    p.add_argument(
        "--parameters",
        metavar="FILE",
        help="PEtab-like parameter table (TSV or CSV: parameterId, estimate, nominalValue, "
        "lowerBound, upperBound, parameterScale, objectivePriorType, "
        "objectivePriorParameters): fixed values, bounds, scales, starts and the sampler's "
        "priors; 'idtool parameters' writes one to edit",
    )
    p.add_argument("--force", action="store_true", help="replace an existing --out")
    p.add_argument("--json", action="store_true", help="print fit.json instead of the text report")
    p.set_defaults(func=_run)
