"""The bench model of a dataset: one model for the fit, the sampler and the checks.

A :class:`BenchModel` is an ``eqx.Module``: the block-averaged traces
(:class:`~idtool._data._blocks.FitData`) are its leaves, so one compiled program serves
every dataset of the same shape; the friction law, the coupling law, the actuator model,
the load-cell offset model, the level model and the noise model are static types, each
declaring its own parameters (``fit_params``, ``trace_params``, ``params``) and
registered by name (:data:`FRICTION_LAWS`, :data:`COUPLINGS`, :data:`ACTUATORS`,
:data:`OFFSETS`, :data:`LEVEL_MODELS`, :data:`NOISE_MODELS`); so is the direction of
vibration (:data:`DIRECTIONS`), which has no parameters.

Parameters, in the order of the internal vector ``z``:

* shared physical ones: the law's (``Kt``; LuGre adds ``static_ratio`` and
  ``stribeck_velocity_m_s``), ``mu``, the coupling's (``coupling_gain``, and
  ``power_load_n`` [N] for the power-limited law);
* shared bench ones: the actuator model's, ``slope_n_s`` and ``startup_slope_n_s``
  [N/s] (the lag model adds ``time_constant_s`` [s], :mod:`idtool._model._actuator`),
  then the level model's (the relaxing ON level's ``on_relax_time_s`` [s], the creeping
  level's ``level_creep_per_s`` [1/s], :mod:`idtool._model._level_model`);
* per trace (:attr:`BenchModel.trace_groups`): the offset model's (the load-cell offset
  [N]: it moves between pulls, the baseline before each pull measures it; the drift model
  adds its drift [N/s], :mod:`idtool._model._offset`), then :data:`TRACE_GROUPS`: the pull
  start [s] and the lag of the horn behind the logged ON flag at switch-on and at
  switch-off [s]; then the level model's (the relaxing ON level's rise [-]).

Every parameter lives on an unbounded internal scale (:mod:`idtool._model._params`).
The noise parameters are not in ``z``: the fit estimates the noise model's correlation
state (AR(1): phi) from its residuals, the
sampler adds the noise model's ``params`` after the shared ones.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float

from idtool._data._blocks import FitData
from idtool._data._start_values import start_values
from idtool._errors import IdtoolError
from idtool._model._actuator import ACTUATORS, DEFAULT_ACTUATOR, AbstractActuator
from idtool._model._bench import TraceTiming, on_friction_ratio
from idtool._model._coupling import COUPLINGS, AbstractCoupling, reacts_on_vibration
from idtool._model._directions import DEFAULT_DIRECTION, DIRECTIONS, AbstractDirection
from idtool._model._laws import FRICTION_LAWS, MU, AbstractFrictionLaw
from idtool._model._level_model import DEFAULT_LEVEL_MODEL, LEVEL_MODELS, AbstractLevelModel
from idtool._model._names import DEFAULT_COUPLING
from idtool._model._noise import DEFAULT_NOISE, NOISE_MODELS, AbstractNoise, NoiseState
from idtool._model._offset import DEFAULT_OFFSET, OFFSETS, AbstractOffset
from idtool._model._params import Param
from idtool._model._settings import ParameterSetting, apply_settings, fixed_values
from idtool._model._xp import xp

__all__ = ["TRACE_GROUPS", "BenchModel", "bench_model", "shared_params_of"]

# Per-trace nuisances of every model, after the offset model's: name, unit, internal
# scale. The horn's lag behind the logged flag differs at switch-on and switch-off (each
# is its own relay and ramp-up), and a single lag leaves a visible bump in the residuals
# after OFF.
TRACE_GROUPS = (
    ("pull_start_s", "s", 0.05),
    ("delay_on_s", "s", 0.01),
    ("delay_off_s", "s", 0.01),
)


class BenchModel(eqx.Module):
    """The model of one dataset for one friction law, coupling law, actuator model,
    load-cell offset model, level model and noise model.

    Build it with :func:`bench_model`. Pure and jittable: pass it to ``jax.jit``-ed
    functions as an argument.
    """

    data: FitData
    nuisance_centre: Float[Array, "groups traces"]  # data-driven start of each nuisance
    start_z: Float[Array, " shared"]  # data-driven internal start of the shared ones
    law: type[AbstractFrictionLaw] = eqx.field(static=True)
    coupling: type[AbstractCoupling] = eqx.field(static=True)
    actuator: type[AbstractActuator] = eqx.field(static=True)
    noise: AbstractNoise = eqx.field(static=True)
    offset: type[AbstractOffset] = eqx.field(static=True)
    level: type[AbstractLevelModel] = eqx.field(static=True, default=LEVEL_MODELS.get("steady"))
    # the direction of vibration the contact kernel assumes (no parameters of its own)
    direction: type[AbstractDirection] = eqx.field(
        static=True, default=DIRECTIONS.get(DEFAULT_DIRECTION)
    )
    # the user's fixed values, bounds, scales, starts and priors (:mod:`._settings`)
    settings: tuple[ParameterSetting, ...] = eqx.field(static=True, default=())

    # ------------------------------------------------------------------ parameters
    @property
    def shared_params(self) -> tuple[Param, ...]:
        """Estimated shared parameters, physical first (module docstring), with the
        user's settings applied; the fixed ones are left out (:attr:`fixed`)."""
        return shared_params_of(self.law, self.coupling, self.actuator, self.settings, self.level)

    @property
    def declared_params(self) -> tuple[Param, ...]:
        """The shared parameters as the laws and models declare them, before the user's
        settings (fixed ones included)."""
        return shared_params_of(self.law, self.coupling, self.actuator, (), self.level)

    @property
    def fixed(self) -> dict[str, float]:
        """The shared parameters the user fixed: name -> value (physical units)."""
        return dict(fixed_values(self.declared_params, self.settings))

    def complete(self, v: Mapping[str, ArrayLike]) -> dict[str, ArrayLike]:
        """``v`` with the fixed parameters' values added: what the physics reads."""
        return {**v, **{name: jnp.asarray(x) for name, x in self.fixed.items()}}

    @property
    def trace_groups(self) -> tuple[tuple[str, str, float], ...]:
        """Per-trace nuisance groups (name, unit, internal scale): the offset model's,
        then :data:`TRACE_GROUPS`."""
        return _trace_groups(self.offset, self.level)

    @property
    def params(self) -> tuple[Param, ...]:
        """Every parameter of ``z``: the shared ones, then each nuisance group's per
        trace (``offset_n[trace_id]``, ...). Outside a trace only (reads the centres)."""
        centre = np.asarray(self.nuisance_centre)
        out = list(self.shared_params)
        for j, (group, unit, scale) in enumerate(self.trace_groups):
            out += [
                Param(f"{group}[{tid}]", unit, "linear", centre=float(centre[j, i]), scale=scale)
                for i, tid in enumerate(self.data.trace_ids)
            ]
        return tuple(out)

    @property
    def n_shared(self) -> int:
        """Number of shared (not per-trace) parameters; they come first in ``z``."""
        return len(self.shared_params)

    @property
    def names(self) -> tuple[str, ...]:
        shared = tuple(p.name for p in self.shared_params)
        return shared + tuple(
            f"{group}[{tid}]" for group, _, _ in self.trace_groups for tid in self.data.trace_ids
        )

    @property
    def physical_names(self) -> tuple[str, ...]:
        return tuple(p.name for p in self.shared_params if p.physical)

    @property
    def n_physical(self) -> int:
        return len(self.physical_names)

    @property
    def param_group(self) -> np.ndarray:
        """Per parameter: -1 if shared, else the trace whose residuals it alone moves."""
        n = self.data.n_traces
        return np.concatenate(
            [np.full(self.n_shared, -1), np.tile(np.arange(n), len(self.trace_groups))]
        )

    @property
    def level_group(self) -> np.ndarray:
        """Per input of :meth:`level_residuals`, ``u = (OFF, ON levels, z[k:])``: -1 if
        it moves every trace's residuals (a shared bench parameter), else the trace
        whose residuals it alone moves (its levels and its nuisances): the sparsity the
        fit's coloured Jacobian exploits (:func:`idtool._fit._program.level_structure`)."""
        n, k = self.data.n_traces, self.n_physical
        return np.concatenate(
            [
                np.arange(n),
                np.arange(n),
                np.full(self.n_shared - k, -1),
                np.tile(np.arange(n), len(self.trace_groups)),
            ]
        )

    def padded(self, n_blocks: int) -> BenchModel:
        """This model on its data padded to ``n_blocks`` blocks (:meth:`FitData.padded`):
        the same residuals, then zeros; the same normal equations."""
        if n_blocks == self.data.force_n.shape[0]:
            return self
        data = self.data.padded(n_blocks)
        return dataclasses.replace(self, data=data)

    def values(self, z: Float[Array | np.ndarray, " p"]) -> dict[str, Array]:
        """Physical values: shared names map to scalars, per-trace groups to arrays
        (NumPy for a NumPy ``z``, JAX otherwise: :mod:`idtool._model._xp`)."""
        k, n = self.n_shared, self.data.n_traces
        out = {p.name: p.value(z[i]) for i, p in enumerate(self.shared_params)}
        centre = self.nuisance_centre if xp(z) is jnp else np.asarray(self.nuisance_centre)
        for j, (group, _, scale) in enumerate(self.trace_groups):
            out[group] = centre[j] + scale * z[k + j * n : k + (j + 1) * n]
        return out

    def z0(self, **physical: float) -> np.ndarray:
        """Internal start vector: the data-driven start values, ``physical`` overrides
        (by name, physical units); the nuisances at their centres."""
        z = np.zeros(self.n_shared + len(self.trace_groups) * self.data.n_traces)
        z[: self.n_shared] = np.asarray(self.start_z)
        for i, p in enumerate(self.shared_params):
            if p.name in physical:
                z[i] = p.internal(physical[p.name])
        return z

    # ------------------------------------------------------------------ physics
    def law_at(self, v: Mapping[str, ArrayLike], normal_load_n) -> AbstractFrictionLaw:
        """The friction law under ``normal_load_n`` [N] (``Fc = mu N``)."""
        return self.law.at_load(self.complete(v), normal_load_n)

    def coupling_of(self, v: Mapping[str, ArrayLike]) -> AbstractCoupling:
        return self.coupling.from_values(self.complete(v))

    def actuator_of(self, v: Mapping[str, ArrayLike]) -> AbstractActuator:
        return self.actuator.from_values(self.complete(v))

    def level_of(self, v: Mapping[str, ArrayLike]) -> AbstractLevelModel:
        return self.level.from_values(self.complete(v))

    def friction_ratios(self, v: Mapping[str, Array], load_n, alpha, speed_m_s) -> Array:
        """FR at operating points (arrays of equal shape) from physical values ``v``
        (notes §3, §5): the cycle-averaged contact at the coupling's amplitude, in the
        model's direction of vibration."""
        coupling = self.coupling_of(v)
        d = self.data

        def one(n, a, s):
            law = self.law_at(v, n)
            return on_friction_ratio(
                law,
                coupling,
                n,
                a,
                s,
                d.vibration_frequency_hz,
                d.max_amplitude_m,
                self.direction,
            )

        shape = jnp.shape(load_n)
        flat = (jnp.ravel(load_n), jnp.ravel(alpha), jnp.ravel(speed_m_s))
        return jax.vmap(one)(*flat).reshape(shape)

    def levels(self, v: Mapping[str, Array]) -> tuple[Array, Array, Array]:
        """Per trace: OFF level [N], ON level [N] and friction ratio. FR is solved once
        per distinct operating point and gathered."""
        d = self.data
        fr = self.friction_ratios(v, d.op_load_n, d.op_alpha, d.op_speed_m_s)[d.op_index]
        off = jax.vmap(lambda n, s: self.law_at(v, n).off_force_n(s))(
            jnp.asarray(d.normal_load_n), jnp.asarray(d.pull_speed_m_s)
        )
        return off, fr * off, fr

    def block_means(self, off_n: Array, on_n: Array, v: Mapping[str, Array]) -> Array:
        """Block-mean load-cell force [N] from per-trace OFF and ON levels.

        ``off_n`` and ``on_n`` are (traces, *batch); the per-trace nuisances in ``v``
        are (traces,) or (traces, *batch), the slopes () or (*batch). A batch (the
        sampler's walkers) is the last, fastest axis: every model point's time and
        nuisances are then read once for all walkers, 2.6x faster than a vmap.
        """
        d = self.data
        off_n, on_n = jnp.asarray(off_n), jnp.asarray(on_n)
        extra = off_n.ndim - 1

        def per_block(x):  # (traces, *b) -> (blocks, 1, *b)
            x = jnp.asarray(x)
            x = x.reshape(x.shape + (1,) * (1 + extra - x.ndim))
            return x[d.block_trace][:, None]

        timing = TraceTiming(
            startup_s=per_block(v["pull_start_s"]),
            on_start_s=per_block(_add_trailing(d.on_start_s, v["delay_on_s"], extra)),
            on_end_s=per_block(_add_trailing(d.on_end_s, v["delay_off_s"], extra)),
        )
        t = jnp.asarray(d.sub_time_s).reshape(d.sub_time_s.shape + (1,) * extra)
        actuator = self.actuator_of(v)
        start = jnp.asarray(d.sub_time_s)[jnp.asarray(d.first_block), 0]  # (traces,)
        offset = self.offset.offset_n(
            {g: per_block(v[g]) for g, _, _ in self.offset.trace_params}, t, per_block(start)
        )
        level = self.level.from_values(
            self.complete(v) | {g: per_block(v[g]) for g, _, _ in self.level.trace_params}
        )
        force = level.force_n(actuator, t, per_block(off_n), per_block(on_n), timing, offset)
        return force.mean(axis=1)

    def predict(self, z: Float[Array, " p"]) -> Float[Array, " blocks"]:
        """Block-mean load-cell force [N] for every block of every trace."""
        v = self.values(z)
        off, on, _ = self.levels(v)
        return self.block_means(off, on, v)

    def residuals(self, z: Float[Array, " p"], state: NoiseState | None = None) -> Array:
        """Residuals of the model whitened by its noise model at the correlation
        ``state`` (:meth:`AbstractNoise.whiten`; default: uncorrelated); 0 at padded
        blocks (:meth:`FitData.padded`)."""
        d = self.data
        at = self.noise.initial_state() if state is None else state
        w = self.noise.whiten(self.predict(z) - d.force_n, jnp.asarray(d.first), at)
        return w * jnp.asarray(d.block_weight)

    def level_residuals(
        self, u: Float[Array, " q"], z: Float[Array, " p"], state: NoiseState
    ) -> Float[Array, " blocks"]:
        """Whitened residuals with the per-trace levels given: ``u = (OFF, ON, z[k:])``
        ([N], [N], then the bench parameters of ``z``; ``z[:k]`` is not used)."""
        k, m = self.n_physical, self.data.n_traces
        v = self.values(jnp.concatenate([z[:k], u[2 * m :]]))
        e = self.block_means(u[:m], u[m : 2 * m], v) - self.data.force_n
        # 0 at padded blocks (FitData.padded): no residual, no Jacobian row
        w = self.noise.whiten(e, jnp.asarray(self.data.first), state)
        return w * jnp.asarray(self.data.block_weight)


