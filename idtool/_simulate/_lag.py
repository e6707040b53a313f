"""The simulator's rate-limited first-order-lag actuator: the force's exact response to
a piecewise-constant target (NumPy; the fit's JAX model of it is
:mod:`idtool._model._actuator`, checked against this one)."""

from __future__ import annotations

import math

import numpy as np

__all__ = ["lag_actuator_force_n"]


def _lag_step(
    elapsed_s: np.ndarray, start_n: float, target_n: float, tau_s: float, rate_n_s: float
) -> np.ndarray:
    """Exact solution of ``dF/dt = clip((target - F) / tau, -rate, rate)`` from ``start_n``.

    While ``|target - F| > rate tau`` the force moves at the rate limit; from then on it
    approaches the target exponentially with time constant ``tau`` (where the exponential's
    own rate is below the limit). Exact for any ``elapsed_s`` >= 0, so the curve does not
    depend on the sample rate.
    """
    gap = target_n - start_n
    direction = math.copysign(1.0, gap)
    tail = min(abs(gap), rate_n_s * tau_s)  # the gap when the exponential part starts
    limited_s = (abs(gap) - tail) / rate_n_s  # duration of the rate-limited part
    linear = start_n + direction * rate_n_s * elapsed_s
    # The clip keeps exp() from overflowing where the linear branch is taken anyway.
    decay = np.exp(-np.maximum(elapsed_s - limited_s, 0.0) / tau_s)
    return np.where(elapsed_s < limited_s, linear, target_n - direction * tail * decay)


def lag_actuator_force_n(
    time_s: np.ndarray,
    off_force_n: float,
    on_force_n: float,
    startup_s: float,
    horn_on_s: tuple[float, float] | None,
    time_constant_s: float,
    rate_limit_n_s: float,
) -> np.ndarray:
    """Noise-free force [N] (without offset) of the rate-limited first-order-lag actuator.

    The target is 0 before ``startup_s`` [s], then ``off_force_n`` [N], ``on_force_n`` [N]
    while the horn is ON (``horn_on_s``, [s]; None for no ON window) and ``off_force_n``
    after; the force follows it by ``dF/dt = clip((target - F) / time_constant_s,
    -rate_limit_n_s, +rate_limit_n_s)`` from 0, solved exactly on each constant-target
    segment (the switchings need not fall on samples).
    """
    t = np.asarray(time_s, dtype=np.float64)
    switches = [startup_s]
    targets = [off_force_n]
    if horn_on_s is not None:
        switches += [horn_on_s[0], horn_on_s[1]]
        targets += [on_force_n, off_force_n]
    out = np.zeros_like(t)
    level = 0.0  # the force at the start of the current segment; 0 before the pull
    for k, (start, target) in enumerate(zip(switches, targets, strict=True)):
        end = switches[k + 1] if k + 1 < len(switches) else math.inf
        inside = (t >= start) & (t < end)
        out[inside] = _lag_step(t[inside] - start, level, target, time_constant_s, rate_limit_n_s)
        if math.isfinite(end):
            span = np.array([end - start])
            level = float(_lag_step(span, level, target, time_constant_s, rate_limit_n_s)[0])
    return out
