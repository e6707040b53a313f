"""Actuator models: how the pull force follows its target (paper Section 2.2.1, issue 10).

The pneumatic actuator cannot jump: when the horn switches, the friction level changes
at once, but the load cell sees the force move towards the new level at a finite pace.
Two nested models, registered in :data:`ACTUATORS`:

* ``slope`` (:class:`SlopeActuator`): the force moves at a constant slope ``slope_n_s``
  [N/s] (``startup_slope_n_s`` for the start-up from zero) and stops at the level, its
  corners rounded over :data:`CORNER_N` (:func:`idtool._model._bench.mean_force_n`);
* ``lag`` (:class:`LagActuator`): a first-order lag with a rate limit,
  ``dF/dt = clip((target - F) / tau, -rate, rate)`` with ``tau = time_constant_s`` [s]
  and ``rate = slope_n_s`` (``startup_slope_n_s`` during the start-up): the force moves at
  the rate limit while far from the level, then approaches it exponentially over its last
  ``rate * tau`` newtons (:func:`lag_force_n`). ``tau -> 0`` is the slope model with sharp
  corners, so the two are nested; the fit chooses between them by BIC
  (:func:`idtool._fit._run.fit_dataset`).

Why it matters: with a lag, a short ON window ends while the force is still creeping
towards the ON level. The slope model reads that creep as the level itself, and every
friction ratio from a short window is biased (5-10% on the simulated lag bench).

Every model is a small ``eqx.Module`` built from parameter values by name
(:meth:`AbstractActuator.from_values`); its parameters are bench parameters (shared by
every trace, not physical), on the fit's internal scale like the others.
"""

from __future__ import annotations

import abc
from collections.abc import Mapping
from typing import ClassVar

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

from idtool._model._bench import TraceTiming, mean_force_n
from idtool._model._names import DEFAULT_ACTUATOR
from idtool._model._params import Param
from idtool._model._truth_fields import TruthField
from idtool._model._xp import xp
from idtool._registry import Registry

__all__ = [
    "ACTUATORS",
    "CORNER_N",
    "DEFAULT_ACTUATOR",
    "LAG_SETTLE_TIME_CONSTANTS",
    "REACH_FRACTION",
    "SETTLED_FRACTION",
    "AbstractActuator",
    "LagActuator",
    "SlopeActuator",
    "lag_force_n",
    "lag_step_n",
]

ACTUATORS: Registry[type[AbstractActuator]] = Registry("actuator model")

CORNER_N = 0.5  # rounding of the slope model's corners [N]; fixed, not identifiable
# A force counts as settled at its new level once within this fraction of the step.
SETTLED_FRACTION = 0.01
# The simulator's start-up of the lag counts as over once its exponential tail is down to
# exp(-5) < 1% of where it started: the steady OFF sliding is measured from there.
LAG_SETTLE_TIME_CONSTANTS = 5.0
# The simulator's truth: a lagging force "reaches" the ON level when within this fraction
# of the ON-OFF depth at the horn's switch-off.
REACH_FRACTION = 0.02

SLOPE = Param("slope_n_s", "N/s", "log", 1.0, 1e5, start=100.0, description="actuator slope")
STARTUP_SLOPE = Param(
    "startup_slope_n_s", "N/s", "log", 1.0, 1e5, start=100.0, description="start-up slope"
)
TIME_CONSTANT = Param(
    "time_constant_s",
    "s",
    "log",
    1e-4,
    10.0,
    start=0.05,
    description="actuator lag time constant",
)


