"""The friction force along a measured time series of slip velocity (model notes §1, §4).

The bristle force ``fb = Kt z`` [N] obeys, along slip ``u`` [m] of constant sign ``s``,

    d fb / du = Kt (1 - s fb / L(V)),        L(V) = Kt g(V)   (notes §1, eq. 2),

and for ``L`` held constant over a stretch of slip ``du`` the exact affine update of
:mod:`idtool._model._laws` (notes §4):

    fb <- s L + (fb - s L) exp(-Kt |du| / L).

Between two samples the slip velocity is taken linear in time (from the sampled
velocities) or constant (from sampled displacements: the slip over the interval is
then the displacement increment itself). Each sample interval is cut into
``substeps`` equal parts, and a part in which V changes sign is split at its zero, so
every piece has one sign. Over a piece the slip is exact (the trapezoid of a linear V)
and the level is taken at the piece's midpoint velocity. The update is therefore exact
for every law of constant level (Coulomb, Dahl: any step, any stiffness, so presliding
needs no small step), and second order in the piece for LuGre, whose level varies with
V through the Stribeck curve (the error is checked against LSODA in
``tests/test_fit_law.py``). The laws' own methods (``at_load``, ``level_n``,
``decay_exponent``, ``bristle_damping_n_s_m``, ``viscous_n_s_m``) carry the physics, so a
newly registered law works here unchanged.

At each sample the friction force is (paper eq. 3)

    F = fb + s1 dz/dt + s2 V + c_v V,      dz/dt = V - |V| fb / L(V),

with ``c_v`` an extra viscous coefficient [N s/m] (zero unless a ``-viscous`` law asks
for it: ``coulomb-viscous`` is ``F = Fc sgn(V) + c_v V``, with the exact sign, not a
smoothed one). The loop over samples is a :func:`jax.lax.scan`, differentiable in the
parameters.

With ``lag_s`` the recorded force is ``y``, the friction force through a first-order
sensor, ``lag_s y' + y = F``, integrated in the same scan on the parts' grid with ``F``
linear over each part (the exact update ``y <- F1 + a (y - F0) - lag (1 - a) (F1 -
F0) / h``, ``a = exp(-h / lag)``); inside an interval ``F`` takes the interval's mean
load. (Filtering the sampled ``F`` instead, linear between samples, erred by half the
noise at the reversals' kinks; on the parts' grid, by 3e-4 of a 0.17 N lag effect.)
"""

from __future__ import annotations

from collections.abc import Callable, Mapping

import jax
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

from idtool._model._laws import AbstractFrictionLaw

__all__ = ["LawAt", "force_at", "output_force", "piece_update", "series_force"]

# A law at a normal load [N]: (values by name, load) -> law (AbstractFrictionLaw.at_load
# with the caller's extras set, e.g. LuGre's damping).
LawAt = Callable[[Mapping[str, ArrayLike], Float[ArrayLike, ""]], AbstractFrictionLaw]


def piece_update(
    law: AbstractFrictionLaw,
    fb_n: Float[ArrayLike, "*b"],
    du_m: Float[ArrayLike, "*b"],
    v_mid_m_s: Float[ArrayLike, "*b"],
) -> Float[Array, "*b"]:
    """The bristle force [N] after a piece of slip ``du_m`` [m] of one sign, the level
    taken at ``v_mid_m_s`` [m/s] (notes §4's affine map); a piece of no slip leaves it."""
    du = jnp.asarray(du_m)
    s = jnp.sign(du)
    level = law.level_n(v_mid_m_s)
    decay = jnp.exp(-law.decay_exponent(jnp.abs(du), level))
    target = s * level
    moved = target + (jnp.asarray(fb_n) - target) * decay
    return jnp.where(du != 0.0, moved, fb_n)


def _split(v_a, v_b, dt):
    """A part with V linear from ``v_a`` to ``v_b`` over ``dt`` [s]: two pieces of one
    sign each, as (slip [m], midpoint velocity [m/s]); the second is empty (zero slip)
    unless V changes sign inside."""
    crosses = v_a * v_b < 0.0
    theta = jnp.where(crosses, v_a / jnp.where(crosses, v_a - v_b, 1.0), 1.0)
    du1 = jnp.where(crosses, 0.5 * v_a * theta * dt, 0.5 * (v_a + v_b) * dt)
    vm1 = jnp.where(crosses, 0.5 * v_a, 0.5 * (v_a + v_b))
    du2 = jnp.where(crosses, 0.5 * v_b * (1.0 - theta) * dt, 0.0)
    return (du1, vm1), (du2, 0.5 * v_b)


