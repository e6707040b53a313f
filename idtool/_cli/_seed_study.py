"""``idtool seed-study --out DIR``: the paper's Figures 8-11 as PNGs and a tidy CSV."""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

from idtool._atomic import atomic_output_dir
from idtool._provenance import provenance

__all__ = ["register"]


def _run(args: argparse.Namespace) -> int:
    # local, as in every command: JAX and the figures load only when a command needs them
    from idtool._model._seed_study import plot_seed_study, seed_study

    started = time.perf_counter()
    with atomic_output_dir(args.out, force=args.force) as tmp:
        table = seed_study()
        table.to_csv(tmp / "seed_study.csv", index=False)
        plot_seed_study(table, tmp)
        meta = provenance(args.argv) | {"seconds": round(time.perf_counter() - started, 2)}
        (tmp / "provenance.json").write_text(json.dumps(meta, indent=1) + "\n")
    out = Path(args.out)
    print(f"seed study: {len(table)} rows in {time.perf_counter() - started:.1f} s")
    for name in sorted(p.name for p in out.iterdir()):
        print(f"  {out / name}")
    return 0


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "seed-study",
        help="reproduce the paper's Section 3.6 study (Figures 8-11)",
        description="Sweeps of Fe, mu, m and Ks around Table 2 on the SDOF transducer: "
        "friction ratio and power dissipation ratio against velocity ratio.",
    )
    p.add_argument("--out", required=True, help="output folder (created atomically)")
    p.add_argument("--force", action="store_true", help="replace an existing --out")
    p.set_defaults(func=_run)
