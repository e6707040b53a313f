"""Benchmark: joint fit of the example dataset, idtool (JAX) against plain SciPy/NumPy.

The model (Dahl law, power-limited coupling) and the fitting problem are those of
:class:`idtool.BenchModel`, re-implemented here without JAX:

* contact: the friction ratio FR at each operating point from the Dahl bristle ODE
  ``df/dtheta = Lambda (VR + cos theta)(1 - sgn(VR + cos theta) f)`` solved by
  ``solve_ivp(method="LSODA", rtol=1e-8)`` (see :func:`dahl_friction_ratio`), with
  ``VR = v / (a w)``, ``Lambda = Kt a / (mu N)``, ``w = 2 pi f`` and the power-limited
  coupling ``a = gain alpha A_max / sqrt(1 + (alpha N / P)^2)``. FR is solved once per
  distinct operating point (6 for the 24 traces) and reused while the four physical
  parameters are unchanged, so the finite-difference columns of the (98) bench
  nuisances cost no ODE solve: generous to SciPy (idtool recomputes all 24 every evaluation);
* bench: the piecewise trace of :func:`idtool._model._bench.mean_force_n` (load-cell offset,
  start-up ramp, actuator-limited slope down while ON and back up after, corners rounded
  over 0.5 N) evaluated sample by sample in a plain Python loop (20 264 model points per
  evaluation), checked against ``mean_force_n`` to 1e-9 N. A vectorised NumPy version is
  timed as well, and the report says what the SciPy fit would cost with it;
* the same block-averaged data (``prepare_fit_data``, ``periods_per_block=2``), the same
  data-driven start values, parameters and transforms (the ``BenchModel.params`` numbers,
  evaluated in NumPy), the same exact AR(1) whitening;
* the same procedure as :func:`idtool._fit._fit.fit_model`: 8 quasi-random starts (seed 0,
  the same points), from each a joint fit of all parameters for 20 steps, the lowest
  end point taken to convergence, then phi re-estimated and the polish repeated until
  phi moves by less than 0.02 (at most 3 rounds). The optimiser is
  ``least_squares(method="trf", jac="2-point")`` with SciPy's default tolerances and
  relative steps of 1e-5 on the physical parameters (the ODE's rtol 1e-8 would swamp
  the default 1.5e-8 step; checked against JAX's Jacobian to ~1e-3).

Timed, each in a fresh interpreter (wall time of the subprocess: interpreter start-up,
imports and JIT compilation all count):

1. end to end: idtool ``import idtool`` + load + ``prepare_fit_data`` + ``fit_model``, against
   the SciPy replica of ``fit_model`` (and idtool once more with XLA's persistent
   compilation cache filled by an earlier run, as ``idtool fit`` keeps it). The SciPy
   process reads the prepared arrays and the quasi-random start points from an .npz
   written by this script, so loading the parquet traces and preparing the blocks
   (idtool's own NumPy code) is not charged to SciPy.
2. the matched polish alone: all (102) parameters from idtool's multi-start optimum (the
   nuisances at their start values, where ``fit_model`` starts its polish) with phi
   fixed at idtool's final value; idtool runs its own compiled Levenberg-Marquardt
   (``idtool._fit._program.run_lm``), SciPy ``least_squares`` as above.

In-process it also measures idtool's warm ``fit_model`` (a second call on the same
data: its compiled programs are reused), the cost of one jitted residual evaluation, of
one coloured Jacobian (what each LM step uses) and of one dense forward-mode Jacobian,
and the compiled polish alone.

Exits non-zero if any of Kt, mu, coupling_gain, power_load_n differs between SciPy and
idtool by more than 0.2 idtool standard errors (statistically irrelevant: the two differ
only in the contact solver's accuracy, ~1e-5 in FR, and the optimisers' stopping rules),
if the two phi differ by more than 0.01, or if the bench loop or the contact solver
disagree with idtool's (1e-9 N; 3e-5 in FR: idtool's 256-step cycle average is itself
~1.5e-5 off at these Lambda, LSODA ~1e-9).

Run: ``.venv/bin/python benchmarks/bench_fit.py [--repeat N]`` (about 5 minutes on a
quiet 2-CPU machine, 4.5 more per extra repeat: the SciPy replica takes 4 of them).
Other load on the machine slows JAX's multi-threaded runtime far more than SciPy's
single thread; every timing row shows how
many CPUs other processes kept busy meanwhile, and ``--repeat`` keeps the fastest of N
fresh interpreters.
"""

from __future__ import annotations

import argparse
import atexit
import json
import math
import os
import resource
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np
from scipy.integrate import solve_ivp
from scipy.optimize import least_squares

PHYSICAL = ("Kt", "mu", "coupling_gain", "power_load_n")
PERIODS_PER_BLOCK = 2
CORNER_N = 0.5  # idtool._model._benchmodel.CORNER_N
# fit_model's procedure (idtool/_fit.py at the time of writing)
N_STARTS, SEED = 8, 0
MULTISTART_MAX_NFEV = 20  # fit_model: _MULTISTART_STEPS (joint runs from each start)
PHI_ROUNDS, PHI_SETTLE = 3, 0.02
# Relative finite-difference steps on the internal scale: the contact ODE is solved to
# rtol 1e-8, so the physical columns need a step well above that; the bench model is
# exact arithmetic and takes SciPy's default step.
DIFF_STEP_PHYSICAL = 1e-5
DIFF_STEP_BENCH = 1.5e-8
SE_TOLERANCE = 0.2  # agreement required, in idtool standard errors
PHI_TOLERANCE = 0.01
BENCH_TOLERANCE_N = 1e-9
FR_TOLERANCE = 3e-5

