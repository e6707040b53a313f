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
"""

from __future__ import annotations

import dataclasses
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from idtool._data._levels import LevelsTable
from idtool._errors import IdtoolError
from idtool._model._bench import on_friction_ratio
from idtool._model._coupling import COUPLINGS, reacts_on_vibration
from idtool._model._directions import DIRECTIONS
from idtool._model._laws import FRICTION_LAWS, MU
from idtool._model._names import DEFAULT_COUPLING, DEFAULT_DIRECTION
from idtool._model._params import Param

__all__ = ["DEFAULT_LAW", "LevelsModel", "levels_model"]

DEFAULT_LAW = "dahl"  # as idtool.fit's


@dataclasses.dataclass(frozen=True, eq=False)
class LevelsModel:
    """The log levels of a table's rows as functions of ``theta`` (module docstring).

    Attributes:
        table: the data.
        law, coupling, direction: registered names.
        params: the physical parameters, in ``theta``'s order.
        log_levels: ``theta -> (2 n,)``: log OFF of every row, then log FR (jitted).
        jacobian: ``theta -> (2 n, k)`` (forward mode, jitted).
        fr_at: ``(theta, load_n, alpha, speed_m_s, frequency_hz) -> FR`` at any points
            (arrays of one shape; jitted).
    """

    table: LevelsTable
    law: str
    coupling: str
    direction: str
    params: tuple[Param, ...]
    log_levels: Any
    jacobian: Any
    fr_at: Any

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(p.name for p in self.params)

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
    params = (*law_cls.fit_params, MU, *coupling_cls.fit_params)
    a_ref = table.reference_amplitude_m
    coefficient = table.friction == "coefficient"
    index, first = table.operating_points
    op = {
        "n": jnp.asarray(table.normal_load_n[first]),
        "alpha": jnp.asarray(table.alpha[first]),
        "v": jnp.asarray(table.sliding_speed_m_s[first]),
        "f": jnp.asarray(table.vibration_frequency_hz[first]),
    }
    row_n = jnp.asarray(table.normal_load_n)
    row_v = jnp.asarray(table.sliding_speed_m_s)
    gather = jnp.asarray(index)

    def values(theta):
        return {p.name: p.value(theta[i]) for i, p in enumerate(params)}

    def fr_points(theta, n, alpha, v, f):
        vals = values(theta)
        cpl = coupling_cls.from_values(vals)

        def one(n1, a1, v1, f1):
            law_n = law_cls.at_load(vals, n1)
            return on_friction_ratio(law_n, cpl, n1, a1, v1, f1, a_ref, direction_cls)

        shape = jnp.shape(n)
        flat = [jnp.ravel(jnp.asarray(x, float)) for x in (n, alpha, v, f)]
        return jax.vmap(one)(*flat).reshape(shape)

    def log_levels(theta):
        vals = values(theta)
        off = jax.vmap(lambda n, v: law_cls.at_load(vals, n).off_force_n(v))(row_n, row_v)
        log_off = jnp.log(off) - (jnp.log(row_n) if coefficient else 0.0)
        fr = fr_points(theta, op["n"], op["alpha"], op["v"], op["f"])[gather]
        return jnp.concatenate([log_off, jnp.log(fr)])

    return LevelsModel(
        table=table,
        law=law_cls.name,
        coupling=coupling_cls.name,
        direction=direction_cls.name,
        params=params,
        log_levels=jax.jit(log_levels),
        jacobian=jax.jit(jax.jacfwd(log_levels)),
        fr_at=jax.jit(fr_points),
    )
