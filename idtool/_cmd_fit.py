"""``idtool fit DATASET --out fits/NAME``: identify Kt, mu and the coupling."""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

from ._atomic import atomic_output_dir, refuse_existing
from ._errors import IdtoolError

__all__ = ["register"]


def _run(args: argparse.Namespace) -> int:
    from ._dataset import load_dataset
    from ._fitreport import fit_json, fit_report, plot_fit
    from ._fitrun import fit_dataset
    from ._fitstore import save_fit_state

    started = time.perf_counter()
    out = Path(args.out)
    refuse_existing(out, args.force)
    if args.starts < 1:
        raise IdtoolError(f"--starts {args.starts}: give at least 1")
    dataset = load_dataset(args.dataset)
    dataset_path = str(Path(args.dataset).resolve())
    for w in dataset.warnings:
        print(f"idtool fit: {w}")
    run = fit_dataset(
        dataset,
        law=args.law,
        coupling=args.coupling,
        seed=args.seed,
        n_starts=args.starts,
        compare_laws=args.compare_laws,
        profile=args.profile,
        mains_hz=args.mains_hz,
    )
    report = fit_report(run)
    with atomic_output_dir(out, force=args.force) as tmp:
        doc = fit_json(run, dataset_path, args.argv)
        doc["seconds"] = round(time.perf_counter() - started, 2)
        (tmp / "fit.json").write_text(json.dumps(doc, indent=1) + "\n")
        (tmp / "report.txt").write_text(report + "\n")
        save_fit_state(tmp, run.chosen)
        plot_fit(run, tmp)
    print(report)
    print(
        f"wrote {out}/ (fit.json, report.txt, traces.png, residuals.png) in "
        f"{time.perf_counter() - started:.1f} s"
    )
    return 0


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "fit",
        help="fit Kt, mu and the coupling to a dataset",
        description="Joint least-squares fit of the bench model to every trace of a v1 "
        "dataset (multi-start Levenberg-Marquardt, AR(1) noise, Gauss-Newton intervals).",
    )
    p.add_argument("dataset", help="dataset folder (or its dataset.json)")
    p.add_argument("--out", required=True, help="output folder, e.g. fits/NAME")
    p.add_argument("--law", choices=("dahl", "lugre"), default="dahl")
    p.add_argument(
        "--coupling",
        choices=("constant", "power-limited", "auto"),
        default="power-limited",
        help="coupling law (default power-limited, the paper's finding); auto fits both "
        "and keeps the lower BIC",
    )
    p.add_argument("--compare-laws", action="store_true", help="also fit and rank LuGre/Dahl")
    p.add_argument(
        "--profile", action="store_true", help="profile likelihood of each physical parameter"
    )
    p.add_argument("--seed", type=int, default=0, help="seed of the multi-start points")
    p.add_argument("--starts", type=int, default=8, help="multi-start points (default 8)")
    p.add_argument("--mains-hz", type=float, default=50.0, help="mains frequency (50 or 60)")
    p.add_argument("--force", action="store_true", help="replace an existing --out")
    p.set_defaults(func=_run)
