"""Departures that move a level within its plateau: a fading horn and a creeping friction.

Both are truth-only (the fit's bench model holds every level constant between switchings),
so a fit on such a bench must notice them in its residuals
(:mod:`idtool._fit._plateau_drift`).

* **Fading horn** (``horn_fading``): the horn's amplitude, hence the contact's slip
  amplitude, decays during each ON window (the transducer heats and detunes), from ``a0``
  at the horn's switch-on towards ``a0 (1 - f)``::

      a(t_on) = a0 (1 - f (1 - exp(-t_on / tau)))

  with ``t_on`` [s] the time since the horn switched on, ``f = fade_fraction`` [-] and
  ``tau = fade_time_constant_s`` [s]. Less slip amplitude gives less reduction, so the
  ON level ``FR(a(t)) mu N`` rises through the window; the contact model gives FR at each
  amplitude (the contact's law at the trace's mu, :func:`fade_ratio_curve`). The actuator
  follows the moving target as it follows a step: the force is
  ``OFF - w(t) (OFF - ON(t))`` with ``w`` the fraction of the ON dip the actuator has
  covered (0 before the switch-on, 1 at the ON level, back to 0 after the recovery) and
  ``ON(t)`` held at its switch-off value once the horn is off.
* **Creeping level** (``contact.level_creep_per_s``): the friction coefficient creeps
  linearly with sliding time from the pull's start (webbing warming, running-in),
  ``mu(t) = mu (1 + r max(t - t_pull, 0))`` with ``r`` [1/s]; the whole friction force
  (start-up, OFF and ON levels alike) scales with it. Unlike the load cell's offset drift
  (additive, the same newtons per second at every level and before the pull too) it is
  relative: the ON level creeps by FR times the OFF level's newtons per second, and the
  zero-force baseline before the pull does not move.
"""

from __future__ import annotations

import functools
import math

import jax
import jax.numpy as jnp
import numpy as np

from idtool._model._directions import AbstractDirection, Along
from idtool._model._laws import AbstractFrictionLaw
from idtool._simulate._params import BenchParams
from idtool._simulate._truth import TraceTruth

__all__ = [
    "FADE_GRID",
    "creep_factor",
    "fade_factor",
    "fade_ratio_curve",
    "faded_force_n",
    "on_force_end_n",
    "on_level_over_time_n",
    "with_plateau_drifts",
]

# Amplitude points the ON level's rise is interpolated between: FR is smooth in the
# amplitude; linear interpolation between 17 points over a 20% fade was measured 6e-5 to
# 8e-5 off the contact model at the midpoints (Dahl, slip 1-10 um), 65 points (error ~h^2,
# 16x smaller) keep it below 1e-5 for one cycle average per point.
FADE_GRID = 65


def fade_factor(time_s: np.ndarray, horn_on_s: tuple[float, float], fraction: float, tau_s: float):
    """Slip amplitude over its value at switch-on [-] at ``time_s`` [s]:
    ``1 - f (1 - exp(-t_on / tau))``, ``t_on`` the time since the horn's switch-on, frozen at
    the switch-off (module docstring); 1 before the switch-on."""
    t_on = np.clip(np.asarray(time_s, float), horn_on_s[0], horn_on_s[1]) - horn_on_s[0]
    return 1.0 - fraction * (1.0 - np.exp(-t_on / tau_s))


@functools.partial(jax.jit, static_argnames=("n", "direction"))
def _friction_ratios(law, speed_m_s, w_rad_s, amplitudes_m, load_n, direction, n=FADE_GRID):
    def one(a):
        return direction.cycle_average(law, speed_m_s, a, w_rad_s, load_n).friction_ratio

    return jax.vmap(one)(jnp.reshape(amplitudes_m, (n,)))


def fade_ratio_curve(
    law: AbstractFrictionLaw,
    speed_m_s: float,
    vibration_frequency_hz: float,
    slip_amplitude_m: float,
    fraction: float,
    load_n: float = 1.0,
    direction: type[AbstractDirection] = Along,
) -> tuple[np.ndarray, np.ndarray]:
    """Amplitude factors ``g`` from ``1 - fraction`` to 1 and ``FR(g a0) / FR(a0)`` [-]
    there: how much the ON level rises when the slip amplitude ``a0`` [m] has faded to
    ``g a0`` (the contact ``law`` at its load ``load_n`` [N], sliding at ``speed_m_s``
    [m/s], vibrating at ``vibration_frequency_hz`` [Hz] in ``direction``)."""
    g = np.linspace(1.0 - fraction, 1.0, FADE_GRID)
    w = 2.0 * math.pi * vibration_frequency_hz
    fr = np.asarray(
        _friction_ratios(law, speed_m_s, w, g * slip_amplitude_m, load_n, direction=direction)
    )
    return g, fr / fr[-1]


