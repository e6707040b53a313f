"""Vibration normal to the contact plane (out of plane; issue 30, item 2).

The seed paper's horn vibrates normal to the webbing. This is the quasi-static model of
sliding under normal oscillation with contact stiffness of M. Popov, V. L. Popov and
N. V. Popov, "Reduction of friction by normal oscillations. I. Influence of contact
stiffness", Friction 5(1) 45-55 (2017) (arXiv:1611.07017), flat cylindrical punch, stiff
system; reviewed in M. Popov, "The influence of vibration on friction: a
contact-mechanical perspective", Front. Mech. Eng. 6:69 (2020). Assumptions:

* quasi-static: inertia of the slider and of the contact neglected (the "stiff
  system" of the paper: the contact is the softest part);
* the indentation is imposed, ``d(theta) = d0 + a cos(theta)``, ``theta = w t``, ``a``
  [m] the coupling's amplitude, now normal to the plane; the contact is a flat punch
  of constant normal stiffness ``k_z`` [N/m] and tangential stiffness ``k_x = Kt``
  [N/m] (the law's), so ``N = k_z max(d, 0)``; the mean normal force is the static load,
  ``<N> = N0``, which sets ``d0`` (below ``d0 < a`` the contact is lost for part of each
  period and the slider "jumps");
* Amontons friction with the law's coefficient at the sliding speed,
  ``mu = F_off / N0`` (``F_off = law.off_force_n(v)``): while the tangential spring's
  force is below ``mu N`` the contact sticks and the force grows at ``Kt v``; otherwise
  it slides at ``F = mu N``; out of contact ``F = 0``. The law's own transition (Dahl's
  exponential, LuGre's damping and Stribeck curve) is not used: the spring is
  elastic-perfectly plastic, as in the paper;
* ``k_x / k_z = KAPPA = 2 (1 - nu) / (2 - nu)`` (Mindlin 1949; Johnson, Contact
  Mechanics 1985, §7.2: like elastic bodies), here with ``nu = 0.4`` (a polymer
  webbing): ``KAPPA = 0.75``. KAPPA only rescales the coupling gain a fit identifies:
  FR depends on ``(beta, vt)`` of eq. N1, which ``KAPPA -> s KAPPA`` with ``a -> s a``
  leaves unchanged, so Kt and mu do not depend on it.

Dimensionless (``n = N / N0``, ``f = F / (mu N0)``):

    beta = k_z a / N0 = Kt a / (KAPPA N0),   g = Kt v / (w mu N0) = Lambda VR,
    vt = g / beta = KAPPA VR / mu,                                              (eq. N1)
    n(theta) = beta max(c + cos(theta), 0),   <n> = 1 fixes c = d0 / a:
        c = 1 / beta for beta <= 1, else (c arccos(-c) + sqrt(1 - c^2)) / pi = 1 / beta.   (eq. N2)

``f`` slides down with ``n`` while ``n`` falls, and sticks (``df/dtheta = g``) from
``theta1 = max(theta_c, pi + arcsin(vt))`` (``theta_c = 2 pi - arccos(-c)`` the return of
contact; a stick exists only if ``vt < 1`` and ``theta1 < 2 pi - arcsin(vt)``) until it
meets ``n`` again at ``theta2``: ``n(theta2) = f1 + g (theta2 - theta1)``, ``f1 =
n(theta1)``. With ``<n> = 1`` and ``D = theta2 - theta1``:

    FR = 1 - (1 / 2 pi) [beta c D + beta (sin theta2 - sin theta1) - f1 D - g D^2 / 2]. (eq. N3)

Limits (tests/test_direction.py): ``vt >= 1`` or Coulomb (Kt -> inf): FR = 1 (rigid
Amontons friction is not reduced by a normal oscillation at constant mean load);
``beta <= 1`` (no loss of contact): FR = 1 - beta h(vt), linear in the amplitude, so
FR -> 1 as ``a -> 0``, and FR = 1 - beta at ``vt = 0``; ``beta > 1`` at ``vt = 0``: FR = 0.
``theta2`` and ``c`` are found by bisection, then one Newton step on which the
gradient flows (the implicit function theorem), so the result is differentiable.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

from idtool._model._contact import CycleAverage
from idtool._model._direction import DIRECTIONS, AbstractDirection

__all__ = ["KAPPA", "Normal", "normal_friction_ratio"]

POISSON = 0.4
KAPPA = 2.0 * (1.0 - POISSON) / (2.0 - POISSON)  # k_x / k_z (Mindlin)
_BISECTIONS = 60  # 2^-60 of a bracket of at most 2 pi: below a rounding


def _bisect(fn, lo: Array, hi: Array, increasing: bool) -> Array:
    """A root of ``fn``, monotone on [lo, hi] with a sign change, by bisection, then
    one Newton step from the (gradient-stopped) bisection point: the value is the
    bisection's, the gradient that of the implicit root."""

    def step(_, bounds):
        a, b = bounds
        mid = 0.5 * (a + b)
        below = (fn(mid) < 0.0) == increasing
        return jnp.where(below, mid, a), jnp.where(below, b, mid)

    a, b = jax.lax.fori_loop(0, _BISECTIONS, step, (lo, hi))
    x = jax.lax.stop_gradient(0.5 * (a + b))
    value, slope = jax.jvp(fn, (x,), (jnp.ones_like(x),))
    return x - value / jnp.where(slope != 0.0, slope, 1.0)


