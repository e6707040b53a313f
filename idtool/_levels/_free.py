"""The coupling law's shape checked against free slip amplitudes (a table fit's
law-free check of Kt).

A table fit reads Kt through the coupling law: at one speed, the friction ratio's fall
with the amplitude and the load is what the law's shape and Kt make of it together, so
a horn whose slip amplitude grows with the command in a way no registered law has moves
Kt out of its interval (a sublinear coupling: 0-3 of 8 simulated tables covered;
``benchmarks/study_benches.py``). A load and amplitude measured at two or more speeds
carry information on Kt that needs no law: at one slip amplitude the speed sets the
velocity ratio, and how FR changes with it depends on Kt (notes §3).

The law-free model gives each load-amplitude point ``j`` (with its frequency) a slip
amplitude of its own, ``a_j = g_j alpha_j A_ref`` with ``g_j`` free in the constant
law's range, and shares the friction law's parameters and mu: it nests every coupling
law (each is one choice of the ``g_j``); a table with its rows' times keeps the law's
horn drift (:data:`idtool._levels._model.HORN_DRIFT`, last). Fitted by the table fit's own stages
(:func:`idtool._levels._estimate.estimate`, started from the law's optimum, so its
likelihood is at least the law's), it gives

* the likelihood-ratio statistic ``-2 log(L_law / L_free)`` at the sds each estimated,
  ``q`` = points - the law's parameters more in the free model; its small-sample form
  ``F = statistic / q`` against Fisher's F with ``(q, r)`` degrees of freedom, ``r`` the
  conditions the free model leaves (conditions - points - the friction law's
  parameters), since the discrepancy sd is estimated from those few (chi-squared with
  ``q``, on 12 simulated tables that follow the law, rejected 2 at 5%; one less with
  the horn drift): small ``p`` is a
  table that rejects the law's shape;
* the friction law's parameters' law-free profile intervals: where the test rejects
  (``p <`` :data:`LEVEL`), :func:`idtool.fit_levels` widens each of those parameters'
  interval to hold the law-free one (on the simulated tables above, Kt's law-free
  interval held the truth where the law's missed; mostly one-sided, an upper bound:
  what the speeds alone say).
"""

from __future__ import annotations

import dataclasses
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
import scipy.stats

from idtool._lawfit._profile import Side
from idtool._levels._estimate import Optimum, estimate, profile_sides
from idtool._levels._model import HORN_DRIFT, LevelsData, LevelsModel, LevelsSpec, log_off
from idtool._model._bench import on_friction_ratio
from idtool._model._coupling import COUPLINGS, GAIN
from idtool._model._params import Param

__all__ = ["LEVEL", "CouplingCheck", "FreeAmplitudeModel", "check_coupling", "free_model"]

LEVEL = 0.05  # the test's level: a table that rejects the law's shape at 5%


def _free_log_levels(spec: LevelsSpec, data: LevelsData, point, theta):
    """Log OFF of every row, then log FR, with each condition's slip gain
    ``theta[k + point]`` (``k``: the friction law's parameters and mu), and each row's
    reference amplitude drifted by ``theta[-1]`` when the spec has the drift."""
    k = len(spec.law.fit_params) + 1
    vals = {p.name: p.value(theta[i]) for i, p in enumerate(spec.params[:k])}
    gains = GAIN.value(theta[k : theta.shape[0] - int(spec.drift)])[point]
    constant = COUPLINGS.get("constant")

    def one(n1, a1, v1, f1, g1, ref):
        law_n = spec.law.at_load(vals, n1)
        return on_friction_ratio(law_n, constant(gain=g1), n1, a1, v1, f1, ref, spec.direction)

    d, g = data, data.gather
    if spec.drift:  # each row at its own reference amplitude (the law's model, too)
        a_row = d.a_ref * (1.0 + HORN_DRIFT.value(theta[-1]) * d.row_tau)
        fr = jax.vmap(one)(d.n[g], d.alpha[g], d.v[g], d.f[g], gains[g], a_row)
    else:
        a_ref = jnp.full(d.n.shape, d.a_ref)
        fr = jax.vmap(one)(d.n, d.alpha, d.v, d.f, gains, a_ref)[g]
    return jnp.concatenate([log_off(spec, data, vals), jnp.log(fr)])