# --------------------------------------------------------------------------- idtool side
# Each runs as ``python -c CODE OUT.json [IN.json]`` in a fresh interpreter.
CACHE_ON = """
import jax
jax.config.update("jax_compilation_cache_dir", "{cache}")
jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.05)
"""
IDTOOL_FULL = """
import json, sys
import idtool
from idtool._data._blocks import prepare_fit_data
from idtool._fit._fit import fit_model

data = prepare_fit_data(
    idtool.load_dataset(idtool.example_dataset_path()), periods_per_block={ppb}
)
r = fit_model(data)
k = len(r.model.physical_names)
z_start = r.model.z0()
z_start[:k] = r.optima[0]["z"]
json.dump({{
    "estimates": {{n: [e.estimate, e.std_error] for n, e in r.estimates.items()}},
    "phi": r.phi, "z": r.z.tolist(), "z_start": z_start.tolist(), "rss": r.rss,
    "lm_steps": r.lm_steps, "names": list(r.model.names), "warnings": r.warnings,
    "jacobians": r.jacobian_evaluations,
}}, open(sys.argv[1], "w"))
"""

IDTOOL_POLISH = """
import json, sys
import jax.numpy as jnp
import idtool
from idtool._data._blocks import prepare_fit_data
from idtool._fit._program import run_lm
from idtool._model._benchmodel import bench_model

job = json.load(open(sys.argv[2]))
data = prepare_fit_data(
    idtool.load_dataset(idtool.example_dataset_path()), periods_per_block={ppb}
)
model = bench_model(data, "dahl", "power-limited")
z0 = jnp.asarray(job["z_start"])
out = run_lm(model, z0, jnp.ones(z0.size, bool), job["phi"], 100)
json.dump({{"z": [float(x) for x in out.z], "lm_steps": int(out.steps),
           "converged": bool(out.converged), "cost": float(out.loss)}}, open(sys.argv[1], "w"))
"""


class Timing(NamedTuple):
    """Wall time [s], and how many CPUs other processes kept busy meanwhile (on average)."""

    wall: float
    other_cpus: float


def busy_cpu_s() -> float:
    """CPU seconds used by everything on the machine so far (Linux), nan elsewhere."""
    try:
        fields = Path("/proc/stat").read_text().split("\n", 1)[0].split()[1:9]
    except OSError:
        return math.nan
    user, nice, system, _idle, _iowait, irq, softirq, steal = (int(x) for x in fields)
    return (user + nice + system + irq + softirq + steal) / os.sysconf("SC_CLK_TCK")


def own_cpu_s(who: int) -> float:
    r = resource.getrusage(who)
    return r.ru_utime + r.ru_stime


def timed(fn, who: int = resource.RUSAGE_SELF) -> tuple[Timing, Any]:
    """Run ``fn``; its wall time and the other processes' load meanwhile."""
    busy0, own0, t0 = busy_cpu_s(), own_cpu_s(who), time.perf_counter()
    out = fn()
    wall = time.perf_counter() - t0
    other = (busy_cpu_s() - busy0 - (own_cpu_s(who) - own0)) / wall
    return Timing(wall, max(other, 0.0)), out


def run_subprocess(args: list[str], out: Path, repeat: int = 1) -> tuple[Timing, dict]:
    """Fastest of ``repeat`` fresh interpreters running ``args`` (which write ``out``):
    its timing and the JSON it wrote. Raises if a run fails."""
    best: tuple[Timing, dict] | None = None
    for _ in range(repeat):

        def once():
            proc = subprocess.run([sys.executable, *args], capture_output=True, text=True)
            if proc.returncode != 0:
                raise SystemExit(f"subprocess failed:\n{proc.stderr[-4000:]}")

        timing, _ = timed(once, resource.RUSAGE_CHILDREN)
        if best is None or timing.wall < best[0].wall:
            best = (timing, json.loads(out.read_text()))
    assert best is not None
    return best


