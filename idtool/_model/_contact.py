"""Prescribed-vibration contact: cycle-averaged steady state (model notes §3-4).

The slip of the contact is imposed: sliding at speed ``v`` plus a sinusoid of
amplitude ``a`` and angular frequency ``w``,

    u(theta) = (v / w) theta + a sin(theta),   theta = w t,
    V = du/dt = v + a w cos(theta),            VR = v / (a w).

For VR < 1 the slip reverses at ``cos(theta) = -VR``. The cycle is split at the two
reversals into a backward and a forward stretch, each cut into ``n_phase`` steps, so no
step straddles a sign change. Along each step the bristle force obeys the exact affine
slip update of :mod:`idtool._model._laws` (exact for Dahl and Coulomb, second order in the step
for LuGre, whose level L(V) is taken at the step's midpoint velocity). The periodic
steady state is the fixed point of the composed one-cycle affine map, so no transient
has to be integrated away, and every output is smooth in the parameters (the grid moves
with VR), so JAX gradients are well defined.

Averages use the exact mean of the exponential over each step (``phi1`` below), which
stays accurate however stiff the contact (large Lambda) is. The sines and cosines with an
element per phase step are :mod:`idtool._model._trig`'s polynomials: XLA:CPU's own took
half this kernel's time.
"""

from __future__ import annotations

import functools
from collections.abc import Callable

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

from idtool._model import _trig as trig
from idtool._model._laws import AbstractFrictionLaw

__all__ = ["CycleAverage", "cycle_average_curve", "prescribed_cycle_average", "reversal_phase"]

_TWO_PI = 2.0 * jnp.pi


class CycleAverage(eqx.Module):
    """Cycle-averaged steady state of a vibrated sliding contact (notes §3).

    Attributes:
        velocity_ratio: VR = v / (a w) (eq. 10).
        friction_ratio: FR = mean friction ON / friction OFF (eq. 8).
        power_ratio: PDR = mean friction power ON / friction power OFF (eq. 9).
        input_power_ratio: phi_iu, power fed in by the vibration over the OFF friction
            power; PDR = FR + phi_iu (for a prescribed slip nothing is stored over a cycle).
        mean_friction_n: mean friction force ON [N].
        off_friction_n: friction force in steady sliding at v without vibration [N].
        mean_power_w: mean friction power ON [W].
        off_power_w: friction power OFF, ``off_friction_n * v`` [W].
        harmonic_cos_n, harmonic_sin_n: first Fourier coefficients of the friction force
            against the phase, ``F ~ F0 + Fc1 cos(theta) + Fs1 sin(theta)`` [N]
            (``Fc1 = (1/pi) int F cos(theta) dtheta``): the force the contact returns on
            the vibrating body at its own frequency, which loads the transducer in
            :mod:`idtool._model._coupling_sdof` (``Fs1`` elastic, ``Fc1`` dissipative).
    """

    velocity_ratio: Float[Array, "*b"]
    friction_ratio: Float[Array, "*b"]
    power_ratio: Float[Array, "*b"]
    input_power_ratio: Float[Array, "*b"]
    mean_friction_n: Float[Array, "*b"]
    off_friction_n: Float[Array, "*b"]
    mean_power_w: Float[Array, "*b"]
    off_power_w: Float[Array, "*b"]
    harmonic_cos_n: Float[Array, "*b"]
    harmonic_sin_n: Float[Array, "*b"]


def _phi1(kappa: Array) -> Array:
    """``(1 - exp(-kappa)) / kappa``: mean of ``exp(-kappa x)`` over x in [0, 1].

    Safe at kappa = 0 (value 1, by its series) and kappa = inf (value 0, Coulomb).
    """
    small = kappa < 1e-4
    k = jnp.where(small, 1.0, kappa)
    return jnp.where(small, 1.0 - kappa / 2.0 + kappa**2 / 6.0, -jnp.expm1(-k) / k)