# compiled once per model and shape, as the law's (idtool._levels._model)
_log_levels = jax.jit(_free_log_levels, static_argnums=0)
_jacobian = jax.jit(jax.jacfwd(_free_log_levels, argnums=3), static_argnums=0)


@dataclasses.dataclass(frozen=True, eq=False)
class FreeAmplitudeModel:
    """A :class:`~idtool._levels._model.LevelsModel`'s table and friction law with a
    free slip gain per load-amplitude point (module docstring): the interface
    :func:`~idtool._levels._estimate.estimate` and ``profile_sides`` read.

    Attributes:
        table: the data.
        spec: the friction law, the constant coupling (its range) and the direction.
        data: the table's numbers, as the law's programs read them.
        point: each condition's load-amplitude point (conditions,).
        n_points: how many points.
    """

    table: Any
    spec: LevelsSpec
    data: LevelsData
    point: Any
    n_points: int

    @property
    def params(self) -> tuple[Param, ...]:
        """The friction law's parameters, mu, ``slip_gain[j]`` per point, then the horn
        drift if the table has its rows' times."""
        k = len(self.spec.law.fit_params) + 1
        gains = tuple(
            dataclasses.replace(
                GAIN,
                name=f"slip_gain[{j}]",
                description=f"slip amplitude per amplitude at load-amplitude point {j}",
            )
            for j in range(self.n_points)
        )
        return (*self.spec.params[:k], *gains, *((HORN_DRIFT,) if self.spec.drift else ()))

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(p.name for p in self.params)

    def log_levels(self, theta):
        return _log_levels(self.spec, self.data, self.point, jnp.asarray(theta))

    def jacobian(self, theta):
        return _jacobian(self.spec, self.data, self.point, jnp.asarray(theta))

    def internal(self, **values: float) -> np.ndarray:
        return np.array([p.internal(values[p.name]) for p in self.params])


def free_model(model: LevelsModel) -> FreeAmplitudeModel:
    """The law-free model of ``model``'s table (same friction law and direction)."""
    d = model.data
    keys: dict[tuple[float, float, float], int] = {}
    point = [
        keys.setdefault((float(n), float(a), float(f)), len(keys))
        for n, a, f in zip(np.asarray(d.n), np.asarray(d.alpha), np.asarray(d.f), strict=True)
    ]
    spec = LevelsSpec(
        model.spec.law, COUPLINGS.get("constant"), model.spec.direction, model.spec.drift
    )
    return FreeAmplitudeModel(model.table, spec, d, jnp.asarray(point), len(keys))