# --------------------------------------------------------------------------- SciPy side
def dahl_friction_ratio(vr: float, lam: float) -> float:
    """Cycle-averaged steady Dahl FR at velocity ratio VR and stiffness Lambda, by LSODA.

    Lambda >= 1 (the optimum has Lambda ~ 10): from f = 0 over ``1 + ceil(7 / Lambda)``
    cycles (at most 8), averaging the last one, as bench_curve.py does; the transient
    shrinks by at least e^(-4 Lambda) per cycle, so it is below 1e-12 by then.
    Lambda < 1 (met only far from the optimum, in the multi-start) would need up to
    thousands of cycles, so one cycle is integrated from f = 0 together with the
    homogeneous response ``h = 1 - g`` (``g`` the decay of a unit initial state), and the
    periodic state ``f* = f(2 pi) / h(2 pi)`` follows by superposition (the ODE is linear
    in f for a given slip). Both give the same steady state to ~1e-9.
    """
    if lam >= 1.0:
        cycles = 1 + math.ceil(7.0 / lam)

        def rhs(theta, y):
            du = vr + math.cos(theta)
            return [lam * du * (1.0 - math.copysign(1.0, du) * y[0]), y[0]]

        t1, t2 = 2 * math.pi * (cycles - 1), 2 * math.pi * cycles
        # max_step: once f saturates at +-1 the right-hand side is exactly zero, and
        # LSODA's error estimate then lets it step clean over the next reversal
        # (it returned FR ~ 1 at VR 0.2, Lambda 12-14 without it).
        sol = solve_ivp(
            rhs,
            (0.0, t2),
            [0.0, 0.0],
            method="LSODA",
            rtol=1e-8,
            atol=1e-10,
            t_eval=[t1, t2],
            max_step=2 * math.pi / 64,
        )
        return float((sol.y[1, 1] - sol.y[1, 0]) / (2 * math.pi))

    def rhs_periodic(theta, y):
        du = vr + math.cos(theta)
        return [lam * (du - abs(du) * y[0]), lam * abs(du) * (1.0 - y[1]), y[0], y[1]]

    sol = solve_ivp(
        rhs_periodic, (0.0, 2 * math.pi), [0.0] * 4, method="LSODA", rtol=1e-8, atol=1e-12
    )
    f_end, h_end, int_f, int_h = sol.y[:, -1]
    return float((int_f + f_end / h_end * (2 * math.pi - int_h)) / (2 * math.pi))


