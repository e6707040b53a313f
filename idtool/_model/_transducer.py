"""The paper's single-degree-of-freedom ultrasonic transducer (eqs. 6-7, notes §2).

    m x'' + c x' + Ks x = Fe cos(w t) + F_D,        V = Vt - x',
    dF_D/dt = Kt V (1 - sgn(V) F_D / Fc),            Fc = mu m g.

The counter-surface slides at Vt; F_D follows the sign of the relative velocity V, so
it drags the mass along and opposes the relative motion (the paper writes ``-F_D`` with
the opposite sign convention for V; notes §2). ``c = 2 zeta sqrt(Ks m)`` is optional
structural damping; the paper has none (``zeta = 0``, the default of :func:`table2`).

Integration. Dahl is exactly solvable along the slip (notes §4): between reversals of V,
``F_D = s Fc + (F_a - s Fc) exp(-Kt s (u - u_a) / Fc)`` with ``u`` the slip since the last
reversal ("anchor") and ``s`` its sign. So the integrator carries ``(x, x', u)``, whose
right-hand side is smooth between reversals, takes classical RK4 steps on it, and splits
every step at a reversal: the crossing time is found from the cubic Hermite interpolant
of V (Newton), the step is redone in two parts and the anchor is moved. No sgn is ever
evaluated inside an RK4 stage, so the scheme keeps fourth order through the switching,
and the friction state is exact however stiff the contact.

Steady state. Without damping the free oscillation at ``sqrt(Ks/m)`` never decays (the
paper notes its signals are not pure sinusoids for that reason), so a time window average
depends on the window. :func:`transducer_steady_state` instead finds the periodic orbit
at the forcing period by Newton shooting, which is well defined with or
without damping; :func:`simulate_transducer` marches from rest as the paper did.
"""

from __future__ import annotations

import dataclasses
import functools

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

__all__ = [
    "EnergyBalance",
    "Transducer",
    "TransducerSteadyState",
    "simulate_transducer",
    "table2",
    "transducer_steady_state",
]

# Quadrature channels integrated alongside the motion: int F dt, int F V dt,
# int Fe cos(wt) x' dt, int c x'^2 dt.
_NQ = 4


class Transducer(eqx.Module):
    """Parameters of the SDOF transducer (paper Table 2 for :func:`table2`).

    Attributes:
        mass_kg: sliding mass m [kg].
        stiffness_n_m: system stiffness Ks [N/m].
        angular_frequency_rad_s: excitation frequency w [rad/s].
        force_amplitude_n: piezo control force amplitude Fe [N].
        contact_stiffness_n_m: tangential bristle stiffness Kt [N/m].
        friction_coefficient: mu; the Coulomb level is ``Fc = mu m g``.
        damping_ratio: structural damping ratio zeta (0 in the paper).
        gravity_m_s2: g [m/s^2].
    """

    mass_kg: Float[ArrayLike, ""]
    stiffness_n_m: Float[ArrayLike, ""]
    angular_frequency_rad_s: Float[ArrayLike, ""]
    force_amplitude_n: Float[ArrayLike, ""]
    contact_stiffness_n_m: Float[ArrayLike, ""]
    friction_coefficient: Float[ArrayLike, ""]
    damping_ratio: Float[ArrayLike, ""] = 0.0
    gravity_m_s2: Float[ArrayLike, ""] = 9.81

    @property
    def fc_n(self) -> Array:
        """Coulomb level Fc = mu m g [N] (paper eq. 7)."""
        return jnp.asarray(self.friction_coefficient * self.mass_kg * self.gravity_m_s2)

    @property
    def damping_n_s_m(self) -> Array:
        """Viscous structural damping c = 2 zeta sqrt(Ks m) [N s/m]."""
        return jnp.asarray(2.0 * self.damping_ratio * jnp.sqrt(self.stiffness_n_m * self.mass_kg))

    @property
    def linear_amplitude_m(self) -> Array:
        """Displacement amplitude of the friction-free forced response [m]."""
        k, m, w = self.stiffness_n_m, self.mass_kg, self.angular_frequency_rad_s
        return jnp.asarray(
            self.force_amplitude_n / jnp.abs(k - m * w**2 + 1j * self.damping_n_s_m * w)
        )


