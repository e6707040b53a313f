"""``idtool fit-law SERIES --law lugre --out fits/NAME``: a friction law fitted to a
velocity-force series (docs/how-to/fit-law.md)."""

from __future__ import annotations

import argparse

from idtool._atomic import refuse_existing
from idtool._cli._args import LazyChoices

__all__ = ["register"]


def _run(args: argparse.Namespace) -> int:
    refuse_existing(args.out, args.force)  # before the fit, not after it
    import idtool

    series = idtool.read_series(args.series)
    fit = idtool.fit_law(series, args.law, posterior=args.posterior, seed=args.seed)
    fit.save(args.out, force=args.force, argv=getattr(args, "argv", None))
    print(fit.report())
    print(f"wrote {args.out}/fit_law.json, report.txt, fit_law.png")
    return 0


def _law_names() -> tuple[str, ...]:
    from idtool._model._series_law import series_law_names  # imports JAX: read when needed

    return series_law_names()


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "fit-law",
        help="fit a friction law (LuGre, Dahl, Coulomb-viscous) to a velocity-force series",
        description="Fit a friction law to a time series of slip velocity (or displacement) "
        "and friction force (and normal load, if it varies): the bristle state integrated "
        "through the series, parameters with 95%% intervals checked against the profile "
        "likelihood, and a statement where the series cannot inform a parameter. Writes "
        "fit_law.json, report.txt and fit_law.png into --out. The series format: "
        "docs/how-to/fit-law.md.",
    )
    p.add_argument("series", help="CSV or Parquet file: time, velocity or displacement, force")
    p.add_argument(
        "--law",
        default="lugre",
        choices=LazyChoices(_law_names),
        metavar="LAW",  # argparse reads the choices for a missing metavar: JAX at --help
        help="friction law: %(choices)s (default lugre)",
    )
    p.add_argument("--out", required=True, help="output folder, e.g. fits/NAME")
    p.add_argument("--posterior", action="store_true", help="also sample the posterior (emcee)")
    p.add_argument("--seed", type=int, default=0, help="seed of the sampler")
    p.add_argument("--force", action="store_true", help="replace --out if it exists")
    p.set_defaults(func=_run)
