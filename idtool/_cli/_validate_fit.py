"""``idtool validate-fit fits/NAME [DATASET]``: predict traces the fit did not see."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import idtool
from idtool._atomic import refuse_existing, write_text_atomic
from idtool._cli._args import load_numerics
from idtool._fit._folder import VALIDATION_JSON
from idtool._provenance import provenance
from idtool._version import __version__

__all__ = ["VALIDATION_FILE", "register"]

VALIDATION_FILE = VALIDATION_JSON.name


def _run(args: argparse.Namespace) -> int:
    load_numerics()  # first: the collector then skips what it imports

    out = Path(args.fit) / VALIDATION_FILE
    refuse_existing(out, args.force)
    fit = idtool.load_fit(args.fit)
    result = fit.validate(args.dataset, args.traces, seed=args.seed)
    prov = provenance(args.argv)
    doc = {  # datasets_schema/validation.schema.json
        "schema_version": VALIDATION_JSON.schema_version,
        **result.to_dict(),
        "seed": args.seed,
        "idtool_version": __version__,
        "command": prov["command"],
        "versions": prov["versions"],
        "created_utc": prov["created_utc"],
    }
    write_text_atomic(out, json.dumps(doc, indent=1) + "\n")
    if args.json:
        print(json.dumps(doc, indent=1))
        return 0
    print(result.table())
    print(result.summary())
    for w in result.warnings:
        print(f"warning: {w}")
    print(f"wrote {out} (idtool report {args.fit} shows it)")
    return 0


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "validate-fit",
        help="predict held-out traces with a fit: force fit %%, FR against its band",
        description="Held-out validation: each trace the fit did not see is predicted "
        "with the fit's shared parameters (only the trace's own nuisances, load-cell "
        "offset, pull start and horn lags, are fitted to it). Per trace: the force fit "
        "% (100 (1 - |y - y_hat| / |y - mean y|), MATLAB's NRMSE fit) and RMSE [N], and "
        "the trace's own friction ratio against the fit's 95% band for a new pull; "
        "their coverage (about 95% if the bands are honest). Written to "
        f"fits/NAME/{VALIDATION_FILE} and shown by 'idtool report'.",
    )
    p.add_argument("fit", help="a fit folder made by 'idtool fit'")
    p.add_argument(
        "dataset",
        nargs="?",
        help="the traces to predict (default: the fit's own dataset, whose traces the "
        "fit did not use: fit with --traces to hold some out)",
    )
    p.add_argument(
        "--traces",
        metavar="PATTERN",
        help="shell patterns selecting the traces, comma-separated, '!' excludes "
        "(default: those the fit did not use, or all of another dataset)",
    )
    p.add_argument("--seed", type=int, default=0, help="seed of the prediction draws")
    p.add_argument("--force", action="store_true", help=f"replace an existing {VALIDATION_FILE}")
    p.add_argument("--json", action="store_true", help=f"print {VALIDATION_FILE}")
    p.set_defaults(func=_run)