def table2(**changes: float) -> Transducer:
    """The paper's Table 2 parameters, with any field replaced by keyword.

    m = 0.02 kg, Ks = 133e6 N/m, w = 2 pi 60 kHz, Fe = 1920 N (the top of its 0-1920 N
    range), Kt = 0.056e6 N/m, mu = 0.1, no damping.
    """
    base = Transducer(
        mass_kg=0.02,
        stiffness_n_m=133e6,
        angular_frequency_rad_s=2.0 * jnp.pi * 60e3,
        force_amplitude_n=1920.0,
        contact_stiffness_n_m=0.056e6,
        friction_coefficient=0.1,
    )
    return dataclasses.replace(base, **changes)


# ---------------------------------------------------------------------------- dynamics


class _Anchor(eqx.Module):
    """Friction state at the last reversal: force ``f`` [N] and slip sign ``s``."""

    f: Array
    s: Array


def _friction(p: Transducer, u: Array, anchor: _Anchor) -> Array:
    """Exact Dahl force [N] after slip ``u`` [m] since the anchor (notes §4)."""
    fc = p.fc_n
    target = anchor.s * fc
    return target + (anchor.f - target) * jnp.exp(
        -jnp.asarray(p.contact_stiffness_n_m) * anchor.s * u / fc
    )


def _rhs(p: Transducer, vt: Array, t: Array, y: Array, anchor: _Anchor) -> Array:
    """d/dt of ``(x, x', u, quadratures...)``; smooth while the anchor is fixed."""
    x, xd, u = y[0], y[1], y[2]
    drive = p.force_amplitude_n * jnp.cos(p.angular_frequency_rad_s * t)
    fd = _friction(p, u, anchor)
    c = p.damping_n_s_m
    xdd = (-jnp.asarray(p.stiffness_n_m) * x - c * xd + drive + fd) / p.mass_kg
    v = vt - xd
    return jnp.stack([xd, xdd, v, fd, fd * v, drive * xd, c * xd**2])


def _rk4(p, vt, t, y, h, anchor):
    k1 = _rhs(p, vt, t, y, anchor)
    k2 = _rhs(p, vt, t + h / 2, y + h / 2 * k1, anchor)
    k3 = _rhs(p, vt, t + h / 2, y + h / 2 * k2, anchor)
    k4 = _rhs(p, vt, t + h, y + h * k3, anchor)
    return y + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4), k1


def _crossing_time(v0, dv0, v1, dv1, h):
    """Root in [0, h] of the cubic Hermite interpolant of V (values and slopes)."""
    tau = jnp.clip(h * v0 / jnp.where(v0 != v1, v0 - v1, 1.0), 0.0, h)
    for _ in range(4):  # Newton; quadratic convergence from the secant guess
        s = tau / h
        h00, h10 = 2 * s**3 - 3 * s**2 + 1, s**3 - 2 * s**2 + s
        h01, h11 = -2 * s**3 + 3 * s**2, s**3 - s**2
        val = h00 * v0 + h10 * h * dv0 + h01 * v1 + h11 * h * dv1
        d00, d10 = (6 * s**2 - 6 * s) / h, 3 * s**2 - 4 * s + 1
        d01, d11 = (-6 * s**2 + 6 * s) / h, 3 * s**2 - 2 * s
        der = d00 * v0 + d10 * dv0 + d01 * v1 + d11 * dv1
        tau = jnp.clip(tau - val / jnp.where(der != 0, der, 1.0), 0.0, h)
    return tau


def _step(p, vt, t, y, h, anchor):
    """One step of length h, split at a reversal of V if one falls inside it."""
    trial, k1 = _rk4(p, vt, t, y, h, anchor)
    v0, v1 = vt - y[1], vt - trial[1]
    crossed = anchor.s * v1 < 0.0
    dv0 = -k1[1]
    dv1 = -_rhs(p, vt, t + h, trial, anchor)[1]
    tau = jnp.where(crossed, _crossing_time(v0, dv0, v1, dv1, h), h)
    mid, _ = _rk4(p, vt, t, y, tau, anchor)
    f_mid = _friction(p, mid[2], anchor)
    new_anchor = _Anchor(
        f=jnp.where(crossed, f_mid, anchor.f), s=jnp.where(crossed, -anchor.s, anchor.s)
    )
    mid = mid.at[2].set(jnp.where(crossed, 0.0, mid[2]))
    end, _ = _rk4(p, vt, t + tau, mid, h - tau, new_anchor)
    end = jnp.where(crossed, end, trial)
    return end, new_anchor


