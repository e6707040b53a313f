"""Time to a first result: where ``idtool fit`` of the example spends its time.

Each run is a fresh interpreter doing what ``idtool fit DATASET --out DIR`` does, with
the persistent compilation cache of the command line, in phases:

* ``import``: ``import idtool``, the command line's parser and the numerical core
  (JAX, equinox, optimistix, the fit's modules), which the fitting commands import
  first and exempt from the garbage collector (``idtool._cli._args.load_numerics``);
* ``load``: reading and checking the dataset;
* ``fit``: ``idtool.fit`` (multi-start, polish, AR(1) rounds, interval checks), with
  the JAX tracing, lowering to StableHLO and XLA compilation (or cache loading) inside
  it reported separately from ``jax.monitoring``, summed over threads: the fit compiles
  the next candidate models' programs in a thread of its own while it computes
  (``idtool._fit._prefetch``), so these can add up to more than the phase's time;
* ``report``: the text report (made inside ``idtool.fit`` with the fit's artefact, so this
  phase reads it); ``save``: fit.json, fit_state.npz and the two figures.

First with an empty cache folder (cold: what a new user waits), then three times with
it warm (a repeated fit of a dataset of the same shape). Also ``import idtool`` alone
against ``import jax`` alone (the floor).

The cache folder holds JAX's compiled programs and, beside them, idtool's traced ones
(``idtool-programs/``, :mod:`idtool._fit._compiled`): a warm run neither traces nor
compiles the fit's large programs. Cold empties both.

    python benchmarks/bench_first_result.py [--repeat 3]

The run does what the console script does first (one OpenBLAS thread,
``idtool._cli._main.single_threaded_blas``) and imports matplotlib in a thread while
the fit runs (``idtool._plotting.import_in_background``), as ``idtool fit`` does.

Measured 2026-11-25 on 2 cores shared with three other sessions (load average 7-8:
wall times are 1.5-2x what an idle machine gives; CPU time is the steadier figure),
main at 63ad8a2 -> branch latency2:

    warm  wall 6.6 -> 7.3 s (load), CPU 4.47 -> 4.10 s
    cold  wall 27.2 -> 26.3 s (load), CPU 18.4 -> 14.2 s

and ``idtool fit`` itself (5 fresh processes each, alternating, load 5-7): warm wall
median 10.4 -> 7.9 s, user CPU median 5.6 -> 4.0 s; cold user CPU 19.4-20.7 -> 13.0 s.
At the load of the last session (1.3-1.8) warm was 3.7-4.3 s and cold 13.2 s wall.

There is no SciPy side to this one: it breaks down idtool's own time to a first result
(``bench_fit.py`` compares the fit with a SciPy implementation).
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

RUN = r"""
import time
t0 = time.perf_counter()
import collections, json, sys
from idtool._cli._main import single_threaded_blas
single_threaded_blas()  # as the console script, before NumPy loads
import jax
phases = collections.OrderedDict()
jax_events = collections.Counter()

KEYS = {"jaxpr_trace_duration": "trace", "jaxpr_to_mlir_module_duration": "lowering",
        "backend_compile_duration": "compile"}

def on_duration(event, secs, **_):
    key = KEYS.get(event.rsplit("/", 1)[-1])
    if key:
        jax_events[key] += secs

jax.monitoring.register_event_duration_secs_listener(on_duration)
from idtool._cli._cache import enable_compilation_cache
from idtool._cli._main import build_parser
from idtool._cli import _args
enable_compilation_cache()
build_parser()
import idtool
_args.freeze_on_load = True  # as the console script: the fit's modules, imports frozen
_args.load_numerics()
def mark(name):
    global t0
    now = time.perf_counter(); phases[name] = now - t0; t0 = now
mark("import")
ds = idtool.load_dataset(idtool.example_dataset_path())
mark("load")
jax_events.clear()
from idtool._plotting import import_in_background
drawing = import_in_background()  # as idtool fit: matplotlib while the fit runs
fit = idtool.fit(ds, seed=0)
mark("fit")
fit_jax = dict(jax_events)
text = fit.report()
mark("report")
drawing.join()
fit.save(sys.argv[1], force=True, command=["fit"])
mark("save")
json.dump({"phases": phases, "jax_in_fit": fit_jax,
           "Kt": fit.estimates["Kt"].estimate}, open(sys.argv[2], "w"))
"""


def run_once(cache: str, out: Path) -> dict:
    result = out.with_suffix(".json")
    env = os.environ | {"IDTOOL_CACHE_DIR": cache, "MPLBACKEND": "Agg"}
    # An installed idtool has its byte code compiled: without it ~100 modules were
    # compiled from source in every run (0.2-0.35 s)
    env.pop("PYTHONDONTWRITEBYTECODE", None)
    t0, c0 = time.perf_counter(), os.times()
    subprocess.run([sys.executable, "-c", RUN, str(out), str(result)], env=env, check=True)
    c1 = os.times()
    doc = json.loads(result.read_text())
    doc["wall"] = time.perf_counter() - t0
    doc["cpu"] = (c1.children_user - c0.children_user) + (c1.children_system - c0.children_system)
    return doc


def import_time(module: str, repeat: int) -> float:
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        subprocess.run([sys.executable, "-c", f"import {module}"], check=True)
        times.append(time.perf_counter() - t0)
    return min(times)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=3, help="warm runs (default 3)")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp)
        cache = str(root / "cache")
        cold = run_once(cache, root / "fit0")
        warm = [run_once(cache, root / f"fit{i + 1}") for i in range(args.repeat)]
    names = list(cold["phases"])
    print(f"idtool fit of the example dataset, fresh interpreters (cpus: {os.cpu_count()})")
    print(f"{'phase':28s}{'cold [s]':>10s}{'warm median [s]':>18s}")
    for name in names:
        w = statistics.median(r["phases"][name] for r in warm)
        print(f"{name:28s}{cold['phases'][name]:10.2f}{w:18.2f}")
        if name == "fit":
            for key, label in (
                ("trace", "tracing"),
                ("lowering", "lowering"),
                ("compile", "XLA compile/load"),
            ):
                c = cold["jax_in_fit"].get(key, 0.0)
                w = statistics.median(r["jax_in_fit"].get(key, 0.0) for r in warm)
                print(f"  of which JAX {label:15s}{c:10.2f}{w:18.2f}")
    total_c = sum(cold["phases"].values())
    total_w = statistics.median(sum(r["phases"].values()) for r in warm)
    wall_w = statistics.median(r["wall"] for r in warm)
    cpu_w = statistics.median(r["cpu"] for r in warm)
    print(f"{'total in process':28s}{total_c:10.2f}{total_w:18.2f}")
    print(f"{'wall, with interpreter':28s}{cold['wall']:10.2f}{wall_w:18.2f}")
    # CPU seconds of the process and its threads: what contention for the cores does not
    # inflate (wall time on a shared machine can be twice the idle figure)
    print(f"{'CPU, user + system':28s}{cold['cpu']:10.2f}{cpu_w:18.2f}")
    print(f"load average at the end: {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores")
    kts = {round(r["Kt"], 3) for r in [cold, *warm]}
    print(f"Kt identical across runs: {len(kts) == 1}")
    n = max(3, args.repeat)
    print(
        f"import idtool {import_time('idtool', n):.2f} s; import jax {import_time('jax', n):.2f} s"
    )


if __name__ == "__main__":
    main()