class ScipyProblem:
    """The FitModel residuals (Dahl, power-limited coupling) in NumPy/SciPy."""

    def __init__(self, arrays: dict[str, np.ndarray]):
        a = arrays
        self.shared = [str(x) for x in a["shared_names"]]
        self.groups = [str(x) for x in a["trace_groups"]]
        self.lo, self.hi = a["lo"], a["hi"]
        self.centre, self.scale = a["centre"], a["scale"]
        self.bounded = a["hi"] > 0.0
        self.n_traces = a["normal_load_n"].size
        self.load = a["normal_load_n"]
        self.on_start, self.on_end = a["on_start_s"], a["on_end_s"]
        self.freq_hz = float(a["vibration_frequency_hz"])
        self.max_amp_m = float(a["max_amplitude_m"])
        self.force = a["force_n"]
        self.sub_time = a["sub_time_s"]
        self.block_trace = a["block_trace"].astype(int)
        self.first_block = a["first_block"].astype(int)
        ops = np.stack([a["normal_load_n"], a["amplitude_fraction"], a["pull_speed_m_s"]], 1)
        self.ops, op_index = np.unique(ops, axis=0, return_inverse=True)
        self.op_index = op_index.ravel()
        # Plain Python lists for the sample loop: per trace, its blocks' sub-sample times.
        self.trace_times = [
            self.sub_time[self.block_trace == i].tolist() for i in range(self.n_traces)
        ]
        self.trace_force = [
            self.force[self.block_trace == i].tolist() for i in range(self.n_traces)
        ]
        self._fr_key: tuple[float, ...] | None = None
        self._fr = np.empty(0)
        self.n_residuals = 0
        self.n_ode_solves = 0
        self.residual_s = 0.0  # time in residuals(), of which ode_s in solve_ivp
        self.ode_s = 0.0

    # -- parameters
    def values(self, z: np.ndarray) -> dict:
        lo = np.log(np.where(self.bounded, self.lo, 1.0))
        hi = np.log(np.where(self.bounded, self.hi, 1.0))
        sig = 1.0 / (1.0 + np.exp(-z))
        x = np.where(self.bounded, np.exp(lo + (hi - lo) * sig), self.centre + self.scale * z)
        n, k = self.n_traces, len(self.shared)
        out: dict = {name: float(x[i]) for i, name in enumerate(self.shared)}
        for j, group in enumerate(self.groups):
            out[group] = x[k + j * n : k + (j + 1) * n]
        # the horn's lag behind the logged ON flag: one per trace, or one per switching
        out.setdefault("delay_on_s", out.get("delay_s"))
        out.setdefault("delay_off_s", out.get("delay_s"))
        return out

    # -- contact
    def friction_ratios(self, v: dict) -> np.ndarray:
        """FR per trace, solved per distinct operating point; kept while (Kt, mu, g, P) stay."""
        key = tuple(v[p] for p in PHYSICAL)
        if key != self._fr_key:
            t0 = time.perf_counter()
            kt, mu, gain, p_load = key
            w = 2.0 * math.pi * self.freq_hz
            fr = np.empty(len(self.ops))
            for j, (load, alpha, speed) in enumerate(self.ops):
                amp = gain * alpha * self.max_amp_m / math.sqrt(1.0 + (alpha * load / p_load) ** 2)
                fr[j] = dahl_friction_ratio(speed / (amp * w), kt * amp / (mu * load))
                self.n_ode_solves += 1
            self._fr_key, self._fr = key, fr
            self.ode_s += time.perf_counter() - t0
        return self._fr[self.op_index]

    # -- bench, one sample at a time, whitened on the fly
    def whitened_loop(self, z: np.ndarray, phi: float, fr: np.ndarray | None = None):
        v = self.values(z)
        if fr is None:
            fr = self.friction_ratios(v)
        off = v["mu"] * self.load
        on = fr * off
        slope, up = v["slope_n_s"], v["startup_slope_n_s"]
        c2 = CORNER_N**2
        w_up2 = (CORNER_N / up) ** 2
        sqrt = math.sqrt
        head = sqrt(1.0 - phi**2)
        out = []
        for i in range(self.n_traces):
            f_off = float(off[i])
            depth = f_off - float(on[i])
            t_start = float(v["pull_start_s"][i])
            offset = float(v["offset_n"][i])
            on0 = self.on_start[i] + float(v["delay_on_s"][i])
            on1 = self.on_end[i] + float(v["delay_off_s"][i])
            has_on = math.isfinite(on0) and math.isfinite(on1)
            t_on = on0 if has_on else 0.0
            on_len = on1 - t_on if has_on else 0.0
            t_off = t_on + on_len
            x = slope * on_len
            drop_end = 0.5 * (x + depth - sqrt((x - depth) ** 2 + c2))
            prev = 0.0
            for b, (times, measured) in enumerate(
                zip(self.trace_times[i], self.trace_force[i], strict=True)
            ):
                total = 0.0
                for t in times:
                    # start-up ramp: smooth_min(up * smooth_max(t - t_start, 0), F_off)
                    x = t - t_start
                    x = up * 0.5 * (x + sqrt(x * x + w_up2))
                    rise = 0.5 * (x + f_off - sqrt((x - f_off) ** 2 + c2))
                    drop = 0.0
                    if has_on:
                        if t < t_off:  # falling towards F_on at the actuator's slope
                            x = slope * (t - t_on)
                            x = 0.5 * (x + sqrt(x * x + c2))
                            drop = 0.5 * (x + depth - sqrt((x - depth) ** 2 + c2))
                        else:  # rising back after OFF
                            x = drop_end - slope * (t - t_on - on_len)
                            drop = 0.5 * (x + sqrt(x * x + c2))
                    total += offset + rise - drop
                e = total / len(times) - measured
                out.append(head * e if b == 0 else e - phi * prev)
                prev = e
        return np.array(out)

    def residuals(self, z: np.ndarray, phi: float) -> np.ndarray:
        t0 = time.perf_counter()
        out = self.whitened_loop(z, phi)
        self.n_residuals += 1
        self.residual_s += time.perf_counter() - t0
        return out

    def ar1(self, e: np.ndarray) -> float:
        """Pooled lag-1 autocorrelation of residuals within traces (as idtool's)."""
        first = np.zeros(e.size, bool)
        first[self.first_block] = True
        num = np.sum((e[1:] * e[:-1])[~first[1:]])
        return float(np.clip(num / np.sum(e**2), -0.99, 0.99))

    # -- bench, vectorised (timed for comparison only)
    def predict_vectorised(self, z: np.ndarray, fr: np.ndarray) -> np.ndarray:
        v = self.values(z)
        bt = self.block_trace

        def smin(a, b, w):
            return 0.5 * (a + b - np.sqrt((a - b) ** 2 + w**2))

        def smax(a, b, w):
            return 0.5 * (a + b + np.sqrt((a - b) ** 2 + w**2))

        off = v["mu"] * self.load
        t = self.sub_time
        f_off = off[bt][:, None]
        depth = f_off - (fr * off)[bt][:, None]
        slope, up = v["slope_n_s"], v["startup_slope_n_s"]
        since = smax(t - v["pull_start_s"][bt][:, None], 0.0, CORNER_N / up)
        rise = smin(up * since, f_off, CORNER_N)
        on0 = (self.on_start + v["delay_on_s"])[bt][:, None]
        on1 = (self.on_end + v["delay_off_s"])[bt][:, None]
        has_on = np.isfinite(on0) & np.isfinite(on1)
        t_on = np.where(has_on, on0, 0.0)
        on_len = np.where(has_on, on1 - t_on, 0.0)
        drop_on = smin(smax(slope * (t - t_on), 0.0, CORNER_N), depth, CORNER_N)
        drop_end = smin(slope * on_len, depth, CORNER_N)
        drop_after = smax(drop_end - slope * (t - t_on - on_len), 0.0, CORNER_N)
        drop = np.where(has_on, np.where(t < t_on + on_len, drop_on, drop_after), 0.0)
        return (v["offset_n"][bt][:, None] + rise - drop).mean(axis=1)


def scipy_polish(problem: ScipyProblem, z_start: np.ndarray, phi: float, max_nfev=None):
    """Joint least squares over all parameters at fixed phi."""
    step = np.full(z_start.size, DIFF_STEP_BENCH)
    step[: len(PHYSICAL)] = DIFF_STEP_PHYSICAL
    return least_squares(
        problem.residuals,
        z_start,
        jac="2-point",
        method="trf",
        diff_step=step,
        args=(phi,),
        max_nfev=max_nfev,
    )


