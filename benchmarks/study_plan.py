"""Study: does a plan deliver what it expects, and beat a uniform grid? (issue 29)

For each departure kind of ``--kinds`` (default scatter, coupling, all): the paper's
matrix simulated with that departure (``--bench-seed``, default 3), fitted with the
defaults (with ``--goal laws``: ``coupling="auto"``, the coupling laws compared), saved;
``idtool plan`` of it for ``--goal`` (``band --at 670,0.7``, or
``laws``) with ``--pulls`` pulls; then ``idtool study`` of the fit with the plan, and
again with ``--uniform`` (the plan's uniform grid of as many pulls), on benches with the
same departure (``--truths`` truths, study seed ``--seed``, ``--workers`` local Dask
workers). Prints, per kind and design (planned, uniform):

* goal ``band``: the expected half-width after the pulls [FR] and the achieved median
  (mean) over the truths, and FR coverage;
* goal ``laws``: in how many truths the true law's weight rose from the fit of the
  existing pulls alone to the fit with the new pulls (target: >= 80% for the plan), the
  true law's mean weight before and after, how often it is chosen before and after.

Run: ``.venv/bin/python benchmarks/study_plan.py --goal laws --truths 20`` (about 30
minutes on 2 cores for three kinds: each laws task fits twice, every coupling law).
Folders go to ``--out`` (default a temporary one); a study finished there before is read,
not run again.
A kind whose fit kept one coupling law has nothing for ``--goal laws`` to tell apart:
it says so and is skipped.
"""

from __future__ import annotations

import argparse
import json
import tempfile
import warnings
from pathlib import Path


def bench_fit(kind: str, bench_seed: int, folder: Path, coupling: str):
    import idtool
    from idtool._simulate._departures import departure_params

    params = departure_params(kind, bench_seed, "paper")
    dataset, _ = idtool.simulate_bench(params, seed=bench_seed)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        fit = idtool.fit(dataset, seed=0, coupling=coupling)
    fit.save(folder, force=True)
    return fit


def row(kind: str, design: str, summary: dict, goal: str) -> str:
    if goal == "laws":
        law = summary["laws"]
        n = law.get("n_before", 0)
        if not n:
            return f"{kind:9s} {design:8s} no truth's law among the kept laws"
        return (
            f"{kind:9s} {design:8s} rose {law['rose']:3d}/{n:<3d} "
            f"weight {law['truth_weight_mean_before']:.3f} -> {law['truth_weight_mean']:.3f}  "
            f"chosen {law['wins_before']}/{n} -> {law['wins']}/{law['n']}"
        )
    t = summary["targets"][0]
    cov = summary["fr_coverage"]
    return (
        f"{kind:9s} {design:8s} expected {t['expected_half_width']:.4g} achieved "
        f"{t['half_width_median']:.4g} ({t['half_width_mean']:.4g})  "
        f"FR {cov['inside']}/{cov['n']}"
    )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--kinds", default="scatter,coupling,all")
    ap.add_argument("--goal", default="laws", choices=("band", "laws"))
    ap.add_argument("--pulls", type=int, default=10)
    ap.add_argument("--truths", type=int, default=20)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--bench-seed", type=int, default=3)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--out", default=None)
    ap.add_argument("--loads", default=None, help="the plan's --loads LOW:HIGH [N]")
    ap.add_argument("--amplitudes", default=None, help="the plan's --amplitudes LOW:HIGH")
    ap.add_argument(
        "--designs",
        default="planned,uniform",
        help="which to study: planned, uniform or both (default)",
    )
    args = ap.parse_args()

    from idtool._cli._main import main as cli

    out = Path(args.out or tempfile.mkdtemp(prefix="study-plan-"))
    out.mkdir(parents=True, exist_ok=True)
    lines = []
    for kind in args.kinds.split(","):
        fit_dir = out / f"fit-{kind}"
        # the laws goal needs a fit that compared the coupling laws (it plans to tell
        # apart those it kept)
        coupling = "auto" if args.goal == "laws" else "by-design"
        fit = bench_fit(kind, args.bench_seed, fit_dir, coupling)
        laws = {name: round(float(d["bic_weight"]), 3) for name, d in fit.coupling_laws.items()}
        print(f"{kind}: the fit kept {laws}", flush=True)
        if args.goal == "laws" and len(laws) < 2:
            lines.append(f"{kind:9s} the fit kept one coupling law: nothing to tell apart")
            continue
        plan_dir = out / f"plan-{kind}"
        goal = ["--goal", "laws"] if args.goal == "laws" else ["--goal", "band", "--at", "670,0.7"]
        argv = ["plan", str(fit_dir), *goal, "--pulls", str(args.pulls)]
        argv += ["--loads", args.loads] if args.loads else []
        argv += ["--amplitudes", args.amplitudes] if args.amplitudes else []
        code = cli([*argv, "--out", str(plan_dir), "--force"])
        if code:
            lines.append(f"{kind:9s} idtool plan failed ({code})")
            continue
        for design, extra in (("planned", []), ("uniform", ["--uniform"])):
            if design not in args.designs.split(","):
                continue
            study_dir = out / f"study-{kind}-{design}"
            if (study_dir / "summary.json").is_file():  # finished before: read, not rerun
                summary = json.loads((study_dir / "summary.json").read_text())
                lines.append(row(kind, design, summary, args.goal))
                print(lines[-1], flush=True)
                continue
            argv = ["study", str(fit_dir), "--plan", str(plan_dir), "--truths", str(args.truths)]
            argv += ["--departure", kind, "--seed", str(args.seed), "--workers", str(args.workers)]
            argv += ["--out", str(study_dir), "--force", *extra]
            code = cli(argv)
            if code:
                lines.append(f"{kind:9s} {design:8s} idtool study failed ({code})")
                continue
            summary = json.loads((study_dir / "summary.json").read_text())
            lines.append(row(kind, design, summary, args.goal))
            print(lines[-1], flush=True)
    within = f"; loads {args.loads or 'tested'}, amplitudes {args.amplitudes or 'tested'}"
    print(
        f"\ngoal {args.goal}, {args.pulls} pulls, {args.truths} truths (seed {args.seed}){within}:"
    )
    print("\n".join(lines))
    print(f"folders: {out}")


if __name__ == "__main__":
    main()