@dataclasses.dataclass(frozen=True)
class CouplingCheck:
    """The law's shape against free slip amplitudes (module docstring).

    Attributes:
        coupling: the coupling law checked.
        statistic: ``-2 log(L_law / L_free)`` (>= 0).
        dof: the free model's parameters more: points minus the law's parameters.
        residual_dof: conditions minus points minus the friction law's parameters.
        p_value: Fisher's F upper tail at ``statistic / dof`` on
            ``(dof, residual_dof)`` degrees of freedom.
        points: load-amplitude points of the table.
        resolved: of them, those measured at two or more speeds.
        free: the friction law's parameters' law-free interval sides (internal scale).
        widened: the parameters whose interval :func:`idtool.fit_levels` widened.
        law_sides: their sides before, the law's own (what its predictions read).
    """

    coupling: str
    statistic: float
    dof: int
    residual_dof: int
    p_value: float
    points: int
    resolved: int
    free: dict[str, tuple[Side, Side]]
    widened: tuple[str, ...] = ()
    law_sides: dict[str, tuple[Side, Side]] = dataclasses.field(default_factory=dict)

    @property
    def rejected(self) -> bool:
        return self.p_value < LEVEL

    def to_dict(self) -> dict[str, Any]:
        """``fit.json``'s ``coupling_check`` (sides as ``[z, wald rise, method]``)."""
        return {
            "coupling": self.coupling,
            "statistic": self.statistic,
            "dof": self.dof,
            "residual_dof": self.residual_dof,
            "p_value": self.p_value,
            "points": self.points,
            "resolved": self.resolved,
            "rejected": self.rejected,
            "free_sides": {n: [side.to_json() for side in sides] for n, sides in self.free.items()},
            "widened": list(self.widened),
            "law_sides": {
                n: [side.to_json() for side in sides] for n, sides in self.law_sides.items()
            },
        }

    @classmethod
    def from_dict(cls, doc: dict[str, Any]) -> CouplingCheck:
        def sides(entries: dict) -> dict[str, tuple[Side, Side]]:
            return {n: (Side.from_json(e[0]), Side.from_json(e[1])) for n, e in entries.items()}

        free, law = sides(doc["free_sides"]), sides(doc["law_sides"])
        return cls(
            str(doc["coupling"]), float(doc["statistic"]), int(doc["dof"]),
            int(doc["residual_dof"]), float(doc["p_value"]), int(doc["points"]),
            int(doc["resolved"]), free,
            tuple(str(n) for n in doc["widened"]), law,
        )  # fmt: skip


def check_coupling(model: LevelsModel, opt: Optimum, seed: int = 0) -> CouplingCheck | None:
    """Fit the law-free model of ``model``'s table from the law's optimum ``opt``, test
    the law's shape and profile the friction law's parameters (module docstring).
    None where the test has no degrees of freedom: no more points than the law has
    parameters, or no conditions left over (no point measured at two speeds)."""
    free = free_model(model)
    dof = free.n_points - len(model.spec.coupling.fit_params)
    residual = int(free.point.size) - free.n_points - len(model.spec.law.fit_params)
    residual -= int(model.spec.drift)  # the horn drift, fitted in both models
    if dof <= 0 or residual <= 0:
        return None
    # the law's slip gain at each point: the law-free model's start, where its
    # likelihood equals the law's (a random multi-start over a gain per point strays)
    values = model.values(opt.theta)
    d = model.data
    coupling = model.spec.coupling.from_values(values)
    amplitude = np.asarray(coupling.amplitude_m(d.alpha, d.n, d.a_ref))
    gain = np.empty(free.n_points)
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = amplitude / (np.asarray(d.alpha) * float(d.a_ref))
    gain[np.asarray(free.point)] = np.where(np.isfinite(ratio), ratio, GAIN.start)
    k = len(model.spec.law.fit_params) + 1
    start = np.concatenate(
        [
            np.asarray(opt.theta[:k]),
            [GAIN.internal(float(np.clip(g, GAIN.lo, GAIN.hi))) for g in gain],
            np.asarray(opt.theta[len(model.params) - int(model.spec.drift) :]),
        ]
    )
    fopt = estimate(free, seed=seed, starts=[start])
    statistic = max(2.0 * (fopt.loglik - opt.loglik), 0.0)
    p_value = float(scipy.stats.f.sf(statistic / dof, dof, residual))
    sides = {}
    for j, p in enumerate(model.spec.law.fit_params):
        lo, hi, _ = profile_sides(free, fopt, j)
        sides[p.name] = (lo, hi)
    t = model.table
    speeds: dict[int, set[float]] = {}
    _, first = t.operating_points
    for c, j in enumerate(np.asarray(free.point)):
        speeds.setdefault(int(j), set()).add(float(t.sliding_speed_m_s[first[c]]))
    resolved = sum(len(s) > 1 for s in speeds.values())
    return CouplingCheck(
        model.coupling, statistic, dof, residual, p_value, free.n_points, resolved, sides
    )
