"""Level models: how the friction levels move within their plateaus (issue 26, item 4).

The contact model gives one friction ratio per operating point, the cycle-averaged steady
state at the slip amplitude the coupling gives for the commanded amplitude (notes §3-5).
A real horn may not hold that amplitude: the transducer warms and detunes within seconds,
its amplitude fades, and the ON level rises through the window (the fading horn of
:mod:`idtool._simulate._plateau_drift`). A fit that holds the ON level constant reads the
window's mean, so its friction ratios depend on the window's length and its bands miss
the friction ratio of the commanded amplitude. Likewise a friction coefficient that
creeps through the pull (webbing warming, running-in) moves every level. Three models,
registered in :data:`LEVEL_MODELS`, each nesting the first:

* ``steady`` (:class:`SteadyLevel`): the OFF level is ``F_off = mu N`` and the ON level
  ``FR0 F_off`` throughout their plateaus;
* ``relaxing`` (:class:`RelaxingOnLevel`): the ON level starts at ``FR0 F_off`` at the
  horn's switch-on (the cold horn at the commanded amplitude: ``FR0`` is the contact
  model's friction ratio) and relaxes towards ``FR_ss F_off`` with time constant
  ``tau = on_relax_time_s`` [s], shared by every trace::

      FR(t) = min(FR0 (1 + r_i h(t)), 1),   h(t) = 1 - exp(-(t - t_on) / tau)     (eq. R1)

  with ``r_i = on_rise[trace]`` [-] the relative rise of trace ``i``'s ON level at steady
  state, a per-trace nuisance like the load-cell offset, so ``FR_ss = min(FR0 (1 + r_i),
  1)`` (eq. R2); ``t - t_on`` is frozen at the switch-off (the recovery starts from the
  level the window ended at). ``r_i = 0`` is the steady model, which it nests;
* ``creeping`` (:class:`CreepingLevel`): the whole friction force (start-up, OFF and ON
  levels alike; not the load cell's offset) grows with the sliding time,
  ``F(t) = F_steady(t) (1 + c max(t - t_pull, 0))`` (eq. C1), ``c = level_creep_per_s``
  [1/s] shared by every trace, ``t_pull`` the trace's pull start: ``mu`` and the levels
  are their values at the pull's start and FR (ON over OFF at the same time) does not
  creep. ``c = 0`` is the steady model. A load cell's offset drift (offset model
  ``drift``) is additive, the same newtons per second at every level; a creep is
  relative, so the ON level creeps by FR times the OFF level's rate. The drifting
  offset alone took up the creep of the simulated creep bench but left every ON level
  low: its held-out friction ratios fell 0.004-0.011 below the truth, outside bands
  0.001-0.002 wide (0 of 6).

The fit tries the relaxing model when the steady fit's ON plateaus drift and the
creeping one when its OFF plateaus drift or its offset drifts grow with the load
(:mod:`idtool._fit._plateau_drift`), each nested in the steady fit, and keeps it if BIC
says so (:func:`idtool._fit._run.fit_dataset`).

Why a rise per trace, not one shared by all: the contact model could give the steady
state itself, ``FR(a0 (1 - f))`` for a horn that loses a fraction ``f`` of its amplitude,
but it would be a third level per trace that the fit's Jacobian (taken through the OFF and
ON levels, :meth:`BenchModel.normal_equations`) and the levels model do not carry. No
function of ``FR0`` alone stands in for it: a 20% fade of the simulated Dahl contact
raises FR by 27% at 270 N (FR0 0.13-0.15) and 41% at 670 N (FR0 0.37-0.39), more than
the Coulomb limit (26% and 31%) or the creep limit (23% at 670 N) say, as the fade lowers
``Lambda = Kt a / (mu N)`` too. A rise shared by every trace (0.42 on that bench, tau
1.59 s against 1.5 s) left the held-out cold-horn FR 7% low, outside every band (0 of 6).
A rise per trace leaves the fade's shape free, and ``FR0``, which the physics model
describes, is read at the window's start where the fade has not acted; the steady
state is reported per trace (eq. R2), not predicted at new operating points.

The actuator follows the moving level as it follows a step (the simulator's convention):
with ``w = (F_off - F(t)) / (F_off - F_on)`` the fraction of the constant-level dip the
actuator's path ``F(t)`` has covered, the force is ``F_off - w (F_off - FR(t) F_off)``
(eq. R3), so before the switch-on, and always under the steady and creeping models, it is
the actuator's path itself.
"""

