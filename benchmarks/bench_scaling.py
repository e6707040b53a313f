"""Benchmark: how the fit scales with the number of traces of one design (issue 28).

The bench: the departure preset ``scatter`` (pull-to-pull scatter, power-limited
coupling; :func:`idtool._simulate._departures.departure_params`, seed 0) on 3 loads x 2
amplitudes x 2 ON durations (1 s, 2 s), repeated ``n / 12`` times: 12, 24, 48, 96 and 384
traces of the same operating points (:func:`repeated_bench`).

For each trace count, in a fresh interpreter: the fit's one compiled Levenberg-Marquardt
program is compiled first (a linearisation at the start, what a warm compilation cache
gives ``idtool fit``), then ``fit_model`` (8 starts, polish, AR(1) rounds) and
``check_intervals`` (refits with each physical parameter held at its interval's ends,
profiles where too flat) are timed together; peak memory is the process's maximum
resident set. The same on the dense normal equations (the reference path,
``level_structure(dense=True)``: what the fit did before the arrowhead) up to
``--dense-max`` traces (default 48: it takes 4 minutes at 96). Printed side by side,
with the exponent of a power law fitted to time against traces (least squares in logs).

Run: ``.venv/bin/python benchmarks/bench_scaling.py [--counts 12 24 48 96 384]
[--dense-max 48]`` (15-20 minutes; the 384 traces alone 8 on a loaded 2-CPU machine).
``--e2e``: ``idtool fit`` end to end instead (command line, defaults: the laws and
actuators compared, the levels model, the figures), each count written as a dataset and
fitted twice, the second timed (the first fills the compilation caches for its shapes);
wall time of the process, its CPU time (user + system) and its peak memory.

Measured 2026-11-25, load average 6-10 on 2 CPUs (other jobs; the timings are noisy),
before the OFF switch of the slope actuator was rounded: fit + checks 0.9, 12.4, 19.8,
148, 481 s and 0.49-1.07 GB at 12, 24, 48, 96, 384 traces (time ~ traces^1.75); dense
1.5, 12.1 s at 12, 24 and 246 s at 48. Per LM step (min of 3, 20-step runs): 4.2, 7.5,
24.5, 72, 217 ms; dense 4.4, 7.7, 214, 397 ms. From 48 traces on the fit and its refits
stopped short of their tolerance (the loss was kinked in the OFF delays: 60-100 steps
until the damping gave up, and profiles walked where Wald ends rose by less than 1).

After (same day, load average 10-12): 3.1, 6.4, 11.9, 43.8, 206 s (fit alone 2.9, 5.6,
11.4, 38.3, 182 s) and 0.50-1.11 GB; every fit converged to LM's own tolerance in
181-204 steps whatever the traces; time ~ traces^1.24 (1.29 from 24 to 384), most of
it the per-step cost (LM step ~ traces^1.1) and the machine's load.

``idtool fit`` end to end (``--e2e``), 2026-11-25, second run of two:

- 03:30, load average 9-14 (three other jobs): before the levels model, the free
  levels, the sampler's levels likelihood and the predictions' conditioning went to
  per-trace blocks and traces.png to at most 24 panels (commit 63ad8a2): 96 traces 34 s
  (0.74 GB), 384 traces 346 s (2.5 GB); after, 8.7, 11.4, 12.6, 15.5, 81.5 s and 0.46,
  0.48, 0.53, 0.60, 0.90 GB at 12, 24, 48, 96, 384 traces. At load 4, 96 traces: 21-30 s
  before, 10.8-11.3 s after.
- 04:00, load average 2-4, on main's tree of then (fc91174: one OpenBLAS thread in the
  console process, issue 27) without and with these changes: 2.6, 3.7, 5.3, 8.4, 52.4 s
  and 0.47-2.38 GB (~traces^0.86) without; 2.6, 3.7, 6.4, 10.2, 22.5 s and 0.46, 0.49,
  0.54, 0.60, 0.91 GB (~traces^0.63) with. At 96 traces the two are within the runs'
  spread (profiled: levels model 0.83 -> 0.27 s, figures 3.9 -> 2.1 s, the three
  candidates' LM fits 7.6-8.4 s either way: most of the time); at 384 (not profiled)
  what differs is the levels model's (2 traces)^2 factorisations and the 384 panels.
- 2026-11-26, load average 6-9 (other jobs), the fit's covariance of ``z`` and the free
  levels' kept in blocks (issue 28: nothing (p, p) or (traces, traces)), two runs each
  of main's tree (75f40ab) and the blocks, interleaved: 96 traces 13.1, 9.5 s wall, 8.8,
  9.0 CPU s, 0.64, 0.65 GB before; 11.1, 14.2 s, 7.8, 8.9 CPU s, 0.65, 0.64 GB after.
  384 traces 56.6, 53.5 s wall, 33.2, 32.6 CPU s, 0.96, 0.94 GB before; 30.2, 32.8 s,
  29.2, 31.6 CPU s, 0.85, 0.83 GB after: 0.1 GB less at 384 traces, the CPU time within
  the runs' spread.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

BASE = 12  # traces of one repeat: 3 loads x 2 amplitudes x 2 ON durations
SEED = 0

CHILD = """
import functools, json, resource, sys, time
import numpy as np
sys.path.insert(0, {here!r})
from bench_scaling import repeated_bench
from idtool._data._blocks import prepare_fit_data
from idtool._fit import _program
from idtool._fit._fit import fit_model
from idtool._fit._intervals import check_intervals
from idtool._model._benchmodel import bench_model

