"""``idtool simulate-bench``: write a format-v1 dataset from the bench model plus noise."""

from __future__ import annotations

import argparse

from idtool._atomic import refuse_existing
from idtool._errors import IdtoolError

__all__ = ["register"]


def _run(args: argparse.Namespace) -> int:
    # local, as in every command: JAX and the figures load only when a command needs them
    from idtool._simulate._params import load_bench_params
    from idtool._simulate._simulate import TRUTH_FILE, simulate_bench, write_simulation

    refuse_existing(args.out, args.force)
    params = load_bench_params(args.params)
    dataset, truth = simulate_bench(params, args.seed)
    try:
        out = write_simulation(args.out, dataset, truth, force=args.force)
    except OSError as err:  # a bad --out (parent is a file, no permission, disk full)
        raise IdtoolError(f"cannot write {args.out} ({err}); nothing was written") from None
    print(f"wrote {len(dataset.traces)} trace(s) to {out} (seed {args.seed})")
    print(f"sha256  {dataset.sha256}")
    print(f"truth   {out / TRUTH_FILE}")
    print(f"{'id':<18} {'FR':>6} {'Lambda':>7} {'VR':>6}  reaches ON level")
    for t in truth.traces:
        vr = "-" if t.velocity_ratio is None else f"{t.velocity_ratio:.3f}"
        lam = "-" if t.dimensionless_stiffness is None else f"{t.dimensionless_stiffness:.2f}"
        print(
            f"{t.id:<18} {t.friction_ratio:>6.3f} {lam:>7} "
            f"{vr:>6}  {'yes' if t.reaches_on_level else 'no'}"
        )
    noise = params.block_mean_noise
    if noise is not None:
        numbers = ", ".join(f"{k} = {v:g}" for k, v in noise.values().items())
        print(f"block-mean noise from noise model '{noise.model}' ({numbers}) on the fit's blocks")
    if not params.coupling.in_fit:
        print(
            f"coupling law '{params.coupling.law}' is truth only: idtool fit has no such law, "
            "so a fit of this dataset is deliberately misspecified"
        )
    return 0


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "simulate-bench",
        help="simulate bench load-cell traces as a format-v1 dataset",
        description="Simulate the seat-belt bench (the bench model plus load-cell noise, "
        "and block-mean noise from a registered noise model if the file's "
        "block_mean_noise asks for it) for the experiment matrix of a parameter file "
        "(datasets_schema/simulator_params.schema.json) and write the dataset with "
        "true_parameters.json.",
    )
    p.add_argument("--out", required=True, metavar="DIR", help="dataset folder to create")
    p.add_argument("--params", required=True, metavar="P.json", help="simulator parameter file")
    p.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    p.add_argument("--force", action="store_true", help="replace DIR if it exists")
    p.set_defaults(func=_run)