class AbstractActuator(eqx.Module):
    """How the force follows its target (module docstring). ``fit_params`` are the
    model's parameters (``slope_n_s`` and ``startup_slope_n_s`` first, in every model)."""

    name: ClassVar[str] = ""
    fit_params: ClassVar[tuple[Param, ...]] = (SLOPE, STARTUP_SLOPE)

    @classmethod
    @abc.abstractmethod
    def from_values(cls, values: Mapping[str, ArrayLike]) -> AbstractActuator:
        """The model from parameter values by name (its ``fit_params``)."""

    @abc.abstractmethod
    def force_n(
        self,
        time_s: Float[ArrayLike, "*b"],
        off_force_n: Float[ArrayLike, "*b"],
        on_force_n: Float[ArrayLike, "*b"],
        timing: TraceTiming,
        offset_n: Float[ArrayLike, "*b"],
    ) -> Float[Array, "*b"]:
        """Noise-free load-cell force [N] at ``time_s`` [s]: 0 before the pull, the
        start-up towards ``off_force_n`` [N], the ON window's step towards ``on_force_n``
        [N] and back; plus ``offset_n`` [N]. Elementwise (everything broadcasts)."""

    @abc.abstractmethod
    def settle_time_s(self, depth_n: ArrayLike) -> Array:
        """Time [s] after a switch until the force is within :data:`SETTLED_FRACTION` of
        a step ``depth_n`` [N] deep (from rest at the old level)."""

    @classmethod
    def truth_fields(cls) -> tuple[TruthField, ...]:
        """The model's numbers in the simulator's parameter file (beside the common
        ``pull_start_s``): by default its ``fit_params``."""
        return tuple(TruthField.of(p) for p in cls.fit_params)

    @classmethod
    def from_truth(cls, values: Mapping[str, float]) -> AbstractActuator:
        """The model from the values of :meth:`truth_fields` by their file names."""
        return cls.from_values(values)

    @abc.abstractmethod
    def startup_duration_s(self, off_force_n: float) -> float:
        """Time [s] from the pull's start until the start-up towards ``off_force_n`` [N]
        is over and the steady OFF sliding begins (the simulator plans its ON window
        from there)."""

    def reaches_level(self, off_force_n: float, on_force_n: float, timing: TraceTiming) -> bool:
        """Whether the force gets down to within :data:`REACH_FRACTION` of the ON-OFF
        depth of ``on_force_n`` [N] by the ON window's end (``timing``, [s]); read off
        :meth:`force_n` at the switch-off."""
        end = jnp.asarray([timing.on_end_s])
        lowest = float(_force_n(self, end, off_force_n, on_force_n, timing)[0])
        return lowest - on_force_n <= REACH_FRACTION * (off_force_n - on_force_n)


@ACTUATORS.register("slope")
class SlopeActuator(AbstractActuator):
    """Constant slopes, rounded corners (:func:`idtool._model._bench.mean_force_n`)."""

    slope_n_s: Float[ArrayLike, "*b"]
    startup_slope_n_s: Float[ArrayLike, "*b"]
    # the corners' rounding [N]: fixed in the fit, a truth field of the simulator
    corner_n: float = eqx.field(static=True, default=CORNER_N)

    @classmethod
    def from_values(cls, values):
        return cls(values["slope_n_s"], values["startup_slope_n_s"])

    @classmethod
    def truth_fields(cls):
        return (
            TruthField.of(STARTUP_SLOPE),
            TruthField.of(SLOPE),
            TruthField("corner_n", "N", "width over which the model's corners are rounded"),
        )

    @classmethod
    def from_truth(cls, values):
        return cls(values["slope_n_s"], values["startup_slope_n_s"], values["corner_n"])

    def force_n(self, time_s, off_force_n, on_force_n, timing, offset_n):
        return mean_force_n(
            time_s,
            off_force_n,
            on_force_n,
            timing,
            self.slope_n_s,
            self.startup_slope_n_s,
            offset_n,
            self.corner_n,
        )

    def settle_time_s(self, depth_n):
        return (1.0 - SETTLED_FRACTION) * depth_n / self.slope_n_s

    def startup_duration_s(self, off_force_n):
        return float(off_force_n / self.startup_slope_n_s)

    def reaches_level(self, off_force_n, on_force_n, timing):
        """Whether the slope covers the whole depth within the ON window."""
        return bool(
            self.slope_n_s * (timing.on_end_s - timing.on_start_s) >= off_force_n - on_force_n
        )


@ACTUATORS.register("lag")
class LagActuator(AbstractActuator):
    """First-order lag with a rate limit (:func:`lag_force_n`); nests the slope model."""

    slope_n_s: Float[ArrayLike, "*b"]
    startup_slope_n_s: Float[ArrayLike, "*b"]
    time_constant_s: Float[ArrayLike, "*b"]
    fit_params: ClassVar[tuple[Param, ...]] = (SLOPE, STARTUP_SLOPE, TIME_CONSTANT)

    @classmethod
    def from_values(cls, values):
        return cls(values["slope_n_s"], values["startup_slope_n_s"], values["time_constant_s"])

    def force_n(self, time_s, off_force_n, on_force_n, timing, offset_n):
        return jnp.asarray(offset_n) + lag_force_n(
            time_s,
            off_force_n,
            on_force_n,
            timing,
            self.slope_n_s,
            self.startup_slope_n_s,
            self.time_constant_s,
        )

    @classmethod
    def truth_fields(cls):
        """The time constant and one rate limit, for the start-up and the switchings."""
        return (
            TruthField.of(TIME_CONSTANT),
            TruthField(
                "rate_limit_n_s",
                "N/s",
                "largest rate of change of the force (flow-restricted pneumatics), for "
                "the start-up as for the ON/OFF switchings",
            ),
        )

    @classmethod
    def from_truth(cls, values):
        rate = values["rate_limit_n_s"]
        return cls(rate, rate, values["time_constant_s"])

    def startup_duration_s(self, off_force_n):
        rate, tau = self.startup_slope_n_s, self.time_constant_s
        return float(max(off_force_n - rate * tau, 0.0) / rate + LAG_SETTLE_TIME_CONSTANTS * tau)

    def settle_time_s(self, depth_n):
        x = xp(depth_n, self.slope_n_s, self.time_constant_s)  # NumPy on the host
        depth = x.asarray(depth_n)
        tail = x.minimum(depth, self.slope_n_s * self.time_constant_s)
        # rate-limited part, then the exponential down to SETTLED_FRACTION of the depth
        return (depth - tail) / self.slope_n_s + self.time_constant_s * x.log(
            x.maximum(tail / (SETTLED_FRACTION * depth), 1.0)
        )


