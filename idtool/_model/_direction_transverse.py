"""Vibration in the contact plane, perpendicular to the sliding (issue 30, item 2).

The contact slides at ``v`` along x and vibrates along y, in the plane of contact:

    V(theta) = (v, a w cos(theta)),   theta = w t,   VR = xi = v / (a w)        (eq. T1)

Friction is isotropic: it acts against the slip *velocity vector*. The bristle state is
the 2-D deflection vector ``z`` [m] of the isotropic Dahl / LuGre model (the 2-D LuGre
of Velenis, Tsiotras, Canudas-de-Wit & Sorine, Veh. Syst. Dyn. 43(1) 3-29, 2005, eq. 9,
with equal stiffness in every direction; its Dahl case is the isotropic Dahl model):

    dz/dt = V - |V| z / g(|V|),   F = Kt z + s1 dz/dt + s2 V,                    (eq. T2)

``g = L / Kt`` with ``L(|V|)`` the law's level (:meth:`AbstractFrictionLaw.level_n`:
``Fc`` for Dahl, the Stribeck curve for LuGre). On the bristle force ``fb = Kt z`` [N]
and the arc length ``s`` of the slip path (``ds = |V| dt``, unit direction
``e = V / |V|``) it is linear, as the 1-D law is (:mod:`idtool._model._laws`):

    d fb / ds = Kt (e - fb / L).                                                 (eq. T3)

With ``e`` and ``L`` held at a step's midpoint, a step of arc length ``ds`` is the
exact affine map ``fb <- L e + (fb - L e) exp(-kappa)``, ``kappa = Kt ds / L``, the
decay a scalar: stable however stiff the contact. The periodic state is the fixed point
of the composed map. The slip velocity never vanishes (v > 0): there is no reversal to
split at, but the direction turns fast near ``cos(theta) = 0`` when xi is small (over a
phase of about 2 xi). The grid is uniform in a variable ``phi`` mapped onto the phase by
the periodic conformal map ``tan(chi / 2) = r tan(psi / 2)`` (``theta = pi/2 + chi/2``,
``psi = 2 phi - pi``, ``r = sqrt(xi / (1 + xi))``), which packs the steps there
(their size shrinks by ``r``). The state's symmetry ``fb(theta + pi) = M fb(theta)``,
``M = diag(1, -1)`` (the velocity is mirrored), lets the grid cover half a period.

Coulomb (``Kt -> inf``, ``fb = Fc e``) has the closed form (model notes §4)

    FR = <xi / sqrt(xi^2 + cos^2 theta)> = (2/pi) xi / sqrt(1 + xi^2) K(1 / (1 + xi^2))   (eq. T4)

with K the complete elliptic integral of the first kind of *parameter* m
(``scipy.special.ellipk(m)``'s convention;
:func:`idtool._model._limits.coulomb_perpendicular_friction_ratio` in JAX, by the
arithmetic-geometric mean); the grid's sum is the midpoint rule of a
periodic analytic function, which converges geometrically: within 1e-12 of eq. T4 for
xi >= 0.01 at the default ``n_phase`` (tests/test_direction.py). Unlike the along
direction, FR < 1 at every xi: a transverse vibration always tilts the slip velocity.
For Dahl and LuGre the scheme is second order in the step; tests/test_direction.py
compares it with LSODA time marching of eq. T2.
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

from idtool._model import _trig as trig
from idtool._model._contact import CycleAverage
from idtool._model._direction import DIRECTIONS, AbstractDirection
from idtool._model._laws import AbstractFrictionLaw

__all__ = ["N_PHASE_TRANSVERSE", "Transverse", "transverse_cycle_average"]

# Steps over half a period. The Dahl friction ratio's error is second order in the step:
# at 256 it is below 6e-6 over Lambda 0.3-100 and xi 0.02-2 (2e-6 at Lambda 3, xi 0.2;
# against 2048 steps and LSODA, tests/test_direction.py), Coulomb's below 1e-12 for
# xi >= 0.01 (the grid's geometric convergence).
N_PHASE_TRANSVERSE = 256


def _phase_map(phi: Array, r: Array) -> tuple[Array, Array]:
    """``theta(phi)`` and ``d theta / d phi`` of the grid map (module docstring), phi in
    [0, pi): ``psi = 2 phi - pi``, ``chi = psi - 2 atan2((1-r) sin psi, (1+r) + (1-r)
    cos psi)`` solves ``tan(chi/2) = r tan(psi/2)`` on one branch; ``theta = pi/2 +
    chi/2``, its derivative ``2 r / ((1 + r^2) + (1 - r^2) cos psi)``."""
    psi = 2.0 * phi - jnp.pi
    cos_psi, sin_psi = trig.cos(psi), trig.sin(psi)
    chi = psi - 2.0 * jnp.arctan2((1.0 - r) * sin_psi, (1.0 + r) + (1.0 - r) * cos_psi)
    slope = 2.0 * r / ((1.0 + r**2) + (1.0 - r**2) * cos_psi)
    return 0.5 * jnp.pi + 0.5 * chi, slope


def _compose(prefix, step):
    """Affine maps ``fb -> A fb + B`` (A scalar, B a 2-vector), extended by one step."""
    a1, b1 = prefix
    a2, b2 = step
    out = (a2 * a1, a2 * b1 + b2)
    return out, out


def _fb_start(kappa: Array, decay: Array, offset: Array) -> Array:
    """Bristle force (2, n) [N] at each step start in the periodic state.

    ``fb(pi) = M fb(0)`` with ``M = diag(1, -1)``: with the half period's composed map
    ``fb(pi) = A fb(0) + B``, ``fb_x(0) = B_x / (1 - A)`` and ``fb_y(0) = -B_y / (1 + A)``.
    """
    _, (prefix_a, prefix_b) = jax.lax.scan(_compose, (1.0, jnp.zeros(2)), (decay, offset.T))
    one_minus_a = -jnp.expm1(-jnp.sum(kappa))
    fb0 = jnp.stack(
        [
            prefix_b[-1, 0] / jnp.where(one_minus_a > 0.0, one_minus_a, 1.0),
            -prefix_b[-1, 1] / (1.0 + prefix_a[-1]),
        ]
    )
    rest = prefix_a[:-1, None] * fb0 + prefix_b[:-1]
    return jnp.concatenate([fb0[None], rest]).T


def _phi1(kappa: Array) -> Array:
    """``(1 - exp(-kappa)) / kappa``, the mean of ``exp(-kappa x)`` over x in [0, 1];
    1 at kappa = 0, 0 at kappa = inf."""
    small = kappa < 1e-4
    k = jnp.where(small, 1.0, kappa)
    return jnp.where(small, 1.0 - kappa / 2.0 + kappa**2 / 6.0, -jnp.expm1(-k) / k)


@functools.partial(jax.jit, static_argnames=("n_phase",))
def transverse_cycle_average(
    law: AbstractFrictionLaw,
    sliding_speed_m_s: Float[ArrayLike, ""],
    amplitude_m: Float[ArrayLike, ""],
    angular_frequency_rad_s: Float[ArrayLike, ""],
    n_phase: int = N_PHASE_TRANSVERSE,
) -> CycleAverage:
    """Steady cycle averages for slip velocity ``(v, a w cos(w t))`` under ``law``.

    Args:
        law: a :class:`Coulomb`, :class:`Dahl` or :class:`LuGre` instance.
        sliding_speed_m_s: sliding speed v > 0 [m/s].
        amplitude_m: transverse vibration amplitude a >= 0 [m]; a = 0 gives FR = 1.
        angular_frequency_rad_s: vibration angular frequency w > 0 [rad/s].
        n_phase: steps over half a period (static).

    Returns:
        A :class:`CycleAverage`: the mean friction along the sliding (x), its power
        ``<F . V>`` (both components), and ``harmonic_cos_n`` / ``harmonic_sin_n``, the
        first harmonic of the friction's component along the vibration (y).
    """
    v = jnp.asarray(sliding_speed_m_s, float)
    a = jnp.asarray(amplitude_m, float)
    w = jnp.asarray(angular_frequency_rad_s, float)
    vibrating = a > 0.0
    a_safe = jnp.where(vibrating, a, 1.0)
    vr = jnp.where(vibrating, v / (a_safe * w), jnp.inf)
    r = jnp.where(vibrating, jnp.sqrt(v / (v + a_safe * w)), 1.0)  # sqrt(xi / (1 + xi))

    dphi = jnp.pi / n_phase
    theta, slope = _phase_map(dphi * (jnp.arange(n_phase) + 0.5), r)
    dtheta = slope * dphi  # phase per step [rad]
    cos_t, sin_t = trig.cos(theta), trig.sin(theta)
    vel = jnp.stack([jnp.broadcast_to(v, theta.shape), a * w * cos_t])  # (2, n) [m/s]
    speed = jnp.sqrt(v**2 + vel[1] ** 2)
    level = law.level_n(speed)
    kappa = law.decay_exponent(speed * dtheta / w, level)
    decay = jnp.exp(-kappa)
    target = level * vel / speed  # L e [N]
    fb_start = _fb_start(kappa, decay, (1.0 - decay) * target)
    # Exact mean of fb over each step's arc length; its phase mean to second order.
    step_mean = target + (fb_start - target) * _phi1(kappa)

    s1 = law.bristle_damping_n_s_m()
    s2 = law.viscous_n_s_m()
    zdot = vel - speed * step_mean / level  # dz/dt [m/s], eq. T2
    half = lambda x: jnp.sum(x * dtheta) / jnp.pi  # noqa: E731  mean over a period
    mean_force = half(step_mean[0]) + s2 * v  # <s1 dz/dt> = 0 over a period
    mean_power = (
        half(jnp.sum(step_mean * vel, axis=0))
        + s1 * half(jnp.sum(zdot * vel, axis=0))
        + s2 * (v**2 + 0.5 * (a * w) ** 2)
    )
    force_y = step_mean[1] + s1 * zdot[1] + s2 * vel[1]
    # (1/pi) int_0^{2 pi} F_y cos = (2/pi) int_0^pi: F_y cos is pi-periodic (mirror)
    harmonic_cos = 2.0 * half(force_y * cos_t)
    harmonic_sin = 2.0 * half(force_y * sin_t)

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


@DIRECTIONS.register("transverse")
class Transverse(AbstractDirection):
    """In-plane vibration perpendicular to the sliding: :func:`transverse_cycle_average`
    at its default ``n_phase`` (module docstring, eqs. T1-T4)."""

    description = "in-plane vibration perpendicular to the sliding"

    @classmethod
    def cycle_average(
        cls, law, sliding_speed_m_s, amplitude_m, angular_frequency_rad_s, normal_load_n
    ):
        del normal_load_n
        return transverse_cycle_average(
            law, sliding_speed_m_s, amplitude_m, angular_frequency_rad_s
        )
