"""The actuator models (idtool._model._actuator) against independent references.

The lag model's closed form is checked against a brute-force integration of its ODE
(the simulator uses this model too: its rate limit is one rate for both phases); the
nesting against the slope model; the settle time against the integrated force; and the
gradients the fit needs for being finite everywhere, no-ON traces and tiny lags included.
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from idtool import ACTUATORS, LagActuator, SlopeActuator
from idtool._model._actuator import CORNER_N, SETTLED_FRACTION, lag_force_n
from idtool._model._bench import TraceTiming

OFF_N, ON_N = 200.0, 90.0
TIMING = TraceTiming(startup_s=0.5, on_start_s=4.0, on_end_s=5.2)  # ends before settling


def brute_force_n(t_end_s, tau_s, rate_n_s, startup_rate_n_s, dt_s=1e-5):
    """Forward-Euler integration of ``dF/dt = clip((target - F) / tau, -rate, rate)``
    with the target of :data:`TIMING`; returns (times, forces) every 1 ms."""
    n = round(t_end_s / dt_s)
    t = np.arange(n + 1) * dt_s
    target = np.where(t < TIMING.startup_s, 0.0, OFF_N)
    inside = (t >= TIMING.on_start_s) & (t < TIMING.on_end_s)
    target = np.where(inside, ON_N, target)
    rate = np.where(t < TIMING.on_start_s, startup_rate_n_s, rate_n_s)

    def euler(f, x):  # the ODE itself, no closed form anywhere
        goal, limit = x
        f = f + dt_s * jnp.clip((goal - f) / tau_s, -limit, limit)
        return f, f

    _, f = jax.lax.scan(euler, 0.0, (jnp.asarray(target[:-1]), jnp.asarray(rate[:-1])))
    f = np.concatenate([[0.0], np.asarray(f)])
    every = round(1e-3 / dt_s)
    return t[::every], f[::every]


@pytest.mark.parametrize("tau_s", [0.02, 0.15, 0.6])
def test_lag_closed_form_matches_brute_force_integration(tau_s):
    # Euler's global error is at most dt/2 times the largest |dF/dt| = 150 N/s, 1e-3 N
    # (plus the switch times' rounding to dt, the same again)
    t, f = brute_force_n(8.0, tau_s, 100.0, 150.0)
    closed = lag_force_n(t, OFF_N, ON_N, TIMING, 100.0, 150.0, tau_s)
    np.testing.assert_allclose(closed, f, atol=3e-3)
    # and as the simulator uses it: one rate for both phases
    t, f = brute_force_n(8.0, tau_s, 100.0, 100.0)
    simulated = LagActuator.from_truth({"time_constant_s": tau_s, "rate_limit_n_s": 100.0})
    np.testing.assert_allclose(simulated.force_n(t, OFF_N, ON_N, TIMING, 0.0), f, atol=3e-3)


def test_lag_without_on_window_and_before_the_pull():
    t = np.linspace(0.0, 8.0, 801)
    no_on = TraceTiming(startup_s=0.5, on_start_s=math.inf, on_end_s=math.inf)
    f = np.asarray(lag_force_n(t, OFF_N, ON_N, no_on, 100.0, 150.0, 0.1))
    assert np.all(f[t < 0.5] == 0.0)
    assert f[-1] == pytest.approx(OFF_N, abs=1e-6)
    assert np.all(np.diff(f) >= 0.0)  # never dips without an ON window


def test_tiny_lag_is_the_slope_model():
    # tau -> 0 leaves a tail of rate * tau = 0.01 N: the slope model with sharp corners.
    # The slope model rounds its corners over CORNER_N: hyperbolic rounding of width w
    # moves a corner by at most w / 2, so the two agree to CORNER_N / 2.
    t = np.linspace(0.0, 8.0, 8001)
    v = {"slope_n_s": 100.0, "startup_slope_n_s": 150.0, "time_constant_s": 1e-4}
    lag = LagActuator.from_values(v).force_n(t, OFF_N, ON_N, TIMING, 3.0)
    slope = SlopeActuator.from_values(v).force_n(t, OFF_N, ON_N, TIMING, 3.0)
    assert float(jnp.max(jnp.abs(lag - slope))) <= CORNER_N / 2 + 0.01
    assert ACTUATORS.names()[0] == "slope"  # the fit nests the lag model in it


@pytest.mark.parametrize("tau_s", [0.05, 0.3, 2.0])
def test_settle_time_is_when_the_integrated_force_is_within_the_fraction(tau_s):
    deep = TraceTiming(startup_s=0.5, on_start_s=4.0 + 6 * tau_s, on_end_s=40.0)
    t0 = deep.on_start_s
    act = LagActuator(100.0, 150.0, tau_s)
    settle = float(act.settle_time_s(OFF_N - ON_N))
    before, after = t0 + settle * (1 - 1e-3), t0 + settle * (1 + 1e-3)
    gap = np.asarray(lag_force_n(np.array([before, after]), OFF_N, ON_N, deep, 100, 150, tau_s))
    gap = (gap - ON_N) / (OFF_N - ON_N)
    assert gap[0] > SETTLED_FRACTION > gap[1]


def test_gradients_are_finite_for_the_fit():
    t = jnp.linspace(0.0, 8.0, 400)

    def total(x, timing):
        off, on, rate, up, tau = x
        return jnp.sum(lag_force_n(t, off, on, timing, rate, up, tau))

    x = jnp.array([OFF_N, ON_N, 100.0, 150.0, 0.15])
    no_on = TraceTiming(startup_s=0.5, on_start_s=jnp.inf, on_end_s=jnp.inf)
    for timing in (TIMING, no_on):
        for tau in (0.15, 1e-4):
            g = jax.grad(total)(x.at[4].set(tau), timing)
            assert bool(jnp.all(jnp.isfinite(g))), (timing, tau, g)
    # the switch times too (the horn lags are fitted)
    g = jax.grad(lambda s: total(x, TraceTiming(0.5, s, s + 1.2)))(4.0)
    assert math.isfinite(float(g)) and float(g) != 0.0