def faded_force_n(
    force_n: np.ndarray,
    time_s: np.ndarray,
    horn_on_s: tuple[float, float],
    off_n: float,
    on_n: float,
    on_over_time_n: np.ndarray,
) -> np.ndarray:
    """The actuator's force [N] (no offset) under a moving ON level: ``OFF - w (OFF -
    ON(t))`` with ``w = (OFF - force) / (OFF - ON)`` the fraction of the constant-level
    dip ``force_n`` [N] covers from the horn's switch-on (``horn_on_s`` [s]) on (module
    docstring); ``on_over_time_n`` [N] is ``ON(t)`` at ``time_s`` [s]."""
    depth = off_n - on_n
    if depth <= 0.0:  # no reduction: nothing to fade
        return force_n
    # before the switch-on the force is below OFF only in the start-up (and 0 before the
    # pull): no ON dip there, the force is the constant-level one. (Until issue 26's item 4
    # it was OFF there, so the fading benches had no start-up and read OFF before the pull.)
    after = np.asarray(time_s) >= horn_on_s[0]
    covered = (off_n - force_n) / depth
    return np.where(after, off_n - covered * (off_n - on_over_time_n), force_n)


def creep_factor(time_s: np.ndarray, pull_start_s: float, rate_per_s: float) -> np.ndarray:
    """The friction coefficient over its value at the pull's start [-] at ``time_s`` [s]:
    ``1 + r max(t - t_pull, 0)`` with ``r = rate_per_s`` [1/s] (module docstring)."""
    return 1.0 + rate_per_s * np.maximum(np.asarray(time_s, float) - pull_start_s, 0.0)


def with_plateau_drifts(
    params: BenchParams, trace: TraceTruth, time_s: np.ndarray, force_n: np.ndarray
) -> np.ndarray:
    """The noise-free force [N] at ``time_s`` [s] with the trace's fading horn and creeping
    level applied to the constant-level force ``force_n`` [N] (offset included, no drift);
    ``force_n`` itself when neither is on (so the output without them is unchanged)."""
    fading = params.horn_fading.fade_fraction > 0.0 and trace.horn_on_s is not None
    if not fading and trace.level_creep_per_s == 0.0:
        return force_n
    bare = force_n - trace.load_cell_offset_n
    if fading:
        assert trace.horn_on_s is not None
        on_t = on_level_over_time_n(params, trace, time_s)
        bare = faded_force_n(
            bare, time_s, trace.horn_on_s, trace.off_force_n, trace.on_force_n, on_t
        )
    bare = bare * creep_factor(time_s, trace.startup_s, trace.level_creep_per_s)
    return trace.load_cell_offset_n + bare


def on_level_over_time_n(params: BenchParams, trace: TraceTruth, time_s: np.ndarray):
    """The fading horn's ON level [N] at ``time_s`` [s] (no creep, no offset): the
    trace's ON level times ``FR(a(t)) / FR(a0)`` (:mod:`idtool._simulate._plateau_drift`)."""
    fading = params.horn_fading
    assert trace.horn_on_s is not None
    g, ratio = fade_ratio_curve(
        params.contact.law_at(trace.normal_load_n, trace.friction_coefficient),
        trace.pull_speed_m_s,
        params.rig.vibration_frequency_hz,
        trace.slip_amplitude_m,
        fading.fade_fraction,
        trace.normal_load_n,
        params.contact.direction_model,
    )
    factor = fade_factor(time_s, trace.horn_on_s, fading.fade_fraction, fading.fade_time_constant_s)
    # an ON level cannot rise above the OFF level (FR <= 1)
    return np.minimum(trace.on_force_n * np.interp(factor, g, ratio), trace.off_force_n)


def on_force_end_n(params: BenchParams, trace: TraceTruth) -> float | None:
    """The ON level [N] at the horn's switch-off (None without ON): the level at
    switch-on unless the horn fades."""
    if trace.horn_on_s is None:
        return None
    if params.horn_fading.fade_fraction == 0.0:
        return trace.on_force_n
    end = np.array([trace.horn_on_s[1]])
    return float(on_level_over_time_n(params, trace, end)[0])
