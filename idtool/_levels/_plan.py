"""The next rows of a friction table: experimental design from a table fit (issue 30,
item 1: the trace planner's goals, :mod:`idtool._plan`, on a table's model).

The table's model linearised at the estimate, with the discrepancy of every condition
explicit (independent between conditions, as the fit has it,
:mod:`idtool._levels._estimate`): unknowns ``beta = (theta, d_1 .. d_C)`` over the
table's conditions, the targets' and the candidates', and

    log FR_r = g(theta; x_c(r)) + d_c(r) + e_r,   e_r ~ N(0, scatter_fr^2 + se_r^2)
    log OFF_r = g_off(theta; x_c(r)) + e'_r,      e'_r ~ N(0, scatter_mu^2 + se_r'^2)

with ``d_c ~ N(0, discrepancy_fr^2)``. The precision of ``beta`` is the table's rows'
``X^T E^-1 X`` plus the discrepancies' prior and a weak prior on ``theta`` (sd
:data:`THETA_PRIOR_SD` on the internal scale, the width of a parameter's range: a
direction the table does not inform gets a large, finite variance, not none). A new row
at condition ``c`` adds ``x x^T / (scatter_fr^2)`` with ``x = (dg/dtheta, e_c)``; its
OFF level is left out (mu is pinned by every row already: conservative).

Goals (their values after 0, 1, ... N rows):

* ``band``: the largest half-width of the 95% FR band at a new condition (what
  :meth:`~idtool.LevelsFit.predict` gives: the curve and a discrepancy) over the target
  conditions, ``FR_t sinh(1.96 sd_t)`` with ``sd_t^2 = h_t^T Sigma_theta h_t + s_d^2``,
  ``h_t = dg/dtheta`` at the target and ``Sigma_theta`` the theta block of
  ``Lambda^-1``: rows inform the parameters (rows at one condition share its
  discrepancy), and the band cannot fall below the discrepancy's own;
* ``parameters``: the largest relative sd of the physical parameters (delta method).

Rows chosen greedily (each the candidate that most lowers the goal with those before
it; a condition may be chosen again: a repeat), against a uniform choice of the same
number (the grid's conditions evenly by index). The sds are the fit's estimates, not
averaged over their uncertainty as the trace planner does: said in the notes.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence

import jax
import numpy as np

from idtool._errors import IdtoolError
from idtool._levels._model import LevelsModel

__all__ = ["GOALS", "THETA_PRIOR_SD", "LevelsPlan", "PlannedRow", "plan_rows"]

GOALS = ("band", "parameters")
THETA_PRIOR_SD = 7.0  # internal units: a bounded parameter's range (Z_AT_BOUND)
_Z95 = 1.959963984540054


@dataclasses.dataclass(frozen=True)
class PlannedRow:
    """One proposed measurement: its condition and the goal's value once it (and
    the rows ranked before it) is added."""

    rank: int
    normal_load_n: float
    amplitude_m: float
    vibration_frequency_hz: float
    sliding_speed_m_s: float
    value_after: float


@dataclasses.dataclass(frozen=True)
class LevelsPlan:
    """The next rows of a friction table for a goal (:func:`plan_rows`).

    Attributes:
        goal: ``band`` or ``parameters``; unit: what its value measures.
        target: the value sought (FR half-width, or relative sd).
        rows: the proposed rows, ranked.
        values: the goal's value after 0, 1, ... N of them (linearised).
        uniform: the same for a uniform choice of the candidates, of each size.
        rows_to_target: how many planned rows reach the target (None: not within N).
        at: the band goal's target conditions (load [N], amplitude [m], speed [m/s]).
        notes: the approximations taken.
    """

    goal: str
    unit: str
    target: float
    rows: tuple[PlannedRow, ...]
    values: tuple[float, ...]
    uniform: tuple[float, ...]
    rows_to_target: int | None
    at: tuple[tuple[float, float, float], ...]
    notes: tuple[str, ...]

    @property
    def met(self) -> bool:
        """Whether the goal's value now already meets its target."""
        return self.values[0] <= self.target

    def to_csv(self, friction: str = "force") -> str:
        """The operator's sheet: the columns ``idtool import-levels`` reads, one row per
        proposed measurement, OFF and ON left to fill in (force [N] or coefficient)."""
        unit = "N" if friction == "force" else "-"
        lines = [f"load (N),amplitude (um),frequency (kHz),speed (mm/s),off ({unit}),on ({unit})"]
        for r in self.rows:
            lines.append(
                f"{r.normal_load_n:.6g},{r.amplitude_m * 1e6:.6g},"
                f"{r.vibration_frequency_hz / 1e3:.6g},{r.sliding_speed_m_s * 1e3:.6g},,"
            )
        return "\n".join(lines) + "\n"

    def report(self) -> str:
        """A page a person can read: the rows, the goal's value after each, the
        uniform choice's beside it."""
        lines = [
            f"idtool plan of a friction table: goal {self.goal} ({self.unit}), target "
            f"{self.target:.4g}; now {self.values[0]:.4g}" + (" (met)" if self.met else ""),
        ]
        if self.at:
            where = "; ".join(
                f"{n:g} N, {a * 1e6:.3g} um, {v * 1e3:.4g} mm/s" for n, a, v in self.at
            )
            lines.append(f"at        {where}")
        lines += ["", "rank  load [N]  amplitude [um]  speed [mm/s]  value after  uniform"]
        for r, u in zip(self.rows, self.uniform[1:], strict=True):
            lines.append(
                f"{r.rank:4d}  {r.normal_load_n:8.4g}  {r.amplitude_m * 1e6:14.4g}  "
                f"{r.sliding_speed_m_s * 1e3:12.4g}  {r.value_after:11.4g}  {u:7.4g}"
            )
        reach = (
            f"{self.rows_to_target} planned row(s) reach the target"
            if self.rows_to_target is not None
            else f"the target is not reached within {len(self.rows)} rows"
        )
        lines += ["", reach, "", "Notes:", *(f"  - {x}" for x in self.notes)]
        return "\n".join(lines)