def _compose_step(prefix, step):
    """Affine maps ``fb -> A fb + B``: extend the composed ``prefix`` by one ``step``."""
    a1, b1 = prefix
    a2, b2 = step
    out = (a2 * a1, a2 * b1 + b2)
    return out, out


def reversal_phase(velocity_ratio: Float[ArrayLike, ""]) -> Float[Array, ""]:
    """Phase theta_a in [pi/2, pi] where the slip turns backward, ``cos = -VR``.

    Returns pi (no backward stretch) for VR >= 1; gradient-safe at VR = 1.
    """
    vr = jnp.asarray(velocity_ratio, float)
    below = vr < 1.0
    vr_in = jnp.where(below, vr, 0.0)  # keep arccos' infinite slope out of the grad
    return jnp.where(below, jnp.arccos(-vr_in), jnp.pi)


# jax.jit, not eqx.filter_jit: Python floats in the law are traced, not baked in,
# so a new parameter value does not recompile.
@functools.partial(jax.jit, static_argnames=("n_phase",))
def prescribed_cycle_average(
    law: AbstractFrictionLaw,
    sliding_speed_m_s: Float[ArrayLike, ""],
    amplitude_m: Float[ArrayLike, ""],
    angular_frequency_rad_s: Float[ArrayLike, ""],
    n_phase: int = 256,
) -> CycleAverage:
    """Steady cycle averages for slip ``u = v t + a sin(w t)`` under ``law``.

    Args:
        law: a :class:`Coulomb`, :class:`Dahl` or :class:`LuGre` instance.
        sliding_speed_m_s: macroscopic sliding speed v > 0 [m/s].
        amplitude_m: vibration (slip) amplitude a >= 0 [m]; a = 0 gives FR = 1.
        angular_frequency_rad_s: vibration angular frequency w > 0 [rad/s].
        n_phase: steps per stretch between reversals (static). The error is second
            order in the step: at 256 it is about 1e-5 in FR for Lambda 3-10 and 4e-5 at
            Lambda 100 (tests/test_contact.py), below any bench data's resolution.

    Returns:
        A :class:`CycleAverage`. Scalar inputs only: use ``jax.vmap`` for sweeps.
    """
    v = jnp.asarray(sliding_speed_m_s, float)
    a = jnp.asarray(amplitude_m, float)
    w = jnp.asarray(angular_frequency_rad_s, float)
    vibrating = a > 0.0
    a_safe = jnp.where(vibrating, a, 1.0)
    vr = jnp.where(vibrating, v / (a_safe * w), jnp.inf)

    # Phase grid, one row per stretch: backward [theta_a, 2 pi - theta_a], then forward
    # [2 pi - theta_a, 2 pi + theta_a], each cut into n_phase steps. For VR >= 1 the
    # backward one has zero length. Everything below is (2, n_phase) elementwise work
    # and a few sums, which XLA compiles into a handful of loops (compile time is most
    # of the time to a first result).
    theta_a = reversal_phase(vr)
    start = jnp.stack([theta_a, _TWO_PI - theta_a])[:, None]
    length = jnp.stack([_TWO_PI - 2.0 * theta_a, 2.0 * theta_a])[:, None]
    sign = jnp.array([[-1.0], [1.0]])
    dtheta = length / n_phase
    th0 = start + dtheta * jnp.arange(n_phase)  # step starts
    mid = th0 + 0.5 * dtheta
    slide_m = v / w  # slip per radian from the sliding alone [m]
    du = _slip_m(slide_m, a, th0, dtheta, sin=jnp.sin)  # dtheta: one per stretch
    du_abs = jnp.maximum(sign * du, 0.0)  # round-off can flip sign at a reversal
    v_mid = v + a * w * jnp.cos(mid)  # used by the velocity-dependent laws only
    level = law.level_n(v_mid)
    kappa = law.decay_exponent(du_abs, level)
    target = sign * level

    if law.constant_level:
        # Exact over a whole stretch: each step start follows in closed form from the
        # stretch start and the slip since (see _fb_start_constant_level).
        fb_level = law.level_n(v)
        k_since = law.decay_exponent(
            jnp.maximum(sign * _slip_m(slide_m, a, start, th0 - start), 0.0), fb_level
        )
        k_stretch = law.decay_exponent(
            jnp.maximum(sign * _slip_m(slide_m, a, start, length, jnp.cos, jnp.sin), 0.0), fb_level
        )
        fb_start = _fb_start_constant_level(fb_level, sign, k_since, k_stretch)
    else:
        decay = jnp.exp(-kappa)
        fb_start = _fb_start_composed(kappa, decay, (1.0 - decay) * target)

    # Exact mean of fb over each step's slip; its phase mean to second order.
    step_mean = target + (fb_start - target) * _phi1(kappa)
    mean_fb = jnp.sum(step_mean * dtheta) / _TWO_PI
    fb_power = w * jnp.sum(step_mean * du) / _TWO_PI

    s1 = law.bristle_damping_n_s_m()
    s2 = law.viscous_n_s_m()
    zdot_factor = 1.0 - sign * step_mean / level  # dz/dt = V (1 - s fb / L)
    s1_power = s1 * jnp.sum(v_mid**2 * zdot_factor * dtheta) / _TWO_PI
    s2_power = s2 * (v**2 + 0.5 * (a * w) ** 2)

    # First harmonic: the step mean (over the slip, its phase mean to second order) times
    # the exact integral of cos / sin over the step; s1 dz/dt at the step midpoint.
    th1 = th0 + dtheta
    s1_force = s1 * v_mid * zdot_factor
    harmonic_cos = (
        jnp.sum(step_mean * (jnp.sin(th1) - jnp.sin(th0)) + s1_force * jnp.cos(mid) * dtheta)
        / jnp.pi
        + s2 * a * w
    )
    harmonic_sin = (
        jnp.sum(step_mean * (jnp.cos(th0) - jnp.cos(th1)) + s1_force * jnp.sin(mid) * dtheta)
        / jnp.pi
    )

    mean_force = mean_fb + s2 * v  # mean of s1 dz/dt over a period is zero
    mean_power = fb_power + s1_power + s2_power
    off_force = law.off_force_n(v)
    off_power = off_force * v
    return CycleAverage(
        velocity_ratio=vr,
        friction_ratio=mean_force / off_force,
        power_ratio=mean_power / off_power,
        input_power_ratio=(mean_power - mean_force * v) / off_power,
        mean_friction_n=mean_force,
        off_friction_n=off_force,
        mean_power_w=mean_power,
        off_power_w=off_power,
        harmonic_cos_n=harmonic_cos,
        harmonic_sin_n=harmonic_sin,
    )


