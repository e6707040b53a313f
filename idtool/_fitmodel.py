"""The joint bench model of a dataset: parameters, transforms, predictions, residuals.

Shared physical parameters: the contact stiffness Kt [N/m], the friction coefficient
mu and the coupling (``coupling_gain``; ``power_load_n`` [N] for the power-limited law;
LuGre adds ``static_ratio`` Fs/Fc and ``stribeck_velocity_m_s``). Shared bench
parameters: the actuator-limited ``slope_n_s`` and ``startup_slope_n_s`` [N/s]. Per trace,
where the data demand them: the load-cell offset [N] (it drifts between pulls; the
baseline before each pull measures it), the pull start [s], and the lag of the horn
behind the logged ON flag at switch-on and at switch-off [s].

Every parameter lives on an unbounded internal scale ``z`` of order one, which is what
Levenberg-Marquardt's damping assumes: bounded positive parameters as
``exp(log lo + (log hi - log lo) sigmoid(z))``, the others as ``centre + scale z``.
"""

from __future__ import annotations

import dataclasses
import functools

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from ._bench import TraceTiming, mean_force_n, on_friction_ratio
from ._coupling import AbstractCoupling, ConstantCoupling, PowerLimitedCoupling
from ._fitdata import FitData, StartValues
from ._laws import AbstractFrictionLaw, Dahl, LuGre
from ._lm import ColouredJacobian, normal_equations

__all__ = ["TRACE_GROUPS", "FitModel", "ParamSpec"]

CORNER_N = 0.5  # rounding of the trace's corners [N]; fixed, not identifiable

# Per-trace nuisances: name, unit, internal scale. The horn's lag behind the logged flag
# differs at switch-on and switch-off (each is its own relay and ramp-up), and a single
# lag leaves a visible bump in the residuals after OFF.
TRACE_GROUPS = (
    ("offset_n", "N", 1.0),
    ("pull_start_s", "s", 0.05),
    ("delay_on_s", "s", 0.01),
    ("delay_off_s", "s", 0.01),
)

LAWS = ("dahl", "lugre")
COUPLINGS = ("constant", "power-limited")


@dataclasses.dataclass(frozen=True)
class ParamSpec:
    """One fitted parameter: its name, unit, transform, and whether it is physical."""

    name: str
    unit: str
    lo: float = 0.0  # bounds of a log-bounded parameter (physical units)
    hi: float = 0.0
    centre: float = 0.0  # value = centre + scale * z for a linear one
    scale: float = 0.0
    physical: bool = False

    @property
    def bounded(self) -> bool:
        return self.hi > 0.0

    def value(self, z):
        if self.bounded:
            a, b = np.log(self.lo), np.log(self.hi)
            return jnp.exp(a + (b - a) * jax.nn.sigmoid(z))
        return self.centre + self.scale * z

    def slope(self, z: float) -> float:
        """``d value / d z`` at ``z`` (for the delta method)."""
        if self.bounded:
            a, b = np.log(self.lo), np.log(self.hi)
            s = 1.0 / (1.0 + np.exp(-z))
            return float(self.value(z)) * (b - a) * s * (1.0 - s)
        return self.scale

    def internal(self, value: float) -> float:
        if self.bounded:
            a, b = np.log(self.lo), np.log(self.hi)
            u = np.clip((np.log(value) - a) / (b - a), 1e-9, 1 - 1e-9)
            return float(np.log(u / (1.0 - u)))
        return float((value - self.centre) / self.scale)


def _physical_specs(law: str, coupling: str) -> list[ParamSpec]:
    specs = [
        ParamSpec("Kt", "N/m", 1e4, 1e13, physical=True),
        ParamSpec("mu", "1", 1e-3, 3.0, physical=True),
        ParamSpec("coupling_gain", "1", 1e-5, 1.0, physical=True),
    ]
    if coupling == "power-limited":
        specs.append(ParamSpec("power_load_n", "N", 1.0, 1e5, physical=True))
    if law == "lugre":
        specs.append(ParamSpec("static_ratio", "1", 1.0, 5.0, physical=True))
        specs.append(ParamSpec("stribeck_velocity_m_s", "m/s", 1e-4, 10.0, physical=True))
    return specs