from __future__ import annotations

import abc
from collections.abc import Mapping
from typing import TYPE_CHECKING, ClassVar

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

from idtool._model._bench import TraceTiming
from idtool._model._names import DEFAULT_LEVEL_MODEL
from idtool._model._params import Param
from idtool._model._xp import xp
from idtool._registry import Registry

if TYPE_CHECKING:
    from idtool._model._actuator import AbstractActuator

__all__ = [
    "DEFAULT_LEVEL_MODEL",
    "LEVEL_MODELS",
    "AbstractLevelModel",
    "CreepingLevel",
    "RelaxingOnLevel",
    "SteadyLevel",
    "relaxed_fraction",
]

LEVEL_MODELS: Registry[type[AbstractLevelModel]] = Registry("level model")

# (name, unit, internal scale) of the per-trace rise, centred on 0 (the steady model):
# a step of 0.1 is a tenth of the ON level, the size of a 10% fade's effect.
ON_RISE = ("on_rise", "1", 0.1)
# tau from 0.05 s (below the actuator's settling it cannot be told from the step) to
# 30 s (ten times the longest window: a straight rise through it). At on_rise = 0 tau has
# no effect, so a fit nested in the steady one starts it at 0.3, 1 and 3 s in turn: from
# 1 s alone, the simulated fading bench (true tau 1.5 s) ended at the 0.05 s bound, -2 log
# L 1094 worse than with tau held at 1.5 s.
ON_RELAX_TIME = Param(
    "on_relax_time_s",
    "s",
    "log",
    0.05,
    30.0,
    start=1.0,
    nested_at=1.0,
    nested_starts=(0.3, 1.0, 3.0),
    description="time constant of the ON level's relaxation",
)


class AbstractLevelModel(eqx.Module):
    """How the levels move within their plateaus (module docstring); ``fit_params`` are
    its shared bench parameters, ``trace_params`` its per-trace ones (none for the steady
    model)."""

    name: ClassVar[str] = ""
    fit_params: ClassVar[tuple[Param, ...]] = ()
    # per-trace nuisances (name, unit, internal scale), after the bench model's own
    trace_params: ClassVar[tuple[tuple[str, str, float], ...]] = ()

    @classmethod
    @abc.abstractmethod
    def from_values(cls, values: Mapping[str, ArrayLike]) -> AbstractLevelModel:
        """The model from parameter values by name (its ``fit_params``)."""

    @abc.abstractmethod
    def force_n(
        self,
        actuator: AbstractActuator,
        time_s: Float[ArrayLike, "*b"],
        off_force_n: Float[ArrayLike, "*b"],
        on_force_n: Float[ArrayLike, "*b"],
        timing: TraceTiming,
        offset_n: Float[ArrayLike, "*b"],
    ) -> Float[Array, "*b"]:
        """Noise-free load-cell force [N] at ``time_s`` [s]: the ``actuator``'s path
        (:meth:`AbstractActuator.force_n`) between the OFF level ``off_force_n`` [N] and
        the ON level, which starts at ``on_force_n`` [N] at the horn's switch-on (both
        at the pull's start); plus ``offset_n`` [N]."""

    @abc.abstractmethod
    def friction_ratio(self, fr0: ArrayLike, elapsed_s: ArrayLike) -> Array:
        """FR [-] ``elapsed_s`` [s] after the horn's switch-on, from its value ``fr0`` at
        the switch-on (eq. R1); ``elapsed_s = inf`` gives the steady state (eq. R2)."""

    def steady_friction_ratio(self, fr0: ArrayLike) -> Array:
        """FR [-] at steady state, from ``fr0`` at the switch-on (eq. R2)."""
        return self.friction_ratio(fr0, float("inf"))


@LEVEL_MODELS.register("steady")
class SteadyLevel(AbstractLevelModel):
    """The OFF level holds ``mu N`` and the ON level ``FR0 mu N`` through their plateaus."""

    @classmethod
    def from_values(cls, values):
        return cls()

    def force_n(self, actuator, time_s, off_force_n, on_force_n, timing, offset_n):
        return actuator.force_n(time_s, off_force_n, on_force_n, timing, offset_n)

    def friction_ratio(self, fr0, elapsed_s):
        x = xp(fr0)
        return x.asarray(fr0) + 0.0 * x.asarray(elapsed_s)


