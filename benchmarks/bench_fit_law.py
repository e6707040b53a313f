"""fit-law (issue 30, item 3): coverage of the 95% intervals over seeds, and the time of
a 10,000-sample LuGre fit beside SciPy's least_squares over a NumPy integration of the
same model (the same exact slip update, in a Python loop; no intervals on that side).

    .venv/bin/python benchmarks/bench_fit_law.py --seeds 50
"""

from __future__ import annotations

import argparse
import os
import time

import numpy as np

import idtool
from idtool._simulate._series import LUGRE_TRUTH


def coverage(kind: str, seeds: int) -> None:
    hits = {k: 0 for k in LUGRE_TRUTH}
    stated = {k: 0 for k in LUGRE_TRUTH}
    seconds = []
    for seed in range(seeds):
        fit = idtool.fit_law(idtool.simulate_series("lugre", kind=kind, seed=1000 + seed))
        seconds.append(fit.seconds)
        for k, truth in LUGRE_TRUTH.items():
            e = fit.estimates[k]
            hits[k] += e.ci95[0] <= truth <= e.ci95[1]
            stated[k] += bool(e.one_sided or e.weakly_identified)
    print(
        f"\n{kind}: {seeds} seeds, 3,001 samples, noise 0.01 N; "
        f"median fit {np.median(seconds):.2f} s"
    )
    print(f"{'parameter':<24}{'truth':>10}{'coverage':>10}{'stated unidentified':>22}")
    for k, truth in LUGRE_TRUTH.items():
        print(f"{k:<24}{truth:>10.4g}{hits[k] / seeds:>10.2f}{stated[k]:>22d}")


def numpy_force(p, t, v):
    """LuGre force by the same update (midpoint level, 4 parts), in NumPy."""
    fc, kt, sr, vs, s1, s2 = p
    fs = sr * fc
    level = lambda vel: fc + (fs - fc) * np.exp(-((vel / vs) ** 2))  # noqa: E731
    fb = np.zeros(t.size)
    for k in range(t.size - 1):
        h, va, vb = (t[k + 1] - t[k]) / 4, v[k], v[k + 1]
        x = fb[k]
        for j in range(4):
            a, b = va + (vb - va) * j / 4, va + (vb - va) * (j + 1) / 4
            pieces = [(0.5 * (a + b) * h, 0.5 * (a + b))]
            if a * b < 0:
                th = a / (a - b)
                pieces = [(0.5 * a * th * h, 0.5 * a), (0.5 * b * (1 - th) * h, 0.5 * b)]
            for du, vm in pieces:
                if du != 0:
                    s, lv = np.sign(du), level(vm)
                    x = s * lv + (x - s * lv) * np.exp(-kt * abs(du) / lv)
        fb[k + 1] = x
    lv = level(v)
    return fb + s1 * (v - np.abs(v) * fb / lv) + s2 * v


def timing() -> None:
    from scipy.optimize import least_squares

    series = idtool.simulate_series("lugre", kind="sliding", duration_s=10.0, seed=7)
    t0 = time.perf_counter()
    fit = idtool.fit_law(series)
    cold = time.perf_counter() - t0
    t0 = time.perf_counter()
    idtool.fit_law(series)
    warm = time.perf_counter() - t0
    t, v, f = series.time_s, series.velocity_m_s, series.force_n
    start = np.array([1.5, 1.5 / 3e-4, 1.2, 0.01, 10.0, 10.0])  # a grid start of fit-law's
    t0 = time.perf_counter()
    res = least_squares(
        lambda lp: numpy_force(np.exp(lp), t, v) - f, np.log(start), method="trf", x_scale=1.0
    )
    scipy_s = time.perf_counter() - t0
    print(f"\n10,000 samples, LuGre, load {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores")
    print(f"fit-law cold (compile incl., intervals, profiles) {cold:8.2f} s")
    print(f"fit-law warm                                      {warm:8.2f} s")
    print(
        f"scipy least_squares over NumPy (one start, no CIs) {scipy_s:8.2f} s "
        f"({res.nfev} evaluations; ratio scipy / fit-law warm {scipy_s / warm:.1f})"
    )
    print("fit-law Kt", fit.estimates["Kt"].statement, "scipy Kt", float(np.exp(res.x[1])))


if __name__ == "__main__":
    ap = argparse.ArgumentParser()
    ap.add_argument("--seeds", type=int, default=50)
    ap.add_argument("--kinds", default="sliding,presliding")
    ap.add_argument("--no-timing", action="store_true")
    args = ap.parse_args()
    if not args.no_timing:
        timing()
    for kind in args.kinds.split(","):
        coverage(kind, args.seeds)