def _key(n: float, a: float, f: float, v: float) -> tuple[float, ...]:
    return tuple(round(float(x), 12) for x in (n, a * 1e9, f, v))


def plan_rows(
    model: LevelsModel,
    theta: np.ndarray,
    cov_rows: np.ndarray,
    sds: dict[str, float],
    goal: str = "band",
    n_rows: int = 6,
    *,
    at: Sequence[tuple[float, float, float]] | None = None,
    half_width: float = 0.01,
    rel: float = 0.05,
    loads_n: tuple[float, float] | None = None,
    amplitudes_m: tuple[float, float] | None = None,
    speeds_m_s: tuple[float, float] | None = None,
    grid: int = 5,
) -> LevelsPlan:
    """Plan ``n_rows`` measurements for ``goal`` (module docstring).

    Args:
        model, theta: the fit's model and estimate (internal scale).
        cov_rows: the table's rows' covariance without the discrepancy (2 n, 2 n):
            the measurement variance and the scatter.
        sds: the fit's relative sds by name.
        at: the band goal's targets, (load [N], amplitude [m], speed [m/s]) each.
        half_width, rel: the band goal's and the parameters goal's targets.
        loads_n, amplitudes_m, speeds_m_s: the candidates' ranges (low, high); default
            the table's; ``grid`` values of each (geometric), at the table's frequency.

    Raises:
        IdtoolError: an unknown goal, a band goal without targets, or a range that is
            not (low, high) with 0 < low <= high.
    """
    if goal not in GOALS:
        raise IdtoolError(f"goal {goal!r} on a table: choose one of {', '.join(GOALS)}")
    if n_rows < 1:
        raise IdtoolError(f"n_rows {n_rows}: give at least 1")
    t = model.table
    f0 = float(t.vibration_frequency_hz[0])
    if goal == "band" and not at:
        raise IdtoolError(
            "the band goal needs its conditions: at=[(load_n, amplitude_m, speed_m_s)]"
        )
    targets = [tuple(float(x) for x in p) for p in (at or ())]

    def axis(given, seen, name):
        lo, hi = given if given is not None else (float(np.min(seen)), float(np.max(seen)))
        if not (0 < lo <= hi and math.isfinite(hi)):
            raise IdtoolError(f"{name} {given!r}: give (low, high) with 0 < low <= high")
        return np.unique(np.geomspace(lo, hi, grid))

    # the grid, and the targets themselves
    cand = np.array(
        [
            (n, a, v)
            for n in axis(loads_n, t.normal_load_n, "loads_n")
            for a in axis(amplitudes_m, t.amplitude_m, "amplitudes_m")
            for v in axis(speeds_m_s, t.sliding_speed_m_s, "speeds_m_s")
        ]
        + [p for p in targets]
    )
    cand = cand[np.sort(np.unique(np.round(cand, 12), axis=0, return_index=True)[1])]
    # the table's conditions (their discrepancies are unknowns), then the candidates'
    # and the targets' points
    index, first = t.operating_points
    table_keys = {
        _key(t.normal_load_n[i], t.amplitude_m[i], t.vibration_frequency_hz[i],
             t.sliding_speed_m_s[i]): j
        for j, i in enumerate(first)
    }  # fmt: skip
    pts = np.array(
        [(t.normal_load_n[i], t.amplitude_m[i], t.vibration_frequency_hz[i],
          t.sliding_speed_m_s[i]) for i in first]
        + [(n, a, f0, v) for n, a, v in cand]
        + [(n, a, f0, v) for n, a, v in targets]
    )  # fmt: skip
    alpha = pts[:, 1] / t.reference_amplitude_m
    fr = np.asarray(model.fr_at(theta, pts[:, 0], alpha, pts[:, 3], pts[:, 2]))
    jac = np.asarray(jax.jacfwd(model.fr_at)(theta, pts[:, 0], alpha, pts[:, 3], pts[:, 2]))
    jl = jac / fr[:, None]  # d log FR / d theta, per point
    n_tab, n_cand = first.size, len(cand)
    h_cand, h_tgt = jl[n_tab : n_tab + n_cand], jl[n_tab + n_cand :]
    fr_tgt = fr[n_tab + n_cand :]
    k = theta.size

    # the table's rows: X (2 n, k + C), their precision E^-1, the priors
    n = t.n_rows
    x_rows = np.zeros((2 * n, k + n_tab))
    x_rows[:, :k] = np.asarray(model.jacobian(theta))
    x_rows[n + np.arange(n), k + index] = 1.0
    s_d = max(sds["discrepancy_fr"], 1e-6)
    info = x_rows.T @ np.linalg.solve(cov_rows, x_rows)
    info += np.diag(np.concatenate([np.full(k, THETA_PRIOR_SD**-2), np.full(n_tab, s_d**-2)]))
    cov = np.linalg.inv(info)
    # a new row's FR variance: the table's typical (its scatter and measurement
    # variance, the median over its FR rows); without repeats the scatter is inside
    # the discrepancy, and a repeat could be all scatter: the discrepancy's then
    noise = float(np.median(np.diag(cov_rows)[n:]))
    if sds["scatter_fr"] <= 0:
        noise = max(noise, s_d**2)
    noise = max(noise, 1e-12)
    # each candidate's discrepancy column in cov (-1: a condition without rows yet)
    column = np.array([table_keys.get(_key(a, b, f0, c), -1) for a, b, c in cand])
    # d(relative value)/dz: the parameters goal's precision relative to the value; a
    # parameter whose range reaches zero (the load-power law's exponent, which can be
    # negative: its log failed) taken in its own unit instead, as relative to 1
    dlog = np.array(
        [
            float(prm.slope(float(theta[j])))
            / (abs(float(prm.value(float(theta[j])))) if _positive(prm) else 1.0)
            for j, prm in enumerate(model.params)
        ]
    )

    def cov_x(cov: np.ndarray, column: np.ndarray):
        """``cov x`` (candidates, k + C) over the columns cov has, and ``x' cov x``: a
        candidate at a condition without rows adds a fresh discrepancy (variance s_d^2,
        independent of all), which enters ``x' cov x`` only."""
        cx = h_cand @ cov[:k, :]  # (candidates, k + C): cov[:, :k] h, cov symmetric
        has = column >= 0
        cx[has] += cov[:, k + column[has]].T
        quad = np.einsum("ij,ij->i", h_cand, cx[:, :k])
        quad += np.where(has, cx[np.arange(n_cand), k + np.maximum(column, 0)], s_d**2)
        return cx, quad

    def values_after(cov: np.ndarray, column: np.ndarray) -> np.ndarray:
        """The goal's value after one more row at each candidate (Sherman-Morrison)."""
        cx, quad = cov_x(cov, column)
        den = quad + noise
        ct = cx[:, :k]
        if goal == "band":
            q = np.einsum("tk,kl,tl->t", h_tgt, cov[:k, :k], h_tgt)[None, :] - (
                (ct @ h_tgt.T) ** 2 / den[:, None]
            )
            sd = np.sqrt(np.maximum(q, 0.0) + s_d**2)
            return np.max(fr_tgt[None, :] * np.sinh(_Z95 * sd), axis=1)
        var = np.diag(cov)[:k][None, :] - ct**2 / den[:, None]
        return np.max(np.abs(dlog)[None, :] * np.sqrt(np.maximum(var, 0.0)), axis=1)

    def value_now(cov: np.ndarray) -> float:
        if goal == "band":
            q = np.einsum("tk,kl,tl->t", h_tgt, cov[:k, :k], h_tgt)
            return float(np.max(fr_tgt * np.sinh(_Z95 * np.sqrt(np.maximum(q, 0) + s_d**2))))
        return float(np.max(np.abs(dlog) * np.sqrt(np.maximum(np.diag(cov)[:k], 0.0))))

    def add(cov: np.ndarray, column: np.ndarray, i: int):
        """``cov`` and the columns after a row at candidate ``i``: a fresh condition's
        discrepancy joins as a new column first."""
        if column[i] < 0:
            m = cov.shape[0]
            grown = np.zeros((m + 1, m + 1))
            grown[:m, :m] = cov
            grown[m, m] = s_d**2
            column = column.copy()
            column[i] = m - k  # the candidates are distinct: this one alone
            cov = grown
        x = np.zeros(cov.shape[0])
        x[:k] = h_cand[i]
        x[k + column[i]] = 1.0
        cx = cov @ x
        return cov - np.outer(cx, cx) / (noise + x @ cx), column

    values, chosen = [value_now(cov)], []
    state = (cov, column)
    for _ in range(n_rows):
        after = values_after(*state)
        best = int(np.argmin(after))
        chosen.append(best)
        state = add(*state, best)
        values.append(value_now(state[0]))
    uniform = [values[0]]
    for m in range(1, n_rows + 1):
        st = (cov, column)
        for i in np.unique(np.linspace(0, n_cand - 1, m).round().astype(int)):
            st = add(*st, int(i))
        uniform.append(value_now(st[0]))
    target = half_width if goal == "band" else rel
    reach = next((i for i, v in enumerate(values) if v <= target), None)
    rows = tuple(
        PlannedRow(
            r + 1, float(cand[i, 0]), float(cand[i, 1]), f0, float(cand[i, 2]), values[r + 1]
        )
        for r, i in enumerate(chosen)
    )
    signed = [p.name for p in model.params if not _positive(p)]
    notes = (
        *(
            [
                f"{', '.join(signed)}: its range reaches zero, so its sd is taken in its own "
                "unit (relative to 1), not relative to its value"
            ]
            if goal == "parameters" and signed
            else []
        ),
        "linearised at the fit's estimate; the sds at the fit's (the discrepancy's the "
        "one its bands use, integrated over its likelihood; the scatter's not averaged "
        "over its uncertainty, as the trace planner does)",
        "a new row's OFF level is left out (mu is pinned by the table already); its FR "
        "variance the table's median (scatter and standard errors), the discrepancy's "
        "where the table has no repeats",
        f"candidates: {len(cand)} conditions ({grid} loads x {grid} amplitudes x {grid} "
        f"speeds at most, geometric, and the targets) at {f0 / 1e3:g} kHz; a condition "
        "may be chosen again",
        "the band is the one predictions give at a new condition: the discrepancy's own "
        "width stays, the parameters' shrinks (rows at one condition share its "
        "discrepancy, independent between conditions)",
    )
    return LevelsPlan(
        goal=goal,
        unit="FR half-width" if goal == "band" else "relative sd",
        target=target,
        rows=rows,
        values=tuple(values),
        uniform=tuple(uniform),
        rows_to_target=reach,
        at=tuple((n, a, v) for n, a, v in targets),
        notes=notes,
    )


def _positive(param) -> bool:
    """A parameter whose range is positive (a relative sd means something)."""
    return param.kind == "log" or (param.kind == "tanh" and param.lo > 0.0)
