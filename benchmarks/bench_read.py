"""Benchmark: checking a big CSV dataset, ``idtool validate`` against plain pyarrow + NumPy.

The dataset: 4 traces of 2.5 million rows each (a 50 kHz DAQ, 50 s pulls: 45 MB of CSV
per trace), written by idtool's own CSV writer (what ``idtool simulate-bench`` and
``idtool import --format csv`` write) into a temporary folder: a pull at 0.3 N per N
of load with an ON window, load-cell noise and 50 Hz hum, quantised to 0.01 N.

Same job on both sides, each in a fresh interpreter (wall time with its imports, and
peak resident memory, ``VmHWM``):

* pyarrow + NumPy: ``pyarrow.csv.read_csv`` of every file, time and force as float64
  and the flag as bool, then every value finite, time strictly increasing, the median
  step, and the SHA-256 of the bytes: the least the check needs;
* idtool: ``idtool validate DIR`` run in a fresh process: every check of
  the format, every file located problem, the summary table;
* with ``--before PATH``: the same command from another checkout (``git worktree add
  /tmp/before main``) to measure a change;
* with ``--located``: one bad cell at the end of each trace, so idtool reads every file
  cell by cell to name it (file, row, column): the error path.

Prints the medians of ``--repeat`` runs, the largest peak, and the ratios to pyarrow.

Run: ``.venv/bin/python benchmarks/bench_read.py [--rows 2500000] [--before PATH]``.
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

import numpy as np

RATE_HZ = 50_000.0
LOADS_N = (270.0, 450.0, 670.0, 450.0)

# Peak memory of this process: VmHWM, which starts afresh at exec (ru_maxrss does
# not on Linux: a child inherits the high-water mark of the parent that forked it).
PEAK = r"""
def peak_kb():
    try:
        with open("/proc/self/status") as status:
            return next(int(l.split()[1]) for l in status if l.startswith("VmHWM:"))
    except OSError:
        import resource
        return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
"""

IDTOOL = r"""
import contextlib, io, json, sys
from idtool._cli import console
sys.argv = ["idtool", "validate", sys.argv[1]]
with contextlib.redirect_stdout(io.StringIO()) as out, contextlib.redirect_stderr(out):
    try:
        status = console()
    except SystemExit as stop:
        status = stop.code
print(json.dumps({"status": status, "peak_kb": peak_kb(), "tail": out.getvalue()[-300:]}))
"""

PYARROW = r"""
import hashlib, json, sys
from pathlib import Path
import numpy as np, pyarrow as pa, pyarrow.csv as pc
digest = hashlib.sha256()
types = {"time_s": pa.float64(), "force_n": pa.float64(), "ultrasound_on": pa.bool_()}
for doc in json.loads(Path(sys.argv[1], "dataset.json").read_text())["traces"]:
    data = Path(sys.argv[1], doc["file"]).read_bytes()
    digest.update(len(data).to_bytes(8, "big") + data)
    table = pc.read_csv(pa.BufferReader(data), convert_options=pc.ConvertOptions(
        column_types=types, true_values=["1"], false_values=["0"]))
    time_s = table.column("time_s").combine_chunks().to_numpy()
    force_n = table.column("force_n").combine_chunks().to_numpy()
    step = np.diff(time_s)
    assert np.isfinite(time_s).all() and np.isfinite(force_n).all() and (step > 0).all()
    rate_hz = 1.0 / float(np.median(step))