def _march(p, vt, t0, state, n_steps, h):
    """March ``n_steps`` of length ``h`` from ``state = (x, x', F_D)`` at ``t0``.

    Returns the final ``(x, x', F_D)``, the quadratures, and the samples of
    ``(t, x, x', F_D)`` at the start of every step.
    """
    x0, xd0, f0 = state
    s0 = jnp.where(vt - xd0 >= 0.0, 1.0, -1.0)
    y0 = jnp.concatenate([jnp.stack([x0, xd0, 0.0 * x0]), jnp.zeros(_NQ)])

    def body(carry, i):
        y, anchor = carry
        t = t0 + i * h
        sample = jnp.stack([t, y[0], y[1], _friction(p, y[2], anchor)])
        y, anchor = _step(p, vt, t, y, h, anchor)
        return (y, anchor), sample

    (y, anchor), samples = jax.lax.scan(
        body, (y0, _Anchor(f=jnp.asarray(f0, float), s=s0)), jnp.arange(n_steps)
    )
    final = jnp.stack([y[0], y[1], _friction(p, y[2], anchor)])
    return final, y[3:], samples


# ---------------------------------------------------------------------------- outputs


class EnergyBalance(eqx.Module):
    """Window averages and the energy balance of eqs. 22-25, over ``Fc Vt``.

    ``power_ratio`` (PDR, from the integral of F_D V) must equal
    ``1 + input_power_ratio - system_power_ratio`` (eq. 25), where the system term
    gathers the power stored in the mass and spring, the power lost in structural
    damping, and the pulling power saved because friction is lower (the paper keeps
    the pulling input at its OFF value Fc Vt): ``(1 - FR) + stored + damping``.
    ``balance_residual`` is the difference, computed from independent quadratures.
    """

    friction_ratio: Array
    power_ratio: Array
    input_power_ratio: Array
    stored_power_ratio: Array
    damping_power_ratio: Array
    system_power_ratio: Array
    balance_residual: Array


def _energy(p: Transducer, vt, start, end, quad, duration) -> EnergyBalance:
    def mech(s):
        return 0.5 * p.mass_kg * s[1] ** 2 + 0.5 * p.stiffness_n_m * s[0] ** 2

    ref = p.fc_n * vt * duration
    fr = quad[0] / (p.fc_n * duration)
    pdr, phi_in, phi_damp = quad[1] / ref, quad[2] / ref, quad[3] / ref
    phi_stored = (mech(end) - mech(start)) / ref
    phi_sys = (1.0 - fr) + phi_stored + phi_damp
    return EnergyBalance(
        friction_ratio=fr,
        power_ratio=pdr,
        input_power_ratio=phi_in,
        stored_power_ratio=phi_stored,
        damping_power_ratio=phi_damp,
        system_power_ratio=phi_sys,
        balance_residual=pdr - (1.0 + phi_in - phi_sys),
    )


class TransducerSteadyState(eqx.Module):
    """Periodic steady state of the transducer at one sliding speed.

    Attributes:
        velocity_ratio: VR = Vt / (X w), X w the amplitude of the fundamental of x'.
        vibration_velocity_m_s: X w [m/s].
        balance: cycle averages and energy terms (:class:`EnergyBalance`).
        state: ``(x [m], x' [m/s], F_D [N])`` at t = 0 on the periodic orbit.
        periodicity_error: max relative change of the state over one period.
    """

    velocity_ratio: Array
    vibration_velocity_m_s: Array
    balance: EnergyBalance
    state: Array
    periodicity_error: Array

    @property
    def friction_ratio(self) -> Array:
        return self.balance.friction_ratio

    @property
    def power_ratio(self) -> Array:
        return self.balance.power_ratio


def _fundamental(samples: Array, n: int) -> Array:
    """Amplitude of the first harmonic of ``n`` equispaced samples over one period."""
    phase = 2.0 * jnp.pi * jnp.arange(n) / n
    return 2.0 / n * jnp.abs(jnp.sum(samples * jnp.exp(-1j * phase)))


