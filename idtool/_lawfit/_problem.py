"""The least-squares problem of ``fit-law``: parameters, residuals, start values.

The parameters live on the internal scale of :class:`idtool._model._params.Param` (a
bounded ``log`` transform for each physical one), plus, for a law of finite stiffness,
the bristle force at the first sample as a fraction of the level there,
``fb0_fraction`` in (-1, 1) (a ``tanh`` nuisance: a measured series need not start at
rest), and the load cell's zero: an offset ``offset_n`` [N] and a linear drift
``drift_n`` [N over the record] added to the model's force (``linear`` nuisances: a
tared cell is off by a little, and warms over a long record; without them a drift of
5 noise sds over a presliding record moved Kt out of its interval on 2 of 3 series),
and, where the series asks for it, the load cell's lag ``sensor_lag_s``
(:mod:`idtool._lawfit._lag`: the friction force through a first-order sensor).
The residuals are ``(F_model - F_measured) / force_scale``, whitened by an AR(1)
coefficient ``phi`` when the noise asks for it (Prais-Winsten: the first residual scaled
by ``sqrt(1 - phi^2)``, then ``r_k - phi r_(k-1)``).
"""

from __future__ import annotations

import dataclasses
import functools
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from idtool._data._series import Series
from idtool._errors import IdtoolError
from idtool._lawfit._lag import LAG
from idtool._model._params import Param
from idtool._model._series_force import output_force, series_force
from idtool._model._series_law import SIGMA1, SIGMA2, SeriesLaw, scale_of, scaled, series_law

__all__ = [
    "DRIFT",
    "FB0",
    "OFFSET",
    "Data",
    "Model",
    "Problem",
    "batch_loss",
    "make_problem",
    "start_grid",
    "whiten",
]

FB0 = Param(
    "fb0_fraction",
    "1",
    "tanh",
    -1.0,
    1.0,
    start=0.0,
    description="bristle force at the first sample over the level there",
)
# the load cell's zero: declared in units of the series' force scale (scale_of)
OFFSET = Param(
    "offset_n", "N", "linear", centre=0.0, scale=1.0, start=0.0,
    description="load-cell offset added to the force",
)  # fmt: skip
DRIFT = Param(
    "drift_n", "N", "linear", centre=0.0, scale=1.0, start=0.0,
    description="load-cell drift over the record, linear in time",
)  # fmt: skip
_Z_START = 3.0  # |z| of a start at most: 95% of the way to a bound
SUBSTEPS = 4  # parts per sample interval: LuGre's error 3.6e-6 N of 1.25 N at 1 kHz


class Data(NamedTuple):
    """The series as JAX arrays (the compiled programs' dynamic arguments).

    Attributes:
        time_s, velocity_m_s, normal_load_n (1 N without a load), force_n: (n,).
        interval_velocity_m_s: (n-1,) ``diff(x) / diff(t)`` of a displacement series
            (zeros for a velocity series: unused).
        force_scale_n: the residuals' unit [N].
        scales: (p,) factors from the declared to the SI values (:func:`scale_of`).
    """

    time_s: jax.Array
    velocity_m_s: jax.Array
    normal_load_n: jax.Array
    force_n: jax.Array
    interval_velocity_m_s: jax.Array
    force_scale_n: jax.Array
    scales: jax.Array


@dataclasses.dataclass(frozen=True)
class Model:
    """What a compiled program depends on (hashable, static): the law, the parameters
    as declared, and whether the slip comes as displacements."""

    law: SeriesLaw
    params: tuple[Param, ...]
    displacement_input: bool

    @property
    def n_physical(self) -> int:
        return len(self.law.params)

    def values(self, data: Data, z):
        """Parameter values by name [SI] at internal ``z``."""
        return {p.name: data.scales[k] * p.value(z[k]) for k, p in enumerate(self.params)}

    @property
    def lagged(self) -> bool:
        return any(p.name == LAG.name for p in self.params)

    @property
    def state_index(self) -> tuple[int, ...]:
        """The parameters the integrated state depends on (:meth:`state`): not the load
        cell's zero, nor, without a lag, the damping and viscous terms, which enter the
        output equation only (paper eq. 3)."""
        outside = {OFFSET.name, DRIFT.name}
        if not self.lagged:
            outside |= {SIGMA1.name, SIGMA2.name}
        return tuple(k for k, p in enumerate(self.params) if p.name not in outside)

    def state(self, data: Data, z):
        """The integrated state at the samples: the bristle force [N], or with the lag the
        recorded force [N] (without the load cell's zero)."""
        values = self.values(data, z)
        law_values = {k: values[k] for k in self.law.names}
        v, load = data.velocity_m_s, data.normal_load_n
        fb0 = 0.0
        if FB0.name in values:
            fb0 = values[FB0.name] * self.law.law_at(law_values, load[0]).level_n(v[0])
        force, bristle = series_force(
            self.law.law_at,
            law_values,
            data.time_s,
            v,
            load,
            fb0,
            interval_velocity_m_s=data.interval_velocity_m_s if self.displacement_input else None,
            extra_viscous_n_s_m=self.law.extra_viscous_n_s_m(law_values),
            substeps=SUBSTEPS,
            lag_s=values.get(LAG.name),
        )
        return force if self.lagged else bristle

    def output(self, data: Data, z, state):
        """The force [N] at the samples from the :meth:`state` (friction, paper eq. 3,
        plus the load cell's zero)."""
        values = self.values(data, z)
        force = state
        if not self.lagged:
            law_values = {k: values[k] for k in self.law.names}
            force = output_force(
                self.law.law_at,
                law_values,
                data.velocity_m_s,
                data.normal_load_n,
                state,
                self.law.extra_viscous_n_s_m(law_values),
            )
        t = data.time_s
        zero = values[OFFSET.name] + values[DRIFT.name] * (t - t[0]) / (t[-1] - t[0])
        return force + zero

    def force(self, data: Data, z):
        """Force [N] (friction plus the load cell's zero) at the samples, at internal
        ``z``."""
        return self.output(data, z, self.state(data, z))

    def residuals(self, data: Data, z, phi=0.0):
        """Scaled (and whitened) residuals ``(F_model - F) / force_scale``."""
        return whiten((self.force(data, z) - data.force_n) / data.force_scale_n, phi)

    def linearised(self, data: Data, z, phi=0.0):
        """:meth:`residuals` and their Jacobian in ``z`` (n, p): forward mode through the
        integration in the :attr:`state_index` parameters only (5 of LuGre's 9 without
        a lag), then through the output equation in all, by the chain rule (the state
        linear in them about ``z``)."""
        idx = np.array(self.state_index)

        def state(zs):
            x = self.state(data, z.at[idx].set(zs))
            return x, x

        ds, s = jax.jacfwd(state, has_aux=True)(z[idx])

        def resid(zz):
            x = s + ds @ (zz[idx] - z[idx])
            return whiten((self.output(data, zz, x) - data.force_n) / data.force_scale_n, phi)

        return resid(z), jax.jacfwd(resid)(z)


