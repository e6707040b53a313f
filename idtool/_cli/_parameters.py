"""``idtool parameters``: a model's shared parameters as a parameter table to edit."""

from __future__ import annotations

import argparse
from pathlib import Path

from idtool._atomic import refuse_existing, write_text_atomic
from idtool._cli._args import add_law_argument, registry_names
from idtool._model._names import DEFAULT_ACTUATOR, DEFAULT_COUPLING, DEFAULT_LEVEL_MODEL

__all__ = ["register"]


def _run(args: argparse.Namespace) -> int:
    # local, as in every command: JAX and the figures load only when a command needs them
    from idtool._fit._parameter_table import parameter_template
    from idtool._model._actuator import ACTUATORS
    from idtool._model._benchmodel import shared_params_of
    from idtool._model._coupling import COUPLINGS
    from idtool._model._laws import FRICTION_LAWS
    from idtool._model._level_model import LEVEL_MODELS

    params = shared_params_of(
        FRICTION_LAWS.get(args.law),
        COUPLINGS.get(args.coupling),
        ACTUATORS.get(args.actuator),
        level=LEVEL_MODELS.get(args.level),
    )
    table = parameter_template(params)
    if args.out is None:
        print(table, end="")
        return 0
    refuse_existing(Path(args.out), args.force)
    write_text_atomic(Path(args.out), table)
    print(f"wrote {args.out}: edit it, then 'idtool fit DATASET --parameters {args.out}'")
    return 0


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "parameters",
        help="write a model's parameter table (PEtab-like) for 'idtool fit --parameters'",
        description="The shared parameters of a friction law, coupling law, actuator "
        "model and level model, one row each with idtool's unit, bounds and scale, every "
        "one estimated: a parameter table to edit (fix a value with estimate 0 and "
        "nominalValue, narrow the bounds, give a start or a prior) and pass to 'idtool fit "
        "--parameters'.",
    )
    add_law_argument(p)
    p.add_argument(
        "--coupling",
        choices=registry_names("COUPLINGS"),
        metavar="LAW",
        default=DEFAULT_COUPLING,
        help=f"coupling law: %(choices)s (default {DEFAULT_COUPLING})",
    )
    p.add_argument(
        "--actuator",
        choices=registry_names("ACTUATORS"),
        metavar="MODEL",
        default=DEFAULT_ACTUATOR,
        help=f"actuator model: %(choices)s (default {DEFAULT_ACTUATOR})",
    )
    p.add_argument(
        "--level",
        choices=registry_names("LEVEL_MODELS"),
        metavar="MODEL",
        default=DEFAULT_LEVEL_MODEL,
        help=f"level model: %(choices)s (default {DEFAULT_LEVEL_MODEL})",
    )
    p.add_argument("-o", "--out", help="write the table to this file (default: print it)")
    p.add_argument("--force", action="store_true", help="replace an existing --out")
    p.set_defaults(func=_run)
