"""The physical model of a steady-state friction table: the bench model's physics at
the table's conditions, nothing of its own.

Per row ``i`` of a :class:`~idtool._data._levels.LevelsTable`, the log levels

    log OFF_i = log F_off(theta; N_i, v_i)        (force; minus log N_i for a coefficient)
    log FR_i  = log FR(theta; N_i, alpha_i, v_i, f_i)

with ``F_off`` the registered friction law's OFF force at ``Fc = mu N``
(:meth:`AbstractFrictionLaw.off_force_n`) and ``FR`` :func:`idtool.on_friction_ratio`:
the registered coupling law's slip amplitude and the direction's cycle average, as
:meth:`idtool.BenchModel.friction_ratios` computes them for a trace dataset (here the
frequency may differ per row). ``alpha_i`` is the row's amplitude over
:attr:`LevelsTable.reference_amplitude_m`. ``theta`` are the law's parameters, ``mu``
and the coupling's, on the internal unbounded scale of :class:`idtool.Param`, in that
order (:func:`idtool._model._benchmodel.shared_params_of` without the bench's own).

A table that records when each row was measured (:attr:`LevelsTable.has_times`) adds
one bench parameter at the end of ``theta``, :data:`HORN_DRIFT` ``d``: the horn's output
(the slip amplitude per command) drifts linearly over the campaign, and row ``i`` is
taken at

    a_i = (1 + d tau_i) a(alpha_i, N_i),   tau_i = (t_i - t_mid) / (t_last - t_first)

(:attr:`LevelsTable.campaign_position`, in [-1/2, 1/2]). Every registered table
coupling's amplitude is proportional to the reference amplitude, so the drift scales
that. A worn sonotrode face or a creeping clamp shifts each row's FR by its sensitivity
to the amplitude; rows measured in a random order then average different drifts at each
condition, a condition effect that lines up with Kt's weak signature (issue 30's
"gain-drift" bench: transverse Kt inside its interval on 5 of 8 tables without the
times). The estimates and every prediction are at the campaign's middle (``tau = 0``).
"""

from __future__ import annotations

import dataclasses
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array

from idtool._data._levels import LevelsTable
from idtool._errors import IdtoolError
from idtool._model._bench import on_friction_ratio
from idtool._model._coupling import COUPLINGS, reacts_on_vibration
from idtool._model._directions import DIRECTIONS
from idtool._model._laws import FRICTION_LAWS, MU
from idtool._model._names import DEFAULT_COUPLING, DEFAULT_DIRECTION
from idtool._model._params import Param

__all__ = [
    "DEFAULT_LAW",
    "HORN_DRIFT",
    "LevelsData",
    "LevelsModel",
    "LevelsSpec",
    "fr_points",
    "levels_model",
    "log_levels",
    "log_off",
]

DEFAULT_LAW = "dahl"  # as idtool.fit's

HORN_DRIFT = Param(
    "horn_drift",
    "1",
    "tanh",
    -0.9,
    0.9,
    start=0.0,
    description=(
        "relative change of the horn's output (slip amplitude per command) from the "
        "campaign's first measurement to its last (module docstring)"
    ),
)


@dataclasses.dataclass(frozen=True)
class LevelsSpec:
    """The registered classes of a table's model: the static part of its compiled
    programs, equal by value, so tables of one shape and model share them."""

    law: Any
    coupling: Any
    direction: Any
    drift: bool = False  # the table records its rows' times: HORN_DRIFT is fitted

    @property
    def params(self) -> tuple[Param, ...]:
        drift = (HORN_DRIFT,) if self.drift else ()
        return (*self.law.fit_params, MU, *self.coupling.fit_params, *drift)


class LevelsData(eqx.Module):
    """A table's numbers the programs read, as arguments (not constants compiled in):
    per condition ``n`` [N], ``alpha`` (fraction of ``a_ref``), ``v`` [m/s], ``f`` [Hz];
    per row ``row_n`` [N], ``row_v`` [m/s], ``gather`` (its condition) and ``row_tau``
    (its place in the campaign, :attr:`LevelsTable.campaign_position`); ``a_ref`` [m];
    ``coefficient`` 1.0 where the table gives friction coefficients."""

    n: Array
    alpha: Array
    v: Array
    f: Array
    row_n: Array
    row_v: Array
    gather: Array
    row_tau: Array
    a_ref: Array
    coefficient: Array


def _values(spec: LevelsSpec, theta) -> dict[str, Any]:
    return {p.name: p.value(theta[i]) for i, p in enumerate(spec.params)}


def fr_points(spec: LevelsSpec, a_ref, theta, n, alpha, v, f):
    """FR at points ``(n [N], alpha, v [m/s], f [Hz])`` (arrays of one shape)."""
    shape = jnp.shape(n)
    flat = [jnp.ravel(jnp.asarray(x, float)) for x in (n, alpha, v, f)]
    a_refs = jnp.full(flat[0].shape, a_ref, float)
    return _fr_rows(spec, a_refs, theta, *flat).reshape(shape)


def log_off(spec: LevelsSpec, data: LevelsData, vals: dict[str, Any]):
    """Log OFF level of every row (n,): force [N], or coefficient (minus log N)."""
    off = jax.vmap(lambda n, v: spec.law.at_load(vals, n).off_force_n(v))(data.row_n, data.row_v)
    return jnp.log(off) - data.coefficient * jnp.log(data.row_n)


