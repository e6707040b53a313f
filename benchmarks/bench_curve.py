"""Benchmark: Dahl friction-ratio curve, idtool (JAX) against SciPy solve_ivp (LSODA).

Same job on both sides: the prescribed-vibration Dahl contact at Lambda = 3, 41 velocity
ratios in [0.05, 0.95], cycle-averaged friction ratio in steady state.

* SciPy: ``solve_ivp(method="LSODA", rtol=1e-8, atol=1e-10)`` on the bristle ODE
  ``df/dtheta = Lambda (VR + cos theta)(1 - sgn(VR + cos theta) f)`` with the running
  integral of f as a second state, from f = 0 over 4 cycles (the transient decays by
  e^-12 per cycle at Lambda = 3), averaging the last cycle; one point after another.
* idtool: :func:`idtool.cycle_average_curve` (the contact solver vmapped over the
  41 points, compiled once), as ``idtool curve`` runs it.

Prints both times, their ratio with and without JAX compilation, and the largest
difference between the two curves (must be below 1e-3).

Run: ``make bench`` or ``.venv/bin/python benchmarks/bench_curve.py``.
"""

from __future__ import annotations

import statistics
import time

import numpy as np
from scipy.integrate import solve_ivp

LAMBDA = 3.0
VR = np.linspace(0.05, 0.95, 41)
CYCLES = 4


def scipy_curve(vr_values: np.ndarray, lam: float) -> np.ndarray:
    out = np.empty_like(vr_values)
    for i, vr in enumerate(vr_values):

        def rhs(theta, y, vr=vr):
            du = vr + np.cos(theta)
            return [lam * du * (1.0 - np.sign(du) * y[0]), y[0]]

        t1, t2 = 2 * np.pi * (CYCLES - 1), 2 * np.pi * CYCLES
        sol = solve_ivp(
            rhs, (0.0, t2), [0.0, 0.0], method="LSODA", rtol=1e-8, atol=1e-10, t_eval=[t1, t2]
        )
        out[i] = (sol.y[1, 1] - sol.y[1, 0]) / (2 * np.pi)
    return out


def main() -> None:
    t0 = time.perf_counter()
    import jax.numpy as jnp

    import idtool

    import_s = time.perf_counter() - t0
    law = idtool.Dahl(fc_n=1.0, kt_n_m=LAMBDA)

    def jax_curve(vr):
        return idtool.cycle_average_curve(law, vr).friction_ratio

    vr = jnp.asarray(VR)
    t0 = time.perf_counter()
    fr_jax = np.asarray(jax_curve(vr).block_until_ready())
    cold_s = time.perf_counter() - t0
    warm = []
    for _ in range(20):
        t0 = time.perf_counter()
        jax_curve(vr).block_until_ready()
        warm.append(time.perf_counter() - t0)
    warm_s = statistics.median(warm)

    t0 = time.perf_counter()
    fr_scipy = scipy_curve(VR, LAMBDA)
    scipy_s = time.perf_counter() - t0

    diff = float(np.max(np.abs(fr_jax - fr_scipy)))
    print(f"Dahl friction-ratio curve, Lambda = {LAMBDA:g}, {VR.size} VR points in [0.05, 0.95]")
    print(f"{'':34}{'seconds':>10}{'speed-up':>10}")
    print(f"{'SciPy solve_ivp LSODA rtol 1e-8':34}{scipy_s:10.4f}{1.0:10.1f}")
    print(f"{'idtool, warm (median of 20)':34}{warm_s:10.5f}{scipy_s / warm_s:10.1f}")
    print(f"{'idtool, first call incl. compile':34}{cold_s:10.4f}{scipy_s / cold_s:10.1f}")
    print(f"{'  (+ importing jax and idtool)':34}{import_s:10.4f}")
    print(f"max |FR_idtool - FR_scipy| = {diff:.2e}  (required < 1e-3)")
    if diff >= 1e-3:
        raise SystemExit("the two implementations disagree")


if __name__ == "__main__":
    main()
