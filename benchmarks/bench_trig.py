"""Benchmark: the contact's sines and cosines, XLA's against idtool's polynomials.

The cycle average (``idtool._model._contact.prescribed_cycle_average``) evaluates three
trigonometric functions per step of its phase grid (2 x 256 steps per operating point).
``idtool._model._trig`` computes them as polynomials on a reduced argument. Printed:

* per element, on 51,200 phases in [0, 4 pi]: NumPy's ``np.cos``, XLA's ``jnp.cos`` and
  idtool's ``trig.cos`` (ns per element), and their largest difference from NumPy;
* the friction-ratio kernel (Dahl, 240 operating points: Lambda 0.3 to 1e6, VR 0.01
  to 1.5, vmapped and compiled) with XLA's functions and with idtool's: milliseconds
  per call, their ratio, and the largest difference of the friction ratios and of
  their gradients in Lambda and VR (relative to each gradient's largest value).

Run: ``make bench`` or ``.venv/bin/python benchmarks/bench_trig.py``.
"""

from __future__ import annotations

import time
import types

import jax
import jax.numpy as jnp
import numpy as np

import idtool
from idtool._model import _contact
from idtool._model import _trig as trig

jax.config.update("jax_enable_x64", True)


def per_call(f, *args, repeat: int = 5, number: int = 100) -> float:
    """Best of ``repeat`` means over ``number`` calls [s]."""
    jax.block_until_ready(f(*args))
    best = np.inf
    for _ in range(repeat):
        t0 = time.perf_counter()
        for _ in range(number):
            jax.block_until_ready(f(*args))
        best = min(best, (time.perf_counter() - t0) / number)
    return best


def with_xla_trig():
    """``prescribed_cycle_average`` as it was before ``_trig``: the same source with
    XLA's own sine and cosine (new function objects, so JAX traces them afresh)."""
    names = {"cos": jnp.cos, "sin": jnp.sin}
    env = dict(vars(_contact), trig=types.SimpleNamespace(**names))
    slip = _contact._slip_m  # its defaults are the polynomials: XLA's in the copy
    env["_slip_m"] = types.FunctionType(slip.__code__, env, "_slip_m", (jnp.cos, jnp.sin))
    raw = _contact.prescribed_cycle_average.__wrapped__
    return jax.jit(types.FunctionType(raw.__code__, env, raw.__name__, raw.__defaults__))


def main() -> None:
    x = np.linspace(0.0, 4.0 * np.pi, 51_200)
    xj = jnp.asarray(x)
    t_np = min(timeit_np(x) for _ in range(5))
    t_xla = per_call(jax.jit(jnp.cos), xj)
    t_ours = per_call(jax.jit(trig.cos), xj)
    err = float(np.max(np.abs(np.asarray(trig.cos(xj)) - np.cos(x))))
    ns = {k: t / x.size * 1e9 for k, t in (("NumPy", t_np), ("XLA", t_xla), ("idtool", t_ours))}
    print("cos per element: " + ", ".join(f"{k} {v:.1f} ns" for k, v in ns.items()))
    print(f"  idtool's max |diff| from NumPy {err:.1e}")

    lam = jnp.asarray(np.repeat([0.3, 3.0, 10.0, 100.0, 1e4, 1e6], 40))
    vr = jnp.asarray(np.tile(np.linspace(0.01, 1.5, 40), 6))
    xla_kernel = with_xla_trig()

    def kernel(cycle):
        def fr(lam_, vr_):
            return cycle(idtool.Dahl(fc_n=1.0, kt_n_m=lam_), vr_, 1.0, 1.0).friction_ratio

        return jax.jit(jax.vmap(fr)), jax.jit(jax.vmap(jax.grad(fr, argnums=(0, 1))))

    (f_xla, g_xla), (f_ours, g_ours) = kernel(xla_kernel), kernel(_contact.prescribed_cycle_average)
    a, b = np.asarray(f_xla(lam, vr)), np.asarray(f_ours(lam, vr))
    ga, gb = g_xla(lam, vr), g_ours(lam, vr)
    # each gradient's largest difference, relative to its largest magnitude
    grad_rel = max(
        float(np.max(np.abs(np.asarray(p) - np.asarray(q))) / np.max(np.abs(np.asarray(p))))
        for p, q in zip(ga, gb, strict=True)
    )
    t1, t2 = per_call(f_xla, lam, vr), per_call(f_ours, lam, vr)
    print(f"friction-ratio kernel, {lam.size} operating points x 2 x 256 phase steps:")
    print(f"  XLA's sin/cos {t1 * 1e3:.3f} ms, idtool's {t2 * 1e3:.3f} ms: {t1 / t2:.2f}x")
    print(f"  max |FR diff| {np.max(np.abs(a - b)):.1e}", end="; ")
    print(f"gradients' max diff relative to their largest {grad_rel:.1e}")


def timeit_np(x: np.ndarray, number: int = 100) -> float:
    t0 = time.perf_counter()
    for _ in range(number):
        np.cos(x)
    return (time.perf_counter() - t0) / number


if __name__ == "__main__":
    main()