def log_levels(spec: LevelsSpec, data: LevelsData, theta):
    """Log OFF of every row, then log FR (2 n,): the module docstring's equations."""
    if spec.drift:
        # each row at its own slip amplitude: the drift scales the reference amplitude
        a_row = data.a_ref * (1.0 + _values(spec, theta)[HORN_DRIFT.name] * data.row_tau)
        g = data.gather
        fr = _fr_rows(spec, a_row, theta, data.n[g], data.alpha[g], data.v[g], data.f[g])
    else:
        fr = fr_points(spec, data.a_ref, theta, data.n, data.alpha, data.v, data.f)
        fr = fr[data.gather]
    return jnp.concatenate([log_off(spec, data, _values(spec, theta)), jnp.log(fr)])


def _fr_rows(spec: LevelsSpec, a_ref, theta, n, alpha, v, f):
    """FR at points with a reference amplitude of each their own (arrays of one shape)."""
    vals = _values(spec, theta)
    cpl = spec.coupling.from_values(vals)

    def one(a1, n1, al1, v1, f1):
        law_n = spec.law.at_load(vals, n1)
        return on_friction_ratio(law_n, cpl, n1, al1, v1, f1, a1, spec.direction)

    return jax.vmap(one)(a_ref, n, alpha, v, f)


# compiled once per model and shape, for every table (they were closures over each
# table's numbers: a new program for every table and every fit of one; 2.3 of a 4.3 s
# table fit, and 5 sampler programs in one test, tests/test_levels_sample.py)
_log_levels = jax.jit(log_levels, static_argnums=0)
_jacobian = jax.jit(jax.jacfwd(log_levels, argnums=2), static_argnums=0)
_fr_at = jax.jit(fr_points, static_argnums=0)


@dataclasses.dataclass(frozen=True, eq=False)
class LevelsModel:
    """The log levels of a table's rows as functions of ``theta`` (module docstring).

    Attributes:
        table: the data.
        spec: the registered law, coupling law and direction.
        data: the table's numbers, as the programs read them.
    """

    table: LevelsTable
    spec: LevelsSpec
    data: LevelsData

    @property
    def law(self) -> str:
        return self.spec.law.name

    @property
    def coupling(self) -> str:
        return self.spec.coupling.name

    @property
    def direction(self) -> str:
        return self.spec.direction.name

    @property
    def params(self) -> tuple[Param, ...]:
        """The physical parameters, in ``theta``'s order."""
        return self.spec.params

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(p.name for p in self.params)

    def log_levels(self, theta) -> Array:
        """``theta -> (2 n,)``: log OFF of every row, then log FR (compiled)."""
        return _log_levels(self.spec, self.data, theta)

    def jacobian(self, theta) -> Array:
        """``theta -> (2 n, k)``: :meth:`log_levels`' Jacobian (forward mode, compiled)."""
        return _jacobian(self.spec, self.data, theta)

    def fr_at(self, theta, load_n, alpha, speed_m_s, frequency_hz) -> Array:
        """FR at any points (arrays of one shape; compiled)."""
        return _fr_at(self.spec, self.data.a_ref, theta, load_n, alpha, speed_m_s, frequency_hz)

    def values(self, theta) -> dict[str, Any]:
        """Physical values by name from internal ``theta``."""
        return {p.name: p.value(theta[i]) for i, p in enumerate(self.params)}

    def internal(self, **values: float) -> np.ndarray:
        """Internal ``theta`` from physical values by name (every parameter)."""
        return np.array([p.internal(values[p.name]) for p in self.params])


def levels_model(
    table: LevelsTable,
    law: str = DEFAULT_LAW,
    coupling: str = DEFAULT_COUPLING,
    direction: str = DEFAULT_DIRECTION,
) -> LevelsModel:
    """The :class:`LevelsModel` of ``table`` with registered laws by name.

    Raises:
        IdtoolError: an unknown name, or a coupling law in which the contact loads the
            horn (``sdof``: it needs the transducer's modal data, which a table lacks).
    """
    law_cls = FRICTION_LAWS.get(law)
    coupling_cls = COUPLINGS.get(coupling)
    direction_cls = DIRECTIONS.get(direction)
    if reacts_on_vibration(coupling_cls):
        raise IdtoolError(
            f"the {coupling} coupling law models the horn's transducer, which a friction "
            "table does not describe: choose another coupling law"
        )
    index, first = table.operating_points
    data = LevelsData(
        n=jnp.asarray(table.normal_load_n[first], float),
        alpha=jnp.asarray(table.alpha[first], float),
        v=jnp.asarray(table.sliding_speed_m_s[first], float),
        f=jnp.asarray(table.vibration_frequency_hz[first], float),
        row_n=jnp.asarray(table.normal_load_n, float),
        row_v=jnp.asarray(table.sliding_speed_m_s, float),
        gather=jnp.asarray(index),
        row_tau=jnp.asarray(table.campaign_position, float),
        a_ref=jnp.asarray(table.reference_amplitude_m, float),
        coefficient=jnp.asarray(1.0 if table.friction == "coefficient" else 0.0),
    )
    spec = LevelsSpec(law_cls, coupling_cls, direction_cls, drift=table.has_times)
    return LevelsModel(table=table, spec=spec, data=data)