def _newton_periodic(residual, z0: Array, iterations: int) -> Array:
    """Fixed-count Newton on ``residual(z) = 0`` (3 unknowns), then one implicit step.

    The iterations run under ``stop_gradient``; the last step
    ``z - J^{-1} residual(z)`` with J frozen has, by the implicit function theorem, the
    exact derivative of the root with respect to every parameter ``residual`` closes
    over. A fixed count (rather than optimistix's adaptive while loop) keeps ``vmap``
    over many operating points cheap; convergence is reported, not assumed.
    """

    def newton(_, z):
        return z - jnp.linalg.solve(jax.jacfwd(residual)(z), residual(z))

    # A loop, not unrolled: one compiled body keeps the time to first result low.
    z = jax.lax.stop_gradient(jax.lax.fori_loop(0, iterations, newton, z0))
    jac = jax.lax.stop_gradient(jax.jacfwd(residual)(z))
    return z - jnp.linalg.solve(jac, residual(z))


# jax.jit, not eqx.filter_jit: Python floats in the model are traced, not baked in,
# so a new parameter value does not recompile.
@functools.partial(jax.jit, static_argnames=("steps_per_period", "newton_iterations"))
def transducer_steady_state(
    p: Transducer,
    sliding_speed_m_s: Float[ArrayLike, ""],
    steps_per_period: int = 256,
    newton_iterations: int = 4,
) -> TransducerSteadyState:
    """Periodic orbit at the forcing period by Newton shooting, and its averages.

    Starts from the friction-free forced response, marches one period to let the
    friction state settle, then solves ``P(y) = y`` for the one-period map P by Newton
    (state scaled by the linear amplitude and Fc). The map is nearly affine (Dahl is
    exact along the slip and friction is small against the drive), so Newton converges
    in two or three iterations; ``periodicity_error`` reports the check.
    Differentiable: gradients flow through the root by the implicit function theorem.
    """
    vt = jnp.asarray(sliding_speed_m_s, float)
    w = jnp.asarray(p.angular_frequency_rad_s, float)
    n = steps_per_period
    period = 2.0 * jnp.pi / w
    h = period / n
    k, m, c = p.stiffness_n_m, p.mass_kg, p.damping_n_s_m
    x_lin = p.force_amplitude_n / (k - m * w**2 + 1j * c * w)
    scale = jnp.stack([jnp.abs(x_lin), jnp.abs(x_lin) * w, p.fc_n])
    guess = jnp.stack([jnp.real(x_lin), -w * jnp.imag(x_lin), 0.0 * scale[2]])
    guess, _, _ = _march(p, vt, 0.0, guess, n, h)

    def residual(z):
        end, _, _ = _march(p, vt, 0.0, z * scale, n, h)
        return end / scale - z

    state = _newton_periodic(residual, guess / scale, newton_iterations) * scale
    end, quad, samples = _march(p, vt, 0.0, state, n, h)
    balance = _energy(p, vt, state, end, quad, period)
    vib = _fundamental(samples[:, 2], n)
    return TransducerSteadyState(
        velocity_ratio=vt / vib,
        vibration_velocity_m_s=vib,
        balance=balance,
        state=state,
        periodicity_error=jnp.max(jnp.abs(end - state) / scale),
    )


class TransducerRun(eqx.Module):
    """A time-marched run: samples at every step start and the last period's balance."""

    time_s: Array
    displacement_m: Array
    velocity_m_s: Array
    friction_n: Array
    last_period: EnergyBalance


@functools.partial(jax.jit, static_argnames=("periods", "steps_per_period"))
def simulate_transducer(
    p: Transducer,
    sliding_speed_m_s: Float[ArrayLike, ""],
    periods: int = 50,
    steps_per_period: int = 1000,
) -> TransducerRun:
    """March from rest (x = x' = F_D = 0) as the paper did, without shooting.

    The paper's RK4 step of 1.667e-8 s is 1000 steps per 60 kHz period (the default).
    With no damping the free oscillation stays in the signal; ``last_period`` holds
    the averages and energy terms over the final forcing period.
    """
    vt = jnp.asarray(sliding_speed_m_s, float)
    n = steps_per_period
    period = 2.0 * jnp.pi / jnp.asarray(p.angular_frequency_rad_s, float)
    h = period / n
    start = jnp.zeros(3)
    mid, _, head = _march(p, vt, 0.0, start, (periods - 1) * n, h)
    end, quad, tail = _march(p, vt, (periods - 1) * period, mid, n, h)
    samples = jnp.concatenate([head, tail])
    return TransducerRun(
        time_s=samples[:, 0],
        displacement_m=samples[:, 1],
        velocity_m_s=samples[:, 2],
        friction_n=samples[:, 3],
        last_period=_energy(p, vt, mid, end, quad, period),
    )