def relaxed_fraction(
    time_s: Float[ArrayLike, "*b"], timing: TraceTiming, tau_s: Float[ArrayLike, "*b"]
) -> Float[Array, "*b"]:
    """``h(t) = 1 - exp(-(t - t_on) / tau)`` of eq. R1 [-], with ``t`` clipped to the ON
    window (0 before the switch-on, frozen after the switch-off; 0 without a window)."""
    t = jnp.asarray(time_s, float)
    has_on = jnp.isfinite(timing.on_start_s) & jnp.isfinite(timing.on_end_s)
    # finite stand-ins without an ON window, so no inf - inf reaches a gradient
    t_on = jnp.where(has_on, timing.on_start_s, 0.0)
    t_off = jnp.where(has_on, timing.on_end_s, 0.0)
    elapsed = jnp.clip(t, t_on, jnp.maximum(t_on, t_off)) - t_on
    return jnp.where(has_on, -jnp.expm1(-elapsed / tau_s), 0.0)


@LEVEL_MODELS.register("relaxing")
class RelaxingOnLevel(AbstractLevelModel):
    """The ON level relaxes from ``FR0 F_off`` by ``on_rise`` [-] of itself (per trace)
    with time constant ``on_relax_time_s`` [s] (eqs. R1-R3); nests the steady model at
    ``on_rise = 0``."""

    on_rise: Float[ArrayLike, "*b"]
    on_relax_time_s: Float[ArrayLike, "*b"]
    fit_params: ClassVar[tuple[Param, ...]] = (ON_RELAX_TIME,)
    trace_params: ClassVar[tuple[tuple[str, str, float], ...]] = (ON_RISE,)

    @classmethod
    def from_values(cls, values):
        return cls(values["on_rise"], values["on_relax_time_s"])

    def force_n(self, actuator, time_s, off_force_n, on_force_n, timing, offset_n):
        bare = actuator.force_n(time_s, off_force_n, on_force_n, timing, 0.0)
        off, on = jnp.asarray(off_force_n), jnp.asarray(on_force_n)
        h = relaxed_fraction(time_s, timing, self.on_relax_time_s)
        depth = off - on
        deep = depth > 1e-9 * jnp.abs(off)
        # (F_off - ON(t)) / (F_off - ON(t_on)) of eq. R3, ON(t) capped at F_off
        shrink = jnp.maximum(1.0 - on * self.on_rise * h / jnp.where(deep, depth, 1.0), 0.0)
        moved = off - (off - bare) * jnp.where(deep, shrink, 1.0)
        return jnp.asarray(offset_n) + moved

    def friction_ratio(self, fr0, elapsed_s):
        x = xp(fr0, self.on_rise, self.on_relax_time_s)
        h = -x.expm1(-x.asarray(elapsed_s, float) / self.on_relax_time_s)
        return x.minimum(x.asarray(fr0) * (1.0 + self.on_rise * h), 1.0)


# c in (-0.01, 0.01) 1/s: up to 1% of the level per second, 12% over a 12 s pull (the
# simulated creep bench has 0.2%/s); tanh, so c = 0 (the steady model) is interior.
LEVEL_CREEP = Param(
    "level_creep_per_s",
    "1/s",
    "tanh",
    -0.01,
    0.01,
    start=0.0,
    nested_at=0.0,
    description="relative creep rate of the friction level",
)


@LEVEL_MODELS.register("creeping")
class CreepingLevel(AbstractLevelModel):
    """The friction force grows by ``level_creep_per_s`` [1/s] of itself per second of
    sliding (eq. C1); nests the steady model at 0."""

    level_creep_per_s: Float[ArrayLike, "*b"]
    fit_params: ClassVar[tuple[Param, ...]] = (LEVEL_CREEP,)

    @classmethod
    def from_values(cls, values):
        return cls(values["level_creep_per_s"])

    def force_n(self, actuator, time_s, off_force_n, on_force_n, timing, offset_n):
        bare = actuator.force_n(time_s, off_force_n, on_force_n, timing, 0.0)
        sliding = jnp.maximum(jnp.asarray(time_s, float) - timing.startup_s, 0.0)
        return jnp.asarray(offset_n) + bare * (1.0 + self.level_creep_per_s * sliding)

    def friction_ratio(self, fr0, elapsed_s):
        x = xp(fr0)
        return x.asarray(fr0) + 0.0 * x.asarray(elapsed_s)