@dataclasses.dataclass(frozen=True)
class Problem:
    """A series and a law, ready to fit.

    Attributes:
        series: the data.
        model: the static part (law, declared parameters).
        data: the dynamic part (arrays).
        params: the parameters in SI units (declared ones times their scale), for
            reports.
        force_scale_n: 99th percentile of |F| [N]: residuals are in its units.
        velocity_scale_m_s: 99th percentile of |V| [m/s].
    """

    series: Series
    model: Model
    data: Data
    params: tuple[Param, ...]
    force_scale_n: float
    velocity_scale_m_s: float

    @property
    def law(self) -> SeriesLaw:
        return self.model.law

    @property
    def n_physical(self) -> int:
        return self.model.n_physical


def whiten(r, phi):
    """AR(1) innovations of ``r`` (Prais-Winsten), or ``r`` itself for ``phi = 0``."""
    first = r[:1] * jnp.sqrt(1.0 - phi**2)
    return jnp.concatenate([first, r[1:] - phi * r[:-1]])


def make_problem(series: Series, law: str, *, lag: bool = False) -> Problem:
    """The problem of fitting ``law`` to ``series`` (with the load cell's lag, last,
    where ``lag``)."""
    v = series.velocity()
    f_scale = float(np.percentile(np.abs(series.force_n), 99))
    v_scale = float(np.percentile(np.abs(v), 99))
    if not (f_scale > 0 and v_scale > 0):
        raise IdtoolError(f"{series.source}: the series has no force or no motion")
    spec = series_law(law, with_load=series.normal_load_n is not None)
    starts = {p.name: p.start for p in spec.params}
    rigid = not np.isfinite(float(spec.law_at(starts, 1.0).stiffness_n_m()))
    declared = (*spec.params, *(() if rigid else (FB0,)), OFFSET, DRIFT, *((LAG,) if lag else ()))
    t = series.time_s
    dt = float(np.median(np.diff(t)))
    scales = np.array([dt if p is LAG else scale_of(p.name, f_scale, v_scale) for p in declared])
    load = np.ones_like(t) if series.normal_load_n is None else series.normal_load_n
    iv = (
        np.zeros(t.size - 1)
        if series.velocity_m_s is not None
        else np.diff(np.asarray(series.displacement_m)) / np.diff(t)
    )
    data = Data(*(jnp.asarray(a, float) for a in (t, v, load, series.force_n, iv, f_scale, scales)))
    model = Model(spec, declared, series.velocity_m_s is None)
    params = tuple(scaled(p, float(c)) for p, c in zip(declared, scales, strict=True))
    return Problem(series, model, data, params, f_scale, v_scale)


def start_grid(problem: Problem) -> np.ndarray:
    """Internal start vectors (rows) spread over the decades a series cannot tell apart
    before fitting: the level (0.7, 1.5, 4 x the force scale), the presliding length
    ``Fc / Kt`` (1e-3 to 1 of the slip's range), the Stribeck velocity (0.03 to 1 of
    the velocity scale); every other parameter at its ``start``."""
    s = problem.series
    x = s.displacement()
    x_range = float(np.ptp(x)) or 1e-9
    load = 1.0 if s.normal_load_n is None else float(np.mean(s.normal_load_n))
    names = [p.name for p in problem.params]
    base = {p.name: p.start for p in problem.params}
    levels = [0.7, 1.5, 4.0]
    lengths = np.logspace(-3, 0, 7) * x_range if "Kt" in names else [None]
    speeds = [0.03, 0.1, 0.3, 1.0] if "stribeck_velocity_m_s" in names else [None]
    rows = []
    for a in levels:
        fc = a * problem.force_scale_n
        for length in lengths:
            for b in speeds:
                values = dict(base)
                values["Fc" if "Fc" in names else "mu"] = fc if "Fc" in names else fc / load
                if length is not None:
                    values["Kt"] = fc / length
                if b is not None:
                    values["stribeck_velocity_m_s"] = b * problem.velocity_scale_m_s
                rows.append([p.internal(values[p.name]) for p in problem.params])
    # inside the ranges: a start in a sigmoid's flat tail (a value at or beyond a bound)
    # never moves
    return np.clip(np.array(rows), -_Z_START, _Z_START)


@functools.partial(jax.jit, static_argnums=0)
def batch_loss(model: Model, data: Data, z):
    """Sum of squared scaled residuals at each row of ``z``."""
    return jax.vmap(lambda zz: jnp.sum(model.residuals(data, zz) ** 2))(z)