@jax.jit
def _force_n(actuator, time_s, off_force_n, on_force_n, timing):
    """:meth:`AbstractActuator.force_n` without offset, compiled once per model (op by
    op, the lag's 40 operations took 7 ms a trace)."""
    return actuator.force_n(time_s, off_force_n, on_force_n, timing, 0.0)


def lag_step_n(
    elapsed_s: Float[ArrayLike, "*b"],
    start_n: Float[ArrayLike, "*b"],
    target_n: Float[ArrayLike, "*b"],
    time_constant_s: Float[ArrayLike, "*b"],
    rate_n_s: Float[ArrayLike, "*b"],
) -> Float[Array, "*b"]:
    """Force [N] ``elapsed_s`` [s] after the target stepped to ``target_n`` [N] with the
    force at ``start_n`` [N]: the exact solution of
    ``dF/dt = clip((target - F) / tau, -rate, rate)`` (first order: the force is the
    whole state, so each segment starts from where the previous one left it).

    While the gap exceeds ``rate tau`` the force moves at the rate limit; then it closes
    the last ``rate tau`` exponentially (its initial pace is the rate limit, so the
    curve is smooth). Exact at any time, so the model does not depend on the sample rate.
    """
    elapsed = jnp.asarray(elapsed_s)
    gap = jnp.asarray(target_n) - jnp.asarray(start_n)
    size = jnp.abs(gap)
    direction = jnp.sign(gap)
    tail = jnp.minimum(size, rate_n_s * time_constant_s)
    limited_s = (size - tail) / rate_n_s
    linear = start_n + direction * rate_n_s * elapsed
    # max(., 0): the exponential's argument stays <= 0 where the linear branch is taken
    decay = jnp.exp(-jnp.maximum(elapsed - limited_s, 0.0) / time_constant_s)
    return jnp.where(elapsed < limited_s, linear, target_n - direction * tail * decay)


def lag_force_n(
    time_s: Float[ArrayLike, "*b"],
    off_force_n: Float[ArrayLike, "*b"],
    on_force_n: Float[ArrayLike, "*b"],
    timing: TraceTiming,
    rate_n_s: Float[ArrayLike, "*b"],
    startup_rate_n_s: Float[ArrayLike, "*b"],
    time_constant_s: Float[ArrayLike, "*b"],
) -> Float[Array, "*b"]:
    """Noise-free force [N] (without offset) of the rate-limited first-order lag.

    The target is 0 before ``timing.startup_s``, ``off_force_n`` after it (reached at
    ``startup_rate_n_s``), ``on_force_n`` within the ON window and ``off_force_n`` again
    after it (at ``rate_n_s``); each segment starts from where the previous one left the
    force (:func:`lag_step_n`), so a short ON window ends before the ON level. An infinite
    ON start means no ON window. Elementwise: everything broadcasts.
    """
    t = jnp.asarray(time_s, float)
    has_on = jnp.isfinite(timing.on_start_s) & jnp.isfinite(timing.on_end_s)
    # finite stand-ins without an ON window, so no inf - inf reaches a gradient
    t_on = jnp.where(has_on, timing.on_start_s, 0.0)
    t_off = jnp.where(has_on, timing.on_end_s, 0.0)
    t0 = jnp.asarray(timing.startup_s)

    def step(elapsed, start, target, rate):
        return lag_step_n(elapsed, start, target, time_constant_s, rate)

    rising = step(t - t0, 0.0, off_force_n, startup_rate_n_s)
    at_on = step(t_on - t0, 0.0, off_force_n, startup_rate_n_s)
    falling = step(t - t_on, at_on, on_force_n, rate_n_s)
    at_off = step(t_off - t_on, at_on, on_force_n, rate_n_s)
    recovering = step(t - t_off, at_off, off_force_n, rate_n_s)
    after_start = jnp.where(has_on & (t >= t_on), jnp.where(t < t_off, falling, recovering), rising)
    return jnp.where(t < t0, 0.0, after_start)