@dataclasses.dataclass(frozen=True, eq=False)
class FitModel:
    """The model of one dataset for one friction law and one coupling law.

    Compared by identity: its compiled fit (:func:`idtool._fit.compiled_lm`) is cached on it.
    """

    data: FitData
    start: StartValues
    law: str = "dahl"
    coupling: str = "power-limited"

    def __post_init__(self):
        if self.law not in LAWS:
            raise ValueError(f"law {self.law!r}: choose one of {LAWS}")
        if self.coupling not in COUPLINGS:
            raise ValueError(f"coupling {self.coupling!r}: choose one of {COUPLINGS}")

    # ------------------------------------------------------------------ parameters
    @property
    def specs(self) -> tuple[ParamSpec, ...]:
        d, s = self.data, self.start
        specs = _physical_specs(self.law, self.coupling)
        specs += [
            ParamSpec("slope_n_s", "N/s", 1.0, 1e5),
            ParamSpec("startup_slope_n_s", "N/s", 1.0, 1e5),
        ]
        centres = {"offset_n": s.offset_n, "pull_start_s": s.pull_start_s}
        for group, unit, scale in TRACE_GROUPS:
            centre = centres.get(group, np.zeros(d.n_traces))
            specs += [
                ParamSpec(f"{group}[{tid}]", unit, centre=float(centre[i]), scale=scale)
                for i, tid in enumerate(d.trace_ids)
            ]
        return tuple(specs)

    @property
    def n_shared(self) -> int:
        """Number of shared (not per-trace) parameters; they come first in ``z``."""
        return len(self.specs) - len(TRACE_GROUPS) * self.data.n_traces

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(p.name for p in self.specs)

    @property
    def physical_names(self) -> tuple[str, ...]:
        return tuple(p.name for p in self.specs if p.physical)

    @property
    def param_group(self) -> np.ndarray:
        """Per parameter: -1 if shared, else the trace whose residuals it alone moves."""
        n = self.data.n_traces
        return np.concatenate(
            [np.full(self.n_shared, -1), np.tile(np.arange(n), len(TRACE_GROUPS))]
        )

    def values(self, z: Float[Array, " p"]) -> dict[str, Array]:
        """Physical values: shared names map to scalars, per-trace groups to arrays."""
        specs = self.specs
        n = self.data.n_traces
        k = self.n_shared
        out = {p.name: p.value(z[i]) for i, p in enumerate(specs[:k])}
        for j, (group, _, _) in enumerate(TRACE_GROUPS):
            block = specs[k + j * n : k + (j + 1) * n]
            centre = jnp.array([p.centre for p in block])
            scale = jnp.array([p.scale for p in block])
            out[group] = centre + scale * z[k + j * n : k + (j + 1) * n]
        return out

    def z0(self, **physical: float) -> np.ndarray:
        """Internal start vector: the data-driven start values, ``physical`` overrides."""
        guess = {
            "Kt": 1e8,
            "mu": self.start.friction_coefficient,
            "coupling_gain": 0.01,
            "power_load_n": 300.0,
            "static_ratio": 1.2,
            "stribeck_velocity_m_s": 0.01,
            "slope_n_s": self.start.slope_n_s,
            "startup_slope_n_s": self.start.startup_slope_n_s,
        } | physical
        return np.array([p.internal(guess[p.name]) if p.bounded else 0.0 for p in self.specs])

    # ------------------------------------------------------------------ physics
    def law_at(self, v: dict[str, Array], normal_load_n) -> AbstractFrictionLaw:
        fc = v["mu"] * normal_load_n
        if self.law == "lugre":
            return LuGre(
                fc_n=fc,
                kt_n_m=v["Kt"],
                fs_n=v["static_ratio"] * fc,
                vs_m_s=v["stribeck_velocity_m_s"],
            )
        return Dahl(fc_n=fc, kt_n_m=v["Kt"])

    def coupling_of(self, v: dict[str, Array]) -> AbstractCoupling:
        if self.coupling == "power-limited":
            return PowerLimitedCoupling(gain=v["coupling_gain"], power_load_n=v["power_load_n"])
        return ConstantCoupling(gain=v["coupling_gain"])

    def friction_ratios(self, v: dict[str, Array], load_n, alpha, speed_m_s) -> Array:
        """FR at operating points (arrays of equal shape), from physical values ``v``."""
        coupling = self.coupling_of(v)
        f_hz, a_max = self.data.vibration_frequency_hz, self.data.max_amplitude_m

        def one(n, a, s):
            return on_friction_ratio(self.law_at(v, n), coupling, n, a, s, f_hz, a_max)

        return jax.vmap(one)(jnp.ravel(load_n), jnp.ravel(alpha), jnp.ravel(speed_m_s)).reshape(
            jnp.shape(load_n)
        )

    @functools.cached_property
    def operating_points(self) -> tuple[np.ndarray, np.ndarray]:
        """The distinct (load [N], amplitude fraction, speed [m/s]) rows of the traces,
        and each trace's row: repeated traces share one contact solve."""
        d = self.data
        ops = np.stack([d.normal_load_n, d.amplitude_fraction, d.pull_speed_m_s], axis=1)
        unique, index = np.unique(ops, axis=0, return_inverse=True)
        return unique, index.ravel()

    def levels(self, v: dict[str, Array]) -> tuple[Array, Array, Array]:
        """Per trace: OFF level [N], ON level [N] and friction ratio."""
        d = self.data
        ops, index = self.operating_points
        fr = self.friction_ratios(v, ops[:, 0], ops[:, 1], ops[:, 2])[index]
        off = jax.vmap(lambda n, s: self.law_at(v, n).off_force_n(s))(
            jnp.asarray(d.normal_load_n), jnp.asarray(d.pull_speed_m_s)
        )
        return off, fr * off, fr

    def predict(self, z: Float[Array, " p"]) -> Float[Array, " blocks"]:
        """Block-mean load-cell force [N] for every block of every trace."""
        off, on, _ = self.levels(self.values(z))
        return self.predict_at_levels(z, off, on)

    def predict_at_levels(
        self, z: Float[Array, " p"], off_n: Float[Array, " traces"], on_n: Float[Array, " traces"]
    ) -> Float[Array, " blocks"]:
        """:meth:`predict` with the per-trace OFF and ON levels [N] given: the physical
        parameters act on the traces only through them."""
        d = self.data
        v = self.values(z)
        bt = d.block_trace

        def per_block(x):
            return jnp.asarray(x)[bt][:, None]

        timing = TraceTiming(
            startup_s=per_block(v["pull_start_s"]),
            on_start_s=per_block(d.on_start_s + v["delay_on_s"]),
            on_end_s=per_block(d.on_end_s + v["delay_off_s"]),
        )
        force = mean_force_n(
            d.sub_time_s,
            per_block(off_n),
            per_block(on_n),
            timing,
            v["slope_n_s"],
            v["startup_slope_n_s"],
            per_block(v["offset_n"]),
            CORNER_N,
        )
        return force.mean(axis=1)

    @functools.cached_property
    def level_structure(self) -> ColouredJacobian:
        """Sparsity of the residuals in ``u = (OFF levels, ON levels, z[k:])``, the
        bench model's own inputs (see :meth:`normal_equations`): 8 colours."""
        m, k = self.data.n_traces, len(self.physical_names)
        groups = np.concatenate([np.arange(m), np.arange(m), self.param_group[k:]])
        return ColouredJacobian.from_groups(groups, self.data.block_trace)

    def normal_equations(
        self, z: Float[Array, " p"], phi: float | Array
    ) -> tuple[Array, Array, Array, tuple[Array, Array]]:
        """Whitened residuals ``r``, ``J^T J`` and ``J^T r`` at ``z``; and the levels
        ``(OFF, ON)`` [N] (2 n_traces) with their Jacobian in the physical parameters.

        The physical parameters reach the traces only through the per-trace OFF and ON
        levels, so the Jacobian is taken in the bench model's inputs ``u = (OFF, ON,
        z[k:])`` with one JVP per colour of :attr:`level_structure` (8; the contact model
        stays out of them) and mapped back by the chain rule, ``J = J_u T`` with
        ``T = du/dz``: the levels' small Jacobian in the physical parameters, the
        identity for the rest.
        """
        k, m = len(self.physical_names), self.data.n_traces
        z = jnp.asarray(z)

        def levels(zp):
            off, on, _ = self.levels(self.values(z.at[:k].set(zp)))
            return jnp.concatenate([off, on])

        def resid(u):
            zz = jnp.concatenate([z[:k], u[2 * m :]])
            e = self.predict_at_levels(zz, u[:m], u[m : 2 * m]) - self.data.force_n
            return self._whiten(e, phi)

        # (2 m, k) and (2 m,): the Jacobian and, from the same pass, the levels
        dlv, lv = jax.jacfwd(lambda zp: (levels(zp),) * 2, has_aux=True)(z[:k])
        u = jnp.concatenate([lv, z[k:]])
        r, jtj_u, jtr_u = normal_equations(resid, u, self.level_structure)
        n_rest = z.size - k
        t = jnp.block(
            [[dlv, jnp.zeros((2 * m, n_rest))], [jnp.zeros((n_rest, k)), jnp.eye(n_rest)]]
        )
        return r, t.T @ jtj_u @ t, t.T @ jtr_u, (lv, dlv)

    def residuals(self, z: Float[Array, " p"], phi: float | Array = 0.0) -> Array:
        """AR(1)-whitened residuals: ``e_t - phi e_{t-1}`` within each trace, and
        ``sqrt(1 - phi^2) e_1`` at each trace's first block (exact AR(1) likelihood)."""
        return self._whiten(self.predict(z) - self.data.force_n, phi)

    def _whiten(self, e: Array, phi: float | Array) -> Array:
        first = np.zeros(self.data.n_blocks, bool)
        first[self.data.first_block] = True
        shifted = jnp.roll(e, 1)
        return jnp.where(first, jnp.sqrt(1.0 - phi**2) * e, e - phi * shifted)