def scipy_fit_model(problem: ScipyProblem, base: np.ndarray, starts: np.ndarray) -> dict:
    """The procedure of idtool's fit_model, with SciPy's least_squares."""
    k = len(PHYSICAL)
    t0 = time.perf_counter()
    ends = []
    for zp in starts:
        z = base.copy()
        z[:k] = zp
        ends.append(scipy_polish(problem, z, 0.0, MULTISTART_MAX_NFEV))
    t1 = time.perf_counter()
    points = [(2.0 * e.cost, e.x[:k], e.status > 0) for e in ends]
    sol = min(ends, key=lambda e: e.cost)
    rss_best, rounds = 2.0 * sol.cost, 0
    if sol.status == 0:  # step budget used up: take it to convergence
        sol, rounds = scipy_polish(problem, sol.x, 0.0), 1
    z, phi = sol.x, 0.0
    for _ in range(PHI_ROUNDS):
        new_phi = problem.ar1(problem.residuals(z, 0.0))
        if abs(new_phi - phi) < PHI_SETTLE:
            break
        phi = new_phi
        sol = scipy_polish(problem, z, phi)
        z, rounds = sol.x, rounds + 1
    assert sol is not None
    return {
        "z": z.tolist(),
        "phi": phi,
        "cost": float(sol.cost),
        "multistart_rss": sorted(float(p[0]) for p in points),
        "multistart_converged": sum(bool(p[2]) for p in points),
        "best_start_rss": rss_best,
        "polish_rounds": rounds,
        "message": str(sol.message),
        "multistart_s": t1 - t0,
        "polish_s": time.perf_counter() - t1,
    }


def scipy_worker(mode: str, npz_path: str, out_path: str) -> None:
    """The SciPy end-to-end jobs (each run in its own interpreter by :func:`main`)."""
    t0 = time.perf_counter()
    with np.load(npz_path) as f:
        arrays = {k: f[k] for k in f.files}
    problem = ScipyProblem(arrays)
    t1 = time.perf_counter()
    if mode == "full":
        out = scipy_fit_model(problem, arrays["z0"], arrays["multistart_z"])
    else:
        sol = scipy_polish(problem, arrays["z_start"], float(arrays["phi"]))
        out = {"z": sol.x.tolist(), "cost": float(sol.cost), "message": str(sol.message)}
    out |= {
        "residual_evaluations": problem.n_residuals,
        "ode_solves": problem.n_ode_solves,
        "setup_s": t1 - t0,
        "fit_s": time.perf_counter() - t1,
        "residual_s": problem.residual_s,
        "ode_s": problem.ode_s,
    }
    z = np.array(out["z"])
    fr = problem.friction_ratios(problem.values(z))
    out["vectorised_s"] = median_time(lambda: problem.predict_vectorised(z, fr), 10)
    Path(out_path).write_text(json.dumps(out))


# --------------------------------------------------------------------------- driver
def median_time(fn, repeats: int) -> float:
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times)


