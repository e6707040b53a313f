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
smoothed one). Every piece's update is an affine map of the bristle force whose
coefficients do not depend on it, so the maps of all intervals are computed at once and
only their composition, a few operations a sample, runs in a :func:`jax.lax.scan`
(differentiable in the parameters; forward derivatives through a scan of the whole
update cost 20 times its value, 39 ms against 3 ms for 10,000 samples and 5 tangents).

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

__all__ = [
    "LawAt",
    "force_at",
    "force_map",
    "output_force",
    "piece_map",
    "piece_update",
    "series_force",
]

# A law at a normal load [N]: (values by name, load) -> law (AbstractFrictionLaw.at_load
# with the caller's extras set, e.g. LuGre's damping).
LawAt = Callable[[Mapping[str, ArrayLike], Float[ArrayLike, ""]], AbstractFrictionLaw]


def piece_map(
    law: AbstractFrictionLaw, du_m: Float[ArrayLike, "*b"], v_mid_m_s: Float[ArrayLike, "*b"]
) -> tuple[Float[Array, "*b"], Float[Array, "*b"]]:
    """The affine map ``fb -> a fb + b`` of the bristle force [N] over a piece of slip
    ``du_m`` [m] of one sign, the level taken at ``v_mid_m_s`` [m/s] (notes §4:
    ``fb <- s L + (fb - s L) exp(-kappa)``); the identity over a piece of no slip. It
    does not depend on ``fb``, so the maps of every interval are computed at once and
    only their composition runs sample by sample."""
    du = jnp.asarray(du_m)
    level = law.level_n(v_mid_m_s)
    decay = jnp.exp(-law.decay_exponent(jnp.abs(du), level))
    moves = du != 0.0
    return jnp.where(moves, decay, 1.0), jnp.where(moves, jnp.sign(du) * level * (1.0 - decay), 0.0)


def piece_update(
    law: AbstractFrictionLaw,
    fb_n: Float[ArrayLike, "*b"],
    du_m: Float[ArrayLike, "*b"],
    v_mid_m_s: Float[ArrayLike, "*b"],
) -> Float[Array, "*b"]:
    """The bristle force [N] after a piece of slip ``du_m`` [m] of one sign, the level
    taken at ``v_mid_m_s`` [m/s] (:func:`piece_map`)."""
    a, b = piece_map(law, du_m, v_mid_m_s)
    return a * jnp.asarray(fb_n) + b


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

    def part_maps(law, va, vb, h):
        """Per part of the interval, the affine map ``(a, b)`` of the bristle force from
        the interval's start to the part's end (its pieces composed), and V there."""
        vs = va + (vb - va) * fractions
        a, b = jnp.ones(()), jnp.zeros(())
        out = []
        for j in range(substeps):
            for du, vm in _split(vs[j], vs[j + 1], h / substeps):
                ap, bp = piece_map(law, du, vm)
                a, b = ap * a, ap * b + bp
            out.append((a, b, vs[j + 1]))
        return out

    if lag_s is None:

        def interval_map(va, vb, h, n_mid):
            """The interval's affine map of the bristle force."""
            a, b, _ = part_maps(law_at(values, n_mid), va, vb, h)[-1]
            return a, b

        # the maps of all intervals at once; only their composition, two operations
        # a sample, runs in the scan (forward derivatives through a scan of the whole
        # update cost 20x its value: 39 ms against 3 ms for 10,000 samples)
        maps = jax.vmap(interval_map)(v_start, v_end, dt, load_mid)

        def step(fb, ab):
            fb = ab[0] * fb + ab[1]
            return fb, fb

        _, fb_rest = jax.lax.scan(step, fb0, maps)
        fb = jnp.concatenate([fb0[None], fb_rest])
        return output_force(law_at, values, v, load, fb, extra_viscous_n_s_m), fb

    tau = jnp.asarray(lag_s, float)
    f0 = force_at(law_at(values, load[0]), fb0, v[0], extra_viscous_n_s_m)

    def lagged_map(va, vb, h, n_mid):
        """The interval's map of ``(fb, y, F)`` at its start (bristle force, recorded
        force, friction force) to its end, affine: ``fb' = A fb + B``, ``F' = P fb + Q``
        and ``y' = Y y + U fb + W F + H``, the parts' sensor updates composed."""
        law = law_at(values, n_mid)
        hp = h / substeps
        a = jnp.exp(-hp / tau)
        c = tau * (1.0 - a) / hp
        # y and the previous part's F as (coefficients of y, fb, F at the start; constant)
        y = (jnp.ones(()), jnp.zeros(()), jnp.zeros(()), jnp.zeros(()))
        f_prev = (jnp.zeros(()), jnp.zeros(()), jnp.ones(()), jnp.zeros(()))
        for ap, bp, v_part in part_maps(law, va, vb, h):
            # F = fb + s1 dz/dt + s2 V is affine in fb (paper eq. 3)
            alpha, beta = force_map(law, v_part, extra_viscous_n_s_m)
            f = (jnp.zeros(()), alpha * ap, jnp.zeros(()), alpha * bp + beta)
            # y <- F + a (y - F_prev) - lag (1 - a) (F - F_prev) / h_part
            y = tuple(
                (1.0 - c) * fi + (c - a) * gi + a * yi
                for fi, gi, yi in zip(f, f_prev, y, strict=True)
            )
            f_prev = f
        return ap, bp, f_prev[1], f_prev[3], *y

    maps = jax.vmap(lagged_map)(v_start, v_end, dt, load_mid)

    def step_lagged(carry, m):
        fb, y, f = carry
        a, b, p, q, yy, yu, yw, yh = m
        y = yy * y + yu * fb + yw * f + yh
        return (a * fb + b, y, p * fb + q), (a * fb + b, y)

    _, (fb_rest, y_rest) = jax.lax.scan(step_lagged, (fb0, f0, f0), maps)
    return jnp.concatenate([f0[None], y_rest]), jnp.concatenate([fb0[None], fb_rest])


def force_at(
    law: AbstractFrictionLaw,
    fb_n: Float[ArrayLike, ""],
    velocity_m_s: Float[ArrayLike, ""],
    extra_viscous_n_s_m: Float[ArrayLike, ""] = 0.0,
) -> Float[Array, ""]:
    """``F = fb + s1 dz/dt + s2 V + c_v V`` [N] of one law at one point (paper eq. 3)."""
    alpha, beta = force_map(law, velocity_m_s, extra_viscous_n_s_m)
    return alpha * jnp.asarray(fb_n) + beta


def force_map(
    law: AbstractFrictionLaw,
    velocity_m_s: Float[ArrayLike, ""],
    extra_viscous_n_s_m: Float[ArrayLike, ""] = 0.0,
) -> tuple[Float[Array, ""], Float[Array, ""]]:
    """:func:`force_at` as the affine map ``fb -> alpha fb + beta`` [N]: with ``dz/dt =
    V - |V| fb / L(V)`` (``z = fb / Kt``), ``alpha = 1 - s1 |V| / L(V)`` and ``beta =
    (s1 + s2 + c_v) V``."""
    v = jnp.asarray(velocity_m_s)
    s1 = law.bristle_damping_n_s_m()
    s2 = law.viscous_n_s_m() + extra_viscous_n_s_m
    return 1.0 - s1 * jnp.abs(v) / law.level_n(v), (s1 + s2) * v


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