n, dense = int(sys.argv[1]), sys.argv[2] == "dense"
if dense:
    _program.level_structure = functools.partial(_program.level_structure, dense=True)
data = prepare_fit_data(repeated_bench(n, {seed}))
model = bench_model(data)
z = model.z0()
_program.run_lm(model, z, np.ones(z.size, bool), 0.0, 0)  # compile the program
t = time.perf_counter()
fitted = fit_model(data)
fit_s = time.perf_counter() - t
result = check_intervals(fitted)
wall = time.perf_counter() - t
json.dump({{
    "traces": data.n_traces, "seconds": wall, "fit_seconds": fit_s,
    "converged": not any(w.code == "lm_not_converged" for w in fitted.warnings),
    "peak_gb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1e6,
    "steps": result.lm_steps,
    "estimates": {{k: result.estimates[k].estimate for k in model.physical_names}},
}}, sys.stdout)
"""

# ``idtool fit`` end to end (defaults) on the dataset in argv[1], in this child: its peak
# resident memory printed last; the parent times the whole process
CHILD_E2E = """
import json, resource, sys
from idtool._cli._main import console
sys.argv = ["idtool", "fit", sys.argv[1], "--out", sys.argv[2], "--force", "-q"]
code = console()
use = resource.getrusage(resource.RUSAGE_SELF)
print(json.dumps({"code": code, "peak_gb": use.ru_maxrss / 1e6,
    "user_s": use.ru_utime, "sys_s": use.ru_stime}))