def main(repeat: int = 1) -> None:
    total0 = time.perf_counter()
    load0 = os.getloadavg()[0]
    tmp = Path(tempfile.mkdtemp(prefix="bench_fit_"))
    atexit.register(shutil.rmtree, tmp, ignore_errors=True)
    ppb = PERIODS_PER_BLOCK

    # 1a. idtool fit_model end to end, fresh interpreter
    print("idtool fit_model, end to end in a fresh interpreter ...", flush=True)
    full_json = tmp / "idtool_full.json"
    wall_full, full = run_subprocess(
        ["-c", IDTOOL_FULL.format(ppb=ppb), str(full_json)], full_json, repeat
    )
    phi = float(full["phi"])
    z_start = np.array(full["z_start"])
    # the same with XLA's persistent compilation cache (what `idtool fit` keeps in
    # ~/.cache/idtool/jax): filled by one run, then timed
    print("idtool fit_model, end to end with a warm compilation cache ...", flush=True)
    cached = ["-c", CACHE_ON.format(cache=tmp / "xla_cache") + IDTOOL_FULL.format(ppb=ppb)]
    run_subprocess([*cached, str(full_json)], full_json, 1)
    wall_cached, _ = run_subprocess([*cached, str(full_json)], full_json, repeat)

    # in-process: warm fit_model, residual and Jacobian costs, problem arrays, cross-checks
    print("idtool in-process: warm fit_model, costs, cross-checks ...", flush=True)
    import jax
    import jax.numpy as jnp

    import idtool
    from idtool._data._blocks import prepare_fit_data
    from idtool._fit._fit import fit_model, quasi_random
    from idtool._fit._lm import levenberg_marquardt_loop
    from idtool._fit._program import _COMPILE, bench_normal_equations, level_structure, run_lm
    from idtool._model._benchmodel import bench_model

    t0 = time.perf_counter()
    dataset = idtool.load_dataset(idtool.example_dataset_path())
    data = prepare_fit_data(dataset, periods_per_block=ppb)
    prepare_s = time.perf_counter() - t0
    # XLA backend compilations during the warm call (they do not nest, so they add up)
    compiles: list[float] = []

    def on_duration(event: str, duration_secs: float, **_: str | int) -> None:
        if event == "/jax/core/compile/backend_compile_duration":
            compiles.append(duration_secs)

    jax.monitoring.register_event_duration_secs_listener(on_duration)
    cold, _ = timed(lambda: fit_model(data))
    compiles.clear()
    warm_t, warm = timed(lambda: fit_model(data))
    warm_s = warm_t.wall
    warm_compile_s, warm_compiles = sum(compiles), len(compiles)
    model = bench_model(data, "dahl", "power-limited")
    residuals = jax.jit(lambda z, phi: model.residuals(z, phi))
    jacobian = jax.jit(jax.jacfwd(lambda z, phi: model.residuals(z, phi)))
    structure = level_structure(model)
    equations = jax.tree_util.Partial(bench_normal_equations, model, structure)
    coloured = jax.jit(lambda z, phi: equations(z, phi))
    zj = jnp.asarray(z_start)
    residuals(zj, phi).block_until_ready()
    jacobian(zj, phi).block_until_ready()
    jax.block_until_ready(coloured(zj, phi)[1])

    def lm(z, mask, phi, max_steps):
        return run_lm(model, z, mask, phi, max_steps)

    mask = jnp.ones(z_start.size, bool)

    # the same iterations in a plain lax.while_loop: what optimistix's driver costs
    own_loop = jax.jit(
        lambda z, mask, phi, n: levenberg_marquardt_loop(equations, z, phi, mask, n),
        compiler_options=_COMPILE,
    )

    def micro():
        resid = median_time(lambda: residuals(zj, phi).block_until_ready(), 200)
        jac = median_time(lambda: jacobian(zj, phi).block_until_ready(), 10)
        col = median_time(lambda: jax.block_until_ready(coloured(zj, phi)[1]), 20)
        lm(zj, mask, phi, 100).z.block_until_ready()
        run = median_time(lambda: lm(zj, mask, phi, 100).z.block_until_ready(), 5)
        steps = int(lm(zj, mask, phi, 100).steps)
        own_loop(zj, mask, phi, 100).z.block_until_ready()
        own = median_time(lambda: own_loop(zj, mask, phi, 100).z.block_until_ready(), 5)
        return resid, jac, col, run, steps, own

    micro_t, (resid_s, jac_s, col_s, polish_run_s, polish_steps, own_run_s) = timed(micro)

    # the problem as plain arrays, and fit_model's quasi-random start points
    specs = model.params
    k = len(PHYSICAL)
    assert tuple(full["names"]) == model.names
    starts = []
    for u in quasi_random(N_STARTS, k, SEED):
        box = {}
        for j, p in enumerate(specs[:k]):
            if p.start_box is not None and p.name != "coupling_gain":
                lo, hi = np.log(p.start_box)
                box[p.name] = float(np.exp(lo + u[j] * (hi - lo)))
        starts.append(model.z0(**box)[:k])
    # The layout the SciPy side reproduces: shared parameters, then per-trace groups.
    shared = [p.name for p in specs if "[" not in p.name]
    groups = list(dict.fromkeys(p.name.split("[")[0] for p in specs if "[" in p.name))
    layout = shared + [f"{g}[{tid}]" for g in groups for tid in data.trace_ids]
    known = {"offset_n", "pull_start_s", "delay_s", "delay_on_s", "delay_off_s"}
    if (
        list(model.names) != layout
        or shared != [*PHYSICAL, "slope_n_s", "startup_slope_n_s"]
        or not set(groups) <= known
    ):
        raise SystemExit(
            f"BenchModel's parameters changed; update the benchmark: {shared} {groups}"
        )
    arrays: dict[str, Any] = {
        "shared_names": np.array(shared),
        "trace_groups": np.array(groups),
        "lo": np.array([p.lo for p in specs]),
        "hi": np.array([p.hi for p in specs]),
        "centre": np.array([p.centre for p in specs]),
        "scale": np.array([p.scale for p in specs]),
        "normal_load_n": data.normal_load_n,
        "amplitude_fraction": data.amplitude_fraction,
        "pull_speed_m_s": data.pull_speed_m_s,
        "on_start_s": data.on_start_s,
        "on_end_s": data.on_end_s,
        "vibration_frequency_hz": np.array(data.vibration_frequency_hz),
        "max_amplitude_m": np.array(data.max_amplitude_m),
        "force_n": data.force_n,
        "sub_time_s": data.sub_time_s,
        "block_trace": data.block_trace,
        "first_block": data.first_block,
        "z0": model.z0(),
        "multistart_z": np.array(starts),
        "z_start": z_start,
        "phi": np.array(phi),
    }
    npz_path = tmp / "problem.npz"
    np.savez(npz_path, **arrays)

    # cross-checks at the polish start point: contact FR, bench model, whitened residuals
    problem = ScipyProblem(arrays)
    fr_idtool = np.asarray(model.levels(model.values(zj))[2])
    fr_scipy = problem.friction_ratios(problem.values(z_start))
    fr_diff = float(np.max(np.abs(fr_scipy - fr_idtool)))
    # bench alone: the loop fed idtool's FR against mean_force_n (phi = 0: raw residuals)
    loop_raw = problem.whitened_loop(z_start, 0.0, fr_idtool)
    bench_diff = float(np.max(np.abs(loop_raw - np.asarray(model.residuals(zj, 0.0)))))
    vec = problem.predict_vectorised(z_start, fr_idtool)
    vec_diff = float(np.max(np.abs(vec - np.asarray(model.predict(zj)))))
    resid_diff = float(
        np.max(np.abs(problem.whitened_loop(z_start, phi) - np.asarray(residuals(zj, phi))))
    )

    # 1b and 2: the SciPy replica of fit_model, then the matched polish on both sides
    print("SciPy fit_model replica, end to end in a fresh interpreter ...", flush=True)
    sp_json = tmp / "scipy_full.json"
    wall_sp, sp = run_subprocess(
        [__file__, "--scipy-worker", "full", str(npz_path), str(sp_json)], sp_json, repeat
    )
    job = tmp / "job.json"
    job.write_text(json.dumps({"z_start": z_start.tolist(), "phi": phi}))
    print("idtool polish (matched problem), fresh interpreter ...", flush=True)
    pol_json = tmp / "idtool_polish.json"
    wall_pol, pol = run_subprocess(
        ["-c", IDTOOL_POLISH.format(ppb=ppb), str(pol_json), str(job)], pol_json, repeat
    )
    print("SciPy polish (matched problem), fresh interpreter ...", flush=True)
    spp_json = tmp / "scipy_polish.json"
    wall_spp, spp = run_subprocess(
        [__file__, "--scipy-worker", "polish", str(npz_path), str(spp_json)], spp_json, repeat
    )

    # ---------------------------------------------------------------- report
    def physical(z) -> dict[str, float]:
        vals = problem.values(np.asarray(z))
        return {p: vals[p] for p in PHYSICAL}

    ref = full["estimates"]
    print()
    print(
        f"Example dataset: {data.n_traces} traces, {data.n_blocks} blocks of {data.block_size} "
        f"samples ({data.sub_time_s.size} model points), {z_start.size} parameters; "
        "Dahl law, power-limited coupling"
    )
    worst = 0.0

    def table(title, left, right, left_name, right_name, se_of):
        nonlocal worst
        print()
        print(title)
        print(f"{'':15}{left_name:>14}{right_name:>14}{'rel. diff':>11}{'diff/SE':>9}")
        for p in PHYSICAL:
            a, b = left[p], right[p]
            in_se = abs(a - b) / se_of[p]
            worst = max(worst, in_se)
            print(f"{p:15}{a:14.7g}{b:14.7g}{(a - b) / b:11.2e}{in_se:9.3f}")

    se = {p: ref[p][1] for p in PHYSICAL}
    table(
        "Estimates, end to end (SE: idtool's standard errors)",
        physical(sp["z"]),
        {p: ref[p][0] for p in PHYSICAL},
        "SciPy",
        "idtool",
        se,
    )
    print(
        f"{'phi (AR(1))':15}{sp['phi']:14.5f}{phi:14.5f}{(sp['phi'] - phi) / phi:11.2e}"
        f"{'':9}   idtool SE: " + ", ".join(f"{p} {se[p]:.3g}" for p in PHYSICAL)
    )
    table(
        "Estimates, matched polish (same start, phi fixed)",
        physical(spp["z"]),
        physical(pol["z"]),
        "SciPy",
        "idtool",
        se,
    )
    print(
        f"{'0.5 * RSS':15}{spp['cost']:14.7g}{pol['cost']:14.7g}"
        f"{(spp['cost'] - pol['cost']) / pol['cost']:11.2e}"
    )
    print()
    print("Cross-checks at the polish start point")
    print(f"  bench loop vs idtool mean_force_n   max |diff| = {bench_diff:.2e} N")
    print(f"  vectorised bench vs idtool predict  max |diff| = {vec_diff:.2e} N")
    print(f"  FR, LSODA vs idtool contact solver  max |diff| = {fr_diff:.2e}")
    print(f"  whitened residuals                  max |diff| = {resid_diff:.2e} N")
    print()
    best = f", fastest of {repeat}" if repeat > 1 else ""
    print(f"Wall times [s]. Fresh interpreter{best}: start-up, imports and compilation included;")
    print("'other CPUs': how many CPUs other processes kept busy meanwhile (0 = quiet machine)")
    print(f"{'':58}{'seconds':>9}{'SciPy/this':>12}{'other CPUs':>12}")
    n_sp, n_spp = sp["residual_evaluations"], spp["residual_evaluations"]
    sp_warm = Timing(sp["fit_s"], math.nan)
    rows = [
        (f"end to end: SciPy fit_model replica ({n_sp} evals)", wall_sp, wall_sp),
        (f"end to end: idtool fit_model ({full['lm_steps']} LM steps)", wall_full, wall_sp),
        ("end to end: the same, compilation cache warm", wall_cached, wall_sp),
        (f"matched polish: SciPy least_squares ({n_spp} evals)", wall_spp, wall_spp),
        (f"matched polish: idtool LM ({pol['lm_steps']} steps)", wall_pol, wall_spp),
        ("in-process: SciPy fit_model replica, fit only", sp_warm, sp_warm),
        (f"in-process: idtool fit_model, 2nd call ({warm.lm_steps} steps)", warm_t, sp_warm),
    ]
    for label, t, against in rows:
        print(f"{label:58}{t.wall:9.2f}{against.wall / t.wall:12.1f}{t.other_cpus:12.2f}")
    print()
    print("Inside the processes")
    print(
        f"  SciPy fit_model: setup {sp['setup_s']:.2f} s, multi-start {sp['multistart_s']:.1f} s "
        f"({sp['multistart_converged']}/{N_STARTS} converged, best RSS "
        f"{sp['best_start_rss']:.6g}), polish {sp['polish_s']:.1f} s "
        f"({sp['polish_rounds']} rounds)"
    )
    print(
        f"    {n_sp} residual evaluations (finite-difference columns included), "
        f"{sp['ode_solves']} solve_ivp calls; {sp['message']}"
    )
    print(
        f"  SciPy polish: {spp['fit_s']:.1f} s, {n_spp} residual evaluations, "
        f"{spp['ode_solves']} solve_ivp calls; {spp['message']}"
    )
    bench_s = sp["residual_s"] - sp["ode_s"]
    print(
        f"    of the fit: {sp['residual_s']:.1f} s in residual evaluations, {sp['ode_s']:.1f} s "
        f"of it in solve_ivp ({sp['ode_s'] / sp['ode_solves'] * 1e3:.1f} ms per FR solve), "
        f"{bench_s:.1f} s in the bench loop ({bench_s / n_sp * 1e3:.1f} ms per evaluation; "
        f"vectorised NumPy {sp['vectorised_s'] * 1e3:.2f} ms)"
    )
    plain_s = wall_sp.wall + (n_sp * len(problem.ops) - sp["ode_solves"]) * (
        sp["ode_s"] / sp["ode_solves"]
    )
    print(
        f"    without the FR memo (every evaluation, finite-difference columns included, "
        f"re-solving its {len(problem.ops)} operating points, as a plain implementation "
        f"does) the same iterates would take ~{plain_s:.0f} s "
        f"(extrapolated from the measured cost per solve; ratio to idtool "
        f"~{plain_s / wall_full.wall:.0f})"
    )
    saved = bench_s - n_sp * sp["vectorised_s"]
    print(
        f"    with the vectorised bench the SciPy fit_model replica would take "
        f"~{wall_sp.wall - saved:.0f} s end to end "
        f"(ratio to idtool ~{(wall_sp.wall - saved) / wall_full.wall:.1f})"
    )
    print(
        f"  idtool: load + prepare {prepare_s:.2f} s; fit_model in-process: first call "
        f"{cold.wall:.1f} s, second (warm) call {warm_s:.1f} s, {warm.lm_steps} LM steps"
    )
    print(
        f"    one jitted residual evaluation {resid_s * 1e3:.3f} ms; one linearisation "
        f"(residuals, J^T J and J^T r from {structure.seeds.shape[0]} JVPs) {col_s * 1e3:.1f} ms "
        f"(= {col_s / resid_s:.1f} residual evaluations; a dense jacfwd Jacobian "
        f"{jac_s * 1e3:.1f} ms = {jac_s / resid_s:.0f}); other CPUs {micro_t.other_cpus:.2f}"
    )
    print(
        f"    warm fit_model: {warm.lm_steps} LM steps, {warm.jacobian_evaluations} "
        "linearisations, "
        f"{warm_s / resid_s:.0f} residual evaluations' worth of time (SciPy end to end: "
        f"{n_sp} evaluations); {warm_compile_s:.1f} s in {warm_compiles} XLA compilations"
    )
    print(
        f"    compiled polish (warm): {polish_run_s:.2f} s, {polish_steps} steps = "
        f"{polish_run_s / resid_s:.0f} residual evaluations' worth"
    )
    print(
        f"    per step, optimistix's least_squares driving the coloured LM "
        f"{polish_run_s / polish_steps * 1e3:.1f} ms against the same update in a plain "
        f"while_loop {own_run_s / polish_steps * 1e3:.1f} ms "
        f"(ratio {polish_run_s / own_run_s:.2f}; the fit uses the former)"
    )
    if full["warnings"]:
        print("  idtool fit warnings: " + " | ".join(full["warnings"]))
    print(
        f"benchmark total {time.perf_counter() - total0:.0f} s on {os.cpu_count()} CPUs; "
        f"load average {load0:.2f} at the start, {os.getloadavg()[0]:.2f} at the end "
        "(other load slows JAX's multi-threaded runtime far more than SciPy)"
    )

    failures = []
    if worst > SE_TOLERANCE:
        failures.append(f"estimates differ by {worst:.2f} SE (allowed {SE_TOLERANCE})")
    if abs(sp["phi"] - phi) > PHI_TOLERANCE:
        failures.append(f"phi differs by {abs(sp['phi'] - phi):.3f}")
    if bench_diff > BENCH_TOLERANCE_N:
        failures.append(f"bench loop differs from mean_force_n by {bench_diff:.2e} N")
    if fr_diff > FR_TOLERANCE:
        failures.append(f"LSODA and idtool friction ratios differ by {fr_diff:.2e}")
    if failures:
        raise SystemExit("; ".join(failures))


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--scipy-worker", nargs=3, metavar=("MODE", "NPZ", "OUT"), help=argparse.SUPPRESS
    )
    parser.add_argument(
        "--repeat", type=int, default=1, help="run each timed interpreter N times, keep the fastest"
    )
    args = parser.parse_args()
    if args.scipy_worker:
        scipy_worker(*args.scipy_worker)
    else:
        main(args.repeat)