def shared_params_of(
    law: type[AbstractFrictionLaw],
    coupling: type[AbstractCoupling],
    actuator: type[AbstractActuator],
    settings: tuple[ParameterSetting, ...] = (),
    level: type[AbstractLevelModel] | None = None,
) -> tuple[Param, ...]:
    """The shared parameters of a law, coupling, actuator and level model, in ``z``'s
    order; ``settings`` applied (the fixed ones left out)."""
    level_params = level.fit_params if level is not None else ()
    every = (*law.fit_params, MU, *coupling.fit_params, *actuator.fit_params, *level_params)
    return apply_settings(every, settings) if settings else every


def _trace_groups(
    offset: type[AbstractOffset], level: type[AbstractLevelModel]
) -> tuple[tuple[str, str, float], ...]:
    return (*offset.trace_params, *TRACE_GROUPS, *level.trace_params)


def _add_trailing(per_trace: ArrayLike, shift: ArrayLike, extra: int) -> Array:
    """``per_trace + shift`` with ``per_trace`` (traces,) and ``shift`` (traces,) or
    (traces, *batch): the result carries ``extra`` trailing axes."""
    a = jnp.asarray(per_trace).reshape((-1,) + (1,) * extra)
    s = jnp.asarray(shift)
    return a + s.reshape(s.shape + (1,) * (1 + extra - s.ndim))