def series_force(
    law_at: LawAt,
    values: Mapping[str, ArrayLike],
    time_s: Float[ArrayLike, " n"],
    velocity_m_s: Float[ArrayLike, " n"],
    normal_load_n: Float[ArrayLike, " n"],
    fb0_n: Float[ArrayLike, ""] = 0.0,
    *,
    interval_velocity_m_s: Float[ArrayLike, " n1"] | None = None,
    extra_viscous_n_s_m: Float[ArrayLike, ""] = 0.0,
    substeps: int = 2,
    lag_s: Float[ArrayLike, ""] | None = None,
) -> tuple[Float[Array, " n"], Float[Array, " n"]]:
    """Friction force [N] and bristle force [N] at every sample of a series.

    Args:
        law_at: the law at a normal load (:data:`LawAt`).
        values: parameter values by name for ``law_at``.
        time_s: sample times [s], increasing.
        velocity_m_s: slip velocity at the samples [m/s] (the output's V).
        normal_load_n: normal load at the samples [N] (the interval uses its mean).
        fb0_n: bristle force at the first sample [N].
        interval_velocity_m_s: the constant velocity over each interval [m/s]
            (``diff(x) / diff(t)`` of a displacement series); None: V linear between the
            sampled velocities.
        extra_viscous_n_s_m: ``c_v`` [N s/m] of a ``-viscous`` law.
        substeps: equal parts per sample interval (a part that changes sign is split
            again at its zero).
        lag_s: a load cell's first-order time constant [s] (module docstring), or None.

    Returns:
        ``(F, fb)``: friction force (as recorded through the lag, with ``lag_s``) and
        bristle force [N], shape (n,).
    """
    t = jnp.asarray(time_s, float)
    v = jnp.asarray(velocity_m_s, float)
    load = jnp.broadcast_to(jnp.asarray(normal_load_n, float), t.shape)
    dt = jnp.diff(t)
    if interval_velocity_m_s is None:
        v_start, v_end = v[:-1], v[1:]
    else:
        v_start = v_end = jnp.asarray(interval_velocity_m_s, float)
    load_mid = 0.5 * (load[:-1] + load[1:])
    fractions = jnp.arange(substeps + 1) / substeps
    fb0 = jnp.asarray(fb0_n, float)

    def parts(law, fb, va, vb, h):
        """The bristle force at the end of each part of the interval."""
        vs = va + (vb - va) * fractions
        out = []
        for j in range(substeps):
            (du1, vm1), (du2, vm2) = _split(vs[j], vs[j + 1], h / substeps)
            fb = piece_update(law, fb, du1, vm1)
            fb = piece_update(law, fb, du2, vm2)
            out.append((fb, vs[j + 1]))
        return out

    if lag_s is None:

        def step(fb, x):
            va, vb, h, n_mid = x
            fb = parts(law_at(values, n_mid), fb, va, vb, h)[-1][0]
            return fb, fb

        _, fb_rest = jax.lax.scan(step, fb0, (v_start, v_end, dt, load_mid))
        fb = jnp.concatenate([fb0[None], fb_rest])
        return output_force(law_at, values, v, load, fb, extra_viscous_n_s_m), fb

    tau = jnp.asarray(lag_s, float)
    f0 = force_at(law_at(values, load[0]), fb0, v[0], extra_viscous_n_s_m)

    def step_lagged(carry, x):
        fb, y, f_prev = carry
        va, vb, h, n_mid = x
        law = law_at(values, n_mid)
        hp = h / substeps
        a = jnp.exp(-hp / tau)
        for fb_part, v_end_part in parts(law, fb, va, vb, h):
            f = force_at(law, fb_part, v_end_part, extra_viscous_n_s_m)
            y = f + a * (y - f_prev) - tau * (1.0 - a) * (f - f_prev) / hp
            f_prev = f
        return (fb_part, y, f_prev), (fb_part, y)

    _, (fb_rest, y_rest) = jax.lax.scan(step_lagged, (fb0, f0, f0), (v_start, v_end, dt, load_mid))
    return jnp.concatenate([f0[None], y_rest]), jnp.concatenate([fb0[None], fb_rest])


def force_at(
    law: AbstractFrictionLaw,
    fb_n: Float[ArrayLike, ""],
    velocity_m_s: Float[ArrayLike, ""],
    extra_viscous_n_s_m: Float[ArrayLike, ""] = 0.0,
) -> Float[Array, ""]:
    """``F = fb + s1 dz/dt + s2 V + c_v V`` [N] of one law at one point (paper eq. 3)."""
    v = jnp.asarray(velocity_m_s)
    dz_dt = v - jnp.abs(v) * fb_n / law.level_n(v)  # [m/s]: dz/dt = V - |V| z / g, z = fb / Kt
    s2 = law.viscous_n_s_m() + extra_viscous_n_s_m
    return jnp.asarray(fb_n + law.bristle_damping_n_s_m() * dz_dt + s2 * v)


def output_force(
    law_at: LawAt,
    values: Mapping[str, ArrayLike],
    velocity_m_s: Float[Array, " n"],
    normal_load_n: Float[Array, " n"],
    fb_n: Float[Array, " n"],
    extra_viscous_n_s_m: Float[ArrayLike, ""] = 0.0,
) -> Float[Array, " n"]:
    """:func:`force_at` at every sample [N] (paper eq. 3)."""
    return jax.vmap(lambda n, fb, v: force_at(law_at(values, n), fb, v, extra_viscous_n_s_m))(
        normal_load_n, fb_n, velocity_m_s
    )