def _mean_indentation(beta: Array) -> Array:
    """``c = d0 / a`` for which ``<max(c + cos, 0)> = 1 / beta`` (eq. N2)."""
    loss = beta > 1.0
    b = jnp.where(loss, beta, 2.0)

    def excess(c):
        c = jnp.clip(c, -1.0, 1.0)
        return (c * jnp.arccos(-c) + jnp.sqrt(jnp.maximum(1.0 - c**2, 0.0))) / jnp.pi - 1.0 / b

    lost = _bisect(excess, jnp.asarray(-1.0), jnp.asarray(1.0), increasing=True)
    return jnp.where(loss, lost, 1.0 / jnp.where(loss, 1.0, beta))


def normal_friction_ratio(beta: Float[ArrayLike, ""], vt: Float[ArrayLike, ""]) -> Float[Array, ""]:
    """FR under normal oscillation from ``beta = k_z a / N0`` >= 0 and
    ``vt = Kt v / (w mu k_z a)`` >= 0 (eqs. N1-N3); scalars."""
    beta = jnp.asarray(beta, float)
    vt = jnp.asarray(vt, float)
    moving = beta > 0.0
    beta = jnp.where(moving, beta, 1.0)
    g = vt * beta
    c = _mean_indentation(beta)
    lost = c < 1.0  # contact lost for part of the period
    c_in = jnp.where(lost, c, 0.0)  # keep arccos' infinite slope at -1 out of the grad
    sticks_at_all = vt < 1.0
    vt_in = jnp.where(sticks_at_all, vt, 0.0)
    asin_vt = jnp.arcsin(vt_in)
    theta_c = jnp.where(lost, 2.0 * jnp.pi - jnp.arccos(-c_in), jnp.pi)
    theta1 = jnp.maximum(theta_c, jnp.pi + asin_vt)
    peak = 2.0 * jnp.pi - asin_vt  # where the stuck force grows faster than n after
    stick = sticks_at_all & (theta1 < peak) & moving
    f1 = beta * jnp.maximum(c + jnp.cos(theta1), 0.0)
    end = jnp.where(lost, 2.0 * jnp.pi + jnp.arccos(-c_in), theta1 + 2.0 * jnp.pi)

    def gap(theta):  # n - f while stuck; decreasing on [peak, end]
        return beta * (c + jnp.cos(theta)) - f1 - g * (theta - theta1)

    lo = jnp.where(stick, jnp.maximum(peak, theta1), 0.0)
    hi = jnp.where(stick, end, 1.0)
    theta2 = _bisect(lambda t: jnp.where(stick, gap(t), 0.5 - t), lo, hi, increasing=False)
    d = theta2 - theta1
    loss = beta * c * d + beta * (jnp.sin(theta2) - jnp.sin(theta1)) - f1 * d - 0.5 * g * d**2
    return jnp.where(stick, 1.0 - loss / (2.0 * jnp.pi), 1.0)


@DIRECTIONS.register("normal")
class Normal(AbstractDirection):
    """Out-of-plane vibration of the indentation (module docstring, eqs. N1-N3)."""

    description = "vibration normal to the contact plane (Popov et al. 2017)"

    @classmethod
    def cycle_average(
        cls, law, sliding_speed_m_s, amplitude_m, angular_frequency_rad_s, normal_load_n
    ):
        v = jnp.asarray(sliding_speed_m_s, float)
        a = jnp.asarray(amplitude_m, float)
        w = jnp.asarray(angular_frequency_rad_s, float)
        n0 = jnp.asarray(normal_load_n, float)
        off = law.off_force_n(v)
        kt = law.stiffness_n_m()
        rigid = jnp.isinf(kt)
        beta = jnp.where(rigid, 1.0, kt) * a / (KAPPA * n0)
        vibrating = a > 0.0
        a_safe = jnp.where(vibrating, a, 1.0)
        vr = jnp.where(vibrating, v / (a_safe * w), jnp.inf)
        vt = KAPPA * v * n0 / (w * a_safe * off)
        fr = jnp.where(rigid | ~vibrating, 1.0, normal_friction_ratio(beta, vt))
        mean_force = fr * off
        zero = jnp.zeros_like(fr)
        return CycleAverage(
            velocity_ratio=vr,
            friction_ratio=fr,
            # quasi-static: the pull's work is all dissipated, the springs' energy is
            # periodic and the normal force does no tangential work
            power_ratio=fr,
            input_power_ratio=zero,
            mean_friction_n=mean_force,
            off_friction_n=off,
            mean_power_w=mean_force * v,
            off_power_w=off * v,
            harmonic_cos_n=zero,
            harmonic_sin_n=zero,
        )