def bench_model(
    data: FitData,
    law: str | type[AbstractFrictionLaw] = "dahl",
    coupling: str | type[AbstractCoupling] = DEFAULT_COUPLING,
    noise: str | type[AbstractNoise] = DEFAULT_NOISE,
    actuator: str | type[AbstractActuator] = DEFAULT_ACTUATOR,
    offset: str | type[AbstractOffset] = DEFAULT_OFFSET,
    settings: tuple[ParameterSetting, ...] = (),
    level: str | type[AbstractLevelModel] = DEFAULT_LEVEL_MODEL,
    direction: str | type[AbstractDirection] = DEFAULT_DIRECTION,
) -> BenchModel:
    """The :class:`BenchModel` of prepared ``data``; laws and models by registered name
    or class; ``settings``: the user's fixed values, bounds, scales, starts and priors
    (:mod:`idtool._model._settings`; those naming parameters this model lacks are
    ignored); ``direction``: of the vibration (:data:`DIRECTIONS`).

    Raises:
        IdtoolError: a coupling law in which the contact loads the horn (``sdof``: it
            solves its balance with the along kernel) with another direction.

    The per-trace nuisances and ``mu`` and the slopes start from values read off the
    traces (:func:`idtool._data._blocks.start_values`), unless the user gives a start;
    the other shared parameters from their ``Param.start``.
    """
    law_cls = FRICTION_LAWS.get(law)
    coupling_cls = COUPLINGS.get(coupling)
    noise_cls = NOISE_MODELS.get(noise)
    actuator_cls = ACTUATORS.get(actuator)
    offset_cls = OFFSETS.get(offset)
    level_cls = LEVEL_MODELS.get(level)
    direction_cls = DIRECTIONS.get(direction)
    if direction_cls is not DIRECTIONS.get(DEFAULT_DIRECTION) and reacts_on_vibration(coupling_cls):
        raise IdtoolError(
            f"the {coupling_cls.name} coupling law solves the horn loaded by friction along "
            f"the sliding; with direction {direction_cls.name!r} choose another coupling law"
        )
    groups_of_trace = _trace_groups(offset_cls, level_cls)
    s = start_values(data)
    # the rig's values for the coupling (a transducer's), unless the user set them
    given = {x.name for x in settings}
    rig = coupling_cls.rig_settings(float(data.vibration_frequency_hz), data.transducer)
    settings = (*(x for x in rig if x.name not in given), *settings)
    shared = shared_params_of(law_cls, coupling_cls, actuator_cls, settings, level_cls)
    guess = {
        "mu": s.friction_coefficient,
        "slope_n_s": s.slope_n_s,
        "startup_slope_n_s": s.startup_slope_n_s,
    }
    # a start the user gives wins over the data's
    guess |= {x.name: x.nominal for x in settings if x.estimate and x.nominal is not None}
    start_z = np.array([p.internal(guess.get(p.name, p.start)) for p in shared])
    n = data.n_traces
    centres = {"offset_n": s.offset_n, "pull_start_s": s.pull_start_s}
    nuisance_centre = np.stack([centres.get(g, np.zeros(n)) for g, _, _ in groups_of_trace])
    return BenchModel(
        data=data,
        # device_put, not jnp.asarray: the same float64 arrays without compiling a
        # conversion program per shape in every process
        nuisance_centre=jax.device_put(nuisance_centre),
        start_z=jax.device_put(start_z),
        law=law_cls,
        coupling=coupling_cls,
        actuator=actuator_cls,
        noise=noise_cls(),
        offset=offset_cls,
        level=level_cls,
        settings=settings,
        direction=direction_cls,
    )
