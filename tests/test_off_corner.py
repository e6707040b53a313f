"""The bench model's OFF switch is a rounded corner (issue 28): the force and its slope
are continuous in time there, so the block means are smooth in the OFF delay and a
Levenberg-Marquardt fit can settle on an optimum instead of a kink."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from sample_helpers import small_params

import idtool
from idtool._data._blocks import prepare_fit_data
from idtool._diagnostic import with_code
from idtool._fit import _fit
from idtool._fit._fit import fit_model
from idtool._model._bench import TraceTiming, mean_force_n, smooth_max, smooth_min

SLOPE, STARTUP, CORNER = 150.0, 400.0, 0.5  # [N/s], [N/s], [N]
OFF, T0, T_ON = 60.0, 0.1, 1.0  # [N], [s], [s]


def force(t, t_off, on_n):
    timing = TraceTiming(startup_s=T0, on_start_s=T_ON, on_end_s=t_off)
    return mean_force_n(t, OFF, on_n, timing, SLOPE, STARTUP, 0.0, CORNER)


def switched(t, t_off, on_n):
    """The previous model: a plain switch between the branches at the OFF time."""
    on_len = t_off - T_ON
    depth = OFF - on_n
    since = smooth_max(t - T0, 0.0, CORNER / STARTUP)
    rise = smooth_min(STARTUP * since, OFF, CORNER)
    drop_on = smooth_min(smooth_max(SLOPE * (t - T_ON), 0.0, CORNER), depth, CORNER)
    drop_end = smooth_min(SLOPE * on_len, depth, CORNER)
    drop_after = smooth_max(drop_end - SLOPE * (t - t_off), 0.0, CORNER)
    return rise - jnp.where(t < t_off, drop_on, drop_after)


# a short window that turns back before the ON level (a V corner), and a long one that
# reaches it first (a corner between the plateau and the recovery)
@pytest.mark.parametrize("on_n", [40.0, 55.0])
def test_force_and_its_slope_are_continuous_at_the_off_switch(on_n):
    t_off = 1.05
    slope = jax.grad(force, argnums=0)
    for eps in (1e-9, 1e-7):
        below, above = t_off - eps, t_off + eps
        assert float(force(above, t_off, on_n)) == pytest.approx(
            float(force(below, t_off, on_n)), abs=2.0 * SLOPE * eps + 1e-9
        )
        # the switch's slopes are -SLOPE (or 0) and +SLOPE: rounded, they meet
        assert float(slope(above, t_off, on_n)) == pytest.approx(
            float(slope(below, t_off, on_n)), abs=1e-3 * SLOPE
        )
    # what the plain switch did: a jump of the slope by SLOPE or 2 SLOPE
    old = jax.grad(switched, argnums=0)
    jump = float(old(t_off + 1e-9, t_off, on_n) - old(t_off - 1e-9, t_off, on_n))
    assert jump > 0.9 * SLOPE


@pytest.mark.parametrize("on_n", [40.0, 55.0])
def test_sample_force_is_smooth_in_the_off_time(on_n):
    """At a sample exactly at the OFF switch the force's derivative in the OFF time is
    the same just before and just after (it jumped by up to 2 SLOPE)."""
    t = 1.05
    d_off = jax.grad(force, argnums=1)
    left, right = float(d_off(t, t - 1e-9, on_n)), float(d_off(t, t + 1e-9, on_n))
    assert right == pytest.approx(left, abs=1e-3 * SLOPE)
    old = jax.grad(switched, argnums=1)
    assert abs(float(old(t, t - 1e-9, on_n) - old(t, t + 1e-9, on_n))) > 0.9 * SLOPE


def test_far_from_the_off_switch_the_branches_are_exact():
    """The rounding fades within a few CORNER / SLOPE of the switch: elsewhere the force
    is the previous model's to round-off (no tail on the recovered level)."""
    t_off = 1.05
    t = np.concatenate([np.linspace(0.0, t_off - 0.05, 400), np.linspace(t_off + 0.05, 3, 400)])
    for on_n in (40.0, 55.0):
        new = np.asarray(force(jnp.asarray(t), t_off, on_n))
        old = np.asarray(switched(jnp.asarray(t), t_off, on_n))
        np.testing.assert_allclose(new, old, rtol=0, atol=1e-9)
    # within the corner the rounding is of the order of CORNER, as at the other corners
    near = np.linspace(t_off - 0.01, t_off + 0.01, 201)
    gap = np.abs(np.asarray(force(jnp.asarray(near), t_off, 40.0) - switched(near, t_off, 40.0)))
    assert 0.01 * CORNER < gap.max() <= CORNER


def test_the_fit_converges_and_the_warning_fires_when_it_does_not(monkeypatch):
    """A fit of a small simulated bench reaches its tolerance (no warning); cut to one
    step per run it has not, and the fit says so."""
    dataset, _ = idtool.simulate_bench(small_params(), seed=0)
    data = prepare_fit_data(dataset)
    done = fit_model(data)
    assert not with_code(done.warnings, "lm_not_converged")
    monkeypatch.setattr(_fit, "_MULTISTART_STEPS", 1)
    monkeypatch.setattr(_fit, "_POLISH_STEPS", 1)
    cut = fit_model(data, n_starts=2)
    assert with_code(cut.warnings, "lm_not_converged")
    assert cut.rss > done.rss
