"""The bench model: what a load cell records on the paper's rig (Section 2, notes §5).

Two time scales. The 20 kHz vibration is far faster than a trace (seconds), so the
friction level with ultrasound ON is the cycle-averaged steady state of the contact
model at the trace's operating point (:func:`on_friction_ratio`), while the trace
itself follows the pneumatic actuator (:func:`mean_force_n`):

* before the pull, the load cell reads its offset; the pull starts at ``startup_s`` and
  the force rises at ``startup_slope_n_s`` to the OFF level ``F_off = mu N``;
* when the horn switches ON the force falls towards ``F_on = FR F_off`` at the
  actuator-limited slope ``slope_n_s`` and, after OFF, rises back at the same slope
  (paper Section 2.2.1); a short ON window ends before ``F_on`` is reached (Figure 2);
* corners are rounded over ``corner_n`` [N] (hyperbolic smooth min/max) so the model is
  differentiable in every parameter.

Everything here is pure JAX: the simulator adds noise on top of it, the fit differentiates
through it.
"""

from __future__ import annotations

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

from idtool._model._coupling import AbstractCoupling
from idtool._model._directions import AbstractDirection, Along
from idtool._model._laws import AbstractFrictionLaw, Dahl

__all__ = [
    "TraceTiming",
    "dahl_at_load",
    "mean_force_n",
    "on_contact",
    "on_friction_ratio",
    "smooth_max",
    "smooth_min",
]


def smooth_min(a: ArrayLike, b: ArrayLike, width: ArrayLike) -> Array:
    """``min(a, b)`` with its corner rounded over ``width`` (same unit as a, b); > 0."""
    a, b = jnp.asarray(a), jnp.asarray(b)
    return 0.5 * (a + b - jnp.sqrt((a - b) ** 2 + jnp.asarray(width) ** 2))


def smooth_max(a: ArrayLike, b: ArrayLike, width: ArrayLike) -> Array:
    """``max(a, b)`` with its corner rounded over ``width``; > 0."""
    a, b = jnp.asarray(a), jnp.asarray(b)
    return 0.5 * (a + b + jnp.sqrt((a - b) ** 2 + jnp.asarray(width) ** 2))


def on_friction_ratio(
    law: AbstractFrictionLaw,
    coupling: AbstractCoupling,
    normal_load_n: Float[ArrayLike, ""],
    amplitude_fraction: Float[ArrayLike, ""],
    pull_speed_m_s: Float[ArrayLike, ""],
    vibration_frequency_hz: Float[ArrayLike, ""],
    max_amplitude_m: Float[ArrayLike, ""],
    direction: type[AbstractDirection] = Along,
) -> Float[Array, ""]:
    """Friction ratio FR = F_on / F_off at one operating point (notes §3, §5).

    ``law`` must already carry ``Fc = mu N`` for this load (see :func:`dahl_at_load`);
    ``direction``: of the vibration (:data:`idtool.DIRECTIONS`; along the sliding by
    default).
    """
    return on_contact(
        law,
        coupling,
        normal_load_n,
        amplitude_fraction,
        pull_speed_m_s,
        vibration_frequency_hz,
        max_amplitude_m,
        direction,
    )[0]


def on_contact(
    law: AbstractFrictionLaw,
    coupling: AbstractCoupling,
    normal_load_n: Float[ArrayLike, ""],
    amplitude_fraction: Float[ArrayLike, ""],
    pull_speed_m_s: Float[ArrayLike, ""],
    vibration_frequency_hz: Float[ArrayLike, ""],
    max_amplitude_m: Float[ArrayLike, ""],
    direction: type[AbstractDirection] = Along,
) -> tuple[Float[Array, ""], Float[Array, ""]]:
    """:func:`on_friction_ratio` and the vibration amplitude [m] it is taken at."""
    w = 2.0 * jnp.pi * jnp.asarray(vibration_frequency_hz)
    a = coupling.slip_amplitude_m(
        law, amplitude_fraction, normal_load_n, pull_speed_m_s, w, max_amplitude_m
    )
    cycle = direction.cycle_average(law, pull_speed_m_s, a, w, normal_load_n)
    return cycle.friction_ratio, a


def dahl_at_load(
    friction_coefficient: Float[ArrayLike, ""],
    contact_stiffness_n_m: Float[ArrayLike, ""],
    normal_load_n: Float[ArrayLike, ""],
) -> Dahl:
    """The Dahl law of a contact with coefficient mu and stiffness Kt under load N."""
    return Dahl(
        fc_n=jnp.asarray(friction_coefficient) * normal_load_n, kt_n_m=contact_stiffness_n_m
    )


class TraceTiming(eqx.Module):
    """When things happen in one trace [s]; ``on_start_s = on_end_s = inf`` for no ON."""

    startup_s: Float[ArrayLike, ""]
    on_start_s: Float[ArrayLike, ""]
    on_end_s: Float[ArrayLike, ""]


def mean_force_n(
    time_s: Float[ArrayLike, " n"],
    off_force_n: Float[ArrayLike, ""],
    on_force_n: Float[ArrayLike, ""],
    timing: TraceTiming,
    slope_n_s: Float[ArrayLike, ""],
    startup_slope_n_s: Float[ArrayLike, ""],
    offset_n: Float[ArrayLike, ""] = 0.0,
    corner_n: Float[ArrayLike, ""] = 0.5,
) -> Float[Array, " n"]:
    """Noise-free load-cell force [N] at ``time_s`` (bench model, module docstring)."""
    t = jnp.asarray(time_s, float)
    f_off = jnp.asarray(off_force_n, float)
    depth = f_off - on_force_n  # > 0 when ultrasound lowers friction
    since_start = smooth_max(t - timing.startup_s, 0.0, corner_n / startup_slope_n_s)
    rise = smooth_min(startup_slope_n_s * since_start, f_off, corner_n)

    # Elementwise in t and every parameter (they broadcast), so a whole dataset can be
    # evaluated in one call; an infinite ON start means no ON window at all.
    has_on = jnp.isfinite(timing.on_start_s) & jnp.isfinite(timing.on_end_s)
    t_on = jnp.where(has_on, timing.on_start_s, 0.0)
    on_len = jnp.where(has_on, jnp.asarray(timing.on_end_s) - t_on, 0.0)
    during = smooth_max(slope_n_s * (t - t_on), 0.0, corner_n)
    drop_on = smooth_min(during, depth, corner_n)
    drop_end = smooth_min(slope_n_s * on_len, depth, corner_n)
    drop_after = smooth_max(drop_end - slope_n_s * (t - t_on - on_len), 0.0, corner_n)
    # The switch OFF is a corner too: the drop stops deepening and starts recovering, so
    # the drop is the smaller of the two branches (they cross at t_on + on_len only). A
    # plain switch between them left a corner in time at the OFF switch, and so a kink
    # in the loss each time it crosses a sub-sample as the OFF delay moves, which no
    # Levenberg-Marquardt step can settle on. Rounded over ``corner_n`` like the other
    # corners, with the rounding's width fading within a few ``corner_n / slope_n_s``
    # of the corner, so that far from it each branch is exact (a constant width would
    # leave a tail of corner_n^2 / (4 depth) on the whole recovered level).
    near = slope_n_s * (t - t_on - on_len) / corner_n
    # (a floor of 1e-6 of the width keeps the square root's derivative finite)
    fade = jnp.exp(-0.25 * near**2) + 1e-6
    drop = smooth_min(drop_on, drop_after, corner_n * fade)
    drop = jnp.where(has_on, drop, 0.0)
    return jnp.asarray(offset_n) + rise - drop