print(json.dumps({"status": 0, "peak_kb": peak_kb(), "tail": f"{rate_hz:g} Hz"}))
"""


def write_dataset(root: Path, n_rows: int, bad_cell: bool = False) -> int:
    """The benchmark dataset in ``root``; its size in bytes."""
    from idtool._data._write import json_bytes, render_table

    rng = np.random.default_rng(2010)
    (root / "traces").mkdir(parents=True)
    entries, size = [], 0
    time_s = np.arange(n_rows) / RATE_HZ
    on = (time_s >= 0.4 * time_s[-1]) & (time_s < 0.45 * time_s[-1])
    for k, load_n in enumerate(LOADS_N):
        force_n = 0.3 * load_n * np.where(on, 0.6, 1.0) * np.minimum(1.0, time_s / 0.5) + 1.5
        force_n += 0.5 * rng.standard_normal(n_rows) + 0.3 * np.sin(2 * np.pi * 50.0 * time_s)
        file = f"traces/T{k}.csv"
        data = render_table(file, time_s, np.round(force_n / 0.01) * 0.01, on)
        if bad_cell:  # the last row's force: 'x'
            head, _, last = data.rstrip(b"\n").rpartition(b"\n")
            t, _, flag = last.split(b",")
            data = head + b"\n" + b",".join([t, b"x", flag]) + b"\n"
        (root / file).write_bytes(data)
        size += len(data)
        entries.append(
            {
                "id": f"T{k}",
                "file": file,
                "normal_load_n": load_n,
                "amplitude_fraction": 0.5,
                "pull_speed_m_s": 0.025,
            }
        )
    document = {
        "schema_version": "1",
        "name": "bench-read",
        "material": "synthetic",
        "rig": {"vibration_frequency_hz": 20000.0, "max_amplitude_m": 85e-6},
        "traces": entries,
    }
    (root / "dataset.json").write_bytes(json_bytes(document))
    return size


def run(code: str, folder: Path, pythonpath: str | None) -> dict:
    """One fresh interpreter running ``code`` on ``folder``: wall time, status, peak."""
    env = os.environ | {"MPLBACKEND": "Agg"}
    if pythonpath is not None:
        env["PYTHONPATH"] = pythonpath
    t0 = time.perf_counter()
    done = subprocess.run(  # cwd: not a checkout, whose idtool would come first
        [sys.executable, "-c", PEAK + code, str(folder)],
        env=env,
        cwd=folder.parent,
        check=True,
        capture_output=True,
    )
    result = json.loads(done.stdout.decode().strip().splitlines()[-1])
    result["wall_s"] = time.perf_counter() - t0
    return result


def measure(
    code: str, folder: Path, pythonpath: str | None, repeat: int, status: int = 0
) -> tuple[float, float]:
    """Median wall time [s] and largest peak memory [MB] of ``repeat`` runs, each of
    which must end with exit ``status`` (0: valid, 2: errors found)."""
    runs = [run(code, folder, pythonpath) for _ in range(repeat)]
    for r in runs:
        assert r["status"] == status, f"exit status {r['status']}, not {status}: {r['tail']}"
    return statistics.median(r["wall_s"] for r in runs), max(r["peak_kb"] for r in runs) / 1024


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rows", type=int, default=2_500_000, help="rows per trace")
    ap.add_argument("--repeat", type=int, default=3, help="runs per line (default 3)")
    ap.add_argument("--before", metavar="PATH", help="another checkout to time as well")
    ap.add_argument("--located", action="store_true", help="also time a bad cell per trace")
    args = ap.parse_args()
    here = str(Path(__file__).resolve().parents[1])
    with tempfile.TemporaryDirectory() as tmp:
        clean = Path(tmp, "clean")
        t0 = time.perf_counter()
        size = write_dataset(clean, args.rows)
        written_s = time.perf_counter() - t0
        lines = [("pyarrow.csv + NumPy checks", *measure(PYARROW, clean, None, args.repeat))]
        lines.append(("idtool validate", *measure(IDTOOL, clean, here, args.repeat)))
        if args.before:
            before = measure(IDTOOL, clean, args.before, args.repeat)
            lines.append(("idtool validate, --before", *before))
        if args.located:
            bad = Path(tmp, "bad")
            write_dataset(bad, args.rows, bad_cell=True)
            lines.append(("idtool validate, a bad cell", *measure(IDTOOL, bad, here, 1, status=2)))
            if args.before:
                located = measure(IDTOOL, bad, args.before, 1, status=2)
                lines.append(("idtool validate, bad cell, --before", *located))
    print(
        f"{len(LOADS_N)} CSV traces x {args.rows} rows ({size / 1e6:.0f} MB, written by idtool "
        f"in {written_s:.1f} s); fresh interpreters, cpus: {os.cpu_count()}"
    )
    print(f"{'':38}{'wall [s]':>10}{'ratio':>8}{'peak [MB]':>11}{'ratio':>8}")
    base_s, base_mb = lines[0][1], lines[0][2]
    for name, wall_s, peak_mb in lines:
        print(
            f"{name:38}{wall_s:10.2f}{wall_s / base_s:8.1f}{peak_mb:11.0f}{peak_mb / base_mb:8.1f}"
        )


if __name__ == "__main__":
    main()