"""


def repeated_bench(n_traces: int, seed: int = SEED):
    """The ``scatter`` departure bench (seed ``seed``) on the 12 operating points of
    module docstring, repeated to ``n_traces`` traces (a multiple of 12)."""
    from idtool._simulate._departures import departure_params
    from idtool._simulate._simulate import simulate_bench

    if n_traces % BASE:
        raise ValueError(f"{n_traces} traces: give a multiple of {BASE}")
    params = departure_params("scatter", seed)
    matrix = dataclasses.replace(
        params.experiments, on_durations_s=(1.0, 2.0), repeats=n_traces // BASE
    )
    dataset, _ = simulate_bench(dataclasses.replace(params, experiments=matrix), seed)
    return dataset


def run(n: int, path: str) -> dict | None:
    code = CHILD.format(here=str(Path(__file__).parent), seed=SEED)
    out = subprocess.run(
        [sys.executable, "-c", code, str(n), path], capture_output=True, text=True, check=False
    )
    if out.returncode:
        print(out.stderr[-2000:], file=sys.stderr)
        return None
    return json.loads(out.stdout.strip().splitlines()[-1])


def run_e2e(n: int, folder: Path) -> dict | None:
    """``idtool fit`` (command line, defaults) on :func:`repeated_bench` of ``n`` traces
    written to ``folder``: run twice (the first fills the compilation caches for these
    shapes), the second timed; wall time of the whole process and its peak memory."""
    from idtool._data._write import write_dataset

    data = folder / f"bench{n}"
    write_dataset(repeated_bench(n, SEED), data, force=True)
    out = None
    for _ in range(2):
        t = time.perf_counter()
        out = subprocess.run(
            [sys.executable, "-c", CHILD_E2E, str(data), str(folder / f"fit{n}")],
            capture_output=True,
            text=True,
            check=False,
        )
        wall = time.perf_counter() - t
        if out.returncode:
            print(out.stderr[-2000:], file=sys.stderr)
            return None
    assert out is not None
    row = json.loads(out.stdout.strip().splitlines()[-1])
    return {
        "traces": n,
        "seconds": wall,
        "peak_gb": row["peak_gb"],
        "cpu_s": row["user_s"] + row["sys_s"],
    }


def exponent(rows: list[dict]) -> float:
    """Slope of log(time) against log(traces), least squares."""
    x = np.log([r["traces"] for r in rows])
    y = np.log([r["seconds"] for r in rows])
    return float(np.polyfit(x, y, 1)[0])


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--counts", type=int, nargs="+", default=[12, 24, 48, 96, 384])
    ap.add_argument("--dense-max", type=int, default=48)
    ap.add_argument(
        "--e2e", action="store_true", help="time idtool fit end to end instead (module docstring)"
    )
    args = ap.parse_args()
    if args.e2e:
        return main_e2e(args.counts)
    rows: dict[str, list[dict]] = {"arrowhead": [], "dense": []}
    print(
        f"{'traces':>6}  {'arrowhead s':>11} {'fit s':>6} {'GB':>5} {'steps':>5} {'conv':>5}"
        f"  {'dense s':>8} {'GB':>5}"
    )
    for n in args.counts:
        a = run(n, "arrowhead")
        d = run(n, "dense") if n <= args.dense_max else None
        for key, r in (("arrowhead", a), ("dense", d)):
            if r is not None:
                rows[key].append(r)
        cells = [f"{n:>6}"]
        cells.append(
            f"{a['seconds']:>11.1f} {a['fit_seconds']:>6.1f} {a['peak_gb']:>5.2f} {a['steps']:>5}"
            f" {'yes' if a['converged'] else 'NO':>5}"
            if a
            else " " * 36
        )
        cells.append(f"{d['seconds']:>8.1f} {d['peak_gb']:>5.2f}" if d else f"{'-':>8}")
        if a and d:  # same optimum on both paths
            worst = max(
                abs(a["estimates"][k] - d["estimates"][k]) / abs(d["estimates"][k])
                for k in d["estimates"]
            )
            cells.append(f"  estimates agree to {worst:.1e}")
        print("  ".join(cells), flush=True)
    for key, r in rows.items():
        if len(r) >= 2:
            span = f"{r[0]['traces']}-{r[-1]['traces']}"
            print(f"{key}: time ~ traces^{exponent(r):.2f} ({span} traces)")
    ok = all(math.isfinite(r["seconds"]) for r in rows["arrowhead"])
    return 0 if ok and len(rows["arrowhead"]) == len(args.counts) else 1


def main_e2e(counts: list[int]) -> int:
    """``--e2e``: :func:`run_e2e` per trace count, and the exponent."""
    rows = []
    print(f"{'traces':>6}  {'idtool fit s':>12} {'CPU s':>6} {'GB':>5}")
    with tempfile.TemporaryDirectory() as tmp:
        for n in counts:
            r = run_e2e(n, Path(tmp))
            if r is None:
                return 1
            rows.append(r)
            cells = f"{r['seconds']:>12.1f} {r['cpu_s']:>6.1f} {r['peak_gb']:>5.2f}"
            print(f"{n:>6}  {cells}", flush=True)
    if len(rows) >= 2:
        print(f"idtool fit: time ~ traces^{exponent(rows):.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