def _slip_m(
    slide_m: Array,
    a: Array,
    theta0: Array,
    dtheta: Array,
    cos: Callable[[Array], Array] = trig.cos,
    sin: Callable[[Array], Array] = trig.sin,
) -> Array:
    """Slip ``u(theta0 + dtheta) - u(theta0)`` [m], ``u = slide_m theta + a sin(theta)``.

    The sine difference is written as a product to avoid cancellation for small steps.
    ``cos`` and ``sin``: :mod:`idtool._model._trig`'s polynomials where the argument has
    an element per phase step (the kernel's time); XLA's own where it has one per
    stretch, where each polynomial would only add to the program JAX traces and XLA
    compiles (a polynomial in place of every sine and cosine of the kernel made a cold
    fit of the example trace 1.4 s and compile 2-3 s longer).
    """
    return slide_m * dtheta + 2.0 * a * cos(theta0 + 0.5 * dtheta) * sin(0.5 * dtheta)


def _fb_start_composed(kappa: Array, decay: Array, offset: Array) -> Array:
    """Bristle force [N] at each step start in the periodic state, any law.

    ``kappa``, ``decay`` and ``offset`` are (2, n) per-step exponents and affine maps
    ``fb -> decay fb + offset``. The periodic state is the fixed point of their
    composition over a cycle, composed in sequence. A sequential scan, not
    jax.lax.associative_scan: same result, but it compiles several times faster.
    """
    shape = kappa.shape
    _, (prefix_a, prefix_b) = jax.lax.scan(
        _compose_step, (1.0, 0.0), (decay.reshape(-1), offset.reshape(-1))
    )
    one_minus_a = -jnp.expm1(-jnp.sum(kappa))
    fb0 = prefix_b[-1] / jnp.where(one_minus_a > 0.0, one_minus_a, 1.0)
    fb = jnp.concatenate([fb0[None], prefix_a[:-1] * fb0 + prefix_b[:-1]])
    return fb.reshape(shape)


def _fb_start_constant_level(
    level_n: Array, sign: Array, k_since: Array, k_stretch: Array
) -> Array:
    """Bristle force [N] at each step start in the periodic state, constant level L [N].

    With L fixed (Coulomb, Dahl) the update ``fb <- s L + (fb - s L) exp(-Kt |du| / L)``
    is exact over a whole stretch of one sign (notes §4), so every step start follows in
    closed form from its stretch's start value and the decay exponent ``k_since``
    (2, n) of the slip since then; the periodic state is the fixed point of the
    backward-then-forward pair of stretch maps, whose exponents are ``k_stretch``
    (2, 1). Same values as :func:`_fb_start_composed` to round-off, but elementwise: no
    sequential scan to compile.
    """
    e_back, e_fwd = jnp.exp(-k_stretch[0, 0]), jnp.exp(-k_stretch[1, 0])
    # fb_b, at the start of the backward stretch, is the fixed point of
    # fb_b = L + (fb_f - L) e_fwd with fb_f = -L + (fb_b + L) e_back.
    one_minus = -jnp.expm1(-(k_stretch[0, 0] + k_stretch[1, 0]))
    fb_back = level_n * (1.0 - 2.0 * e_fwd + e_back * e_fwd)
    fb_back = fb_back / jnp.where(one_minus > 0.0, one_minus, 1.0)
    fb_fwd = -level_n + (fb_back + level_n) * e_back
    stretch_start = jnp.stack([fb_back, fb_fwd])[:, None]
    target = sign * level_n
    return target + (stretch_start - target) * jnp.exp(-k_since)


# The curve is cheap to run (a few milliseconds for 41 points) but costs a few tenths
# of a second to compile, so the time to a first result is mostly compilation. These
# XLA options cut the compile time from 0.18 s to 0.06 s (benchmarks/bench_curve.py):
# backend optimisation level 0, the classic loop emitters instead of the newer fusion
# emitters, and no expensive LLVM passes. The run time about doubles (1.5 to 3 ms for
# 41 points), a good trade for a function called once per command.
QUICK_COMPILE = {
    "xla_backend_optimization_level": 0,
    "xla_cpu_use_fusion_emitters": False,
    "xla_llvm_disable_expensive_passes": True,
}


@functools.partial(jax.jit, static_argnames=("n_phase",), compiler_options=QUICK_COMPILE)
def cycle_average_curve(
    law: AbstractFrictionLaw,
    velocity_ratios: Float[ArrayLike, " n"],
    amplitude_m: Float[ArrayLike, ""] = 1.0,
    angular_frequency_rad_s: Float[ArrayLike, ""] = 1.0,
    n_phase: int = 256,
) -> CycleAverage:
    """:func:`prescribed_cycle_average` at many velocity ratios (``v = VR a w``).

    With the defaults ``a = w = 1`` and a law with ``Fc = 1``, ``Kt`` is Lambda.
    """
    vr = jnp.asarray(velocity_ratios, float)
    speeds = vr * amplitude_m * angular_frequency_rad_s
    return jax.vmap(
        lambda v: prescribed_cycle_average(law, v, amplitude_m, angular_frequency_rad_s, n_phase)
    )(speeds)
