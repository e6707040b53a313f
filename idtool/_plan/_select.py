"""Batch selection of the next pulls: greedy, on the linearised model.

The greedy algorithm adds, N times, the candidate pull that most improves the goal
(:mod:`idtool._plan._goals`), updating the linear-Gaussian model after each (eq. P4 of
:mod:`idtool._plan._linear`); a candidate may be chosen again (a repeat). For the
``band`` and ``parameters`` goals the goal is a monotone function of a posterior
variance, and the variance reduction of a linear-Gaussian design is submodular in
favourable cases, where the greedy batch is within ``1 - 1/e`` of the best (Krause,
Singh & Guestrin 2008, JMLR 9, 235); ties go to the first candidate (deterministic).
The comparison design is a uniform grid of the same size over the candidates' loads and
amplitudes (:func:`uniform_batch`).
"""

from __future__ import annotations

import math

import numpy as np

from idtool._plan._goals import band_values, law_goal, parameter_values
from idtool._plan._linear import LinearLaw

__all__ = ["goal_value", "greedy", "uniform_batch", "value_after"]


def _better(goal: str) -> int:
    """+1 when higher is better (laws), -1 when lower is (band, parameters)."""
    return 1 if goal == "laws" else -1


def _add(goal: str, laws: list[LinearLaw], c: int) -> None:
    """Add pull ``c`` to every law's model; not for the laws goal, which takes the
    batch's joint predictive from the model before it (:func:`~idtool._plan._goals.
    law_goal`)."""
    if goal != "laws":
        for law in laws:
            law.add(c)


def goal_value(goal: str, laws: list[LinearLaw], next_pull: bool, batch: list[int]) -> float:
    """The goal's value on ``laws`` as they are (pulls of ``batch`` already added; the
    laws goal needs the batch itself, its joint predictive)."""
    if goal == "band":
        return float(band_values(laws, next_pull, after=False)[0])
    if goal == "parameters":
        return float(parameter_values(laws[0], after=False)[0][0])
    return law_goal(laws, batch)


def _candidate_values(goal: str, laws: list[LinearLaw], next_pull: bool, batch: list[int]):
    """The goal's value after adding each candidate to the current design (c,)."""
    if goal == "band":
        return band_values(laws, next_pull, after=True)
    if goal == "parameters":
        return parameter_values(laws[0], after=True)[0]
    n_c = laws[0].cand_rows.shape[0]
    return np.array([law_goal(laws, [*batch, c]) for c in range(n_c)])


def greedy(
    goal: str, laws: list[LinearLaw], n_pulls: int, next_pull: bool = False
) -> tuple[list[int], list[float], np.ndarray]:
    """The greedy batch of ``n_pulls`` candidate indices, the goal's value after each
    pull (``n_pulls + 1``, now first) and the first step's value of every candidate
    (c,): the ranking of single pulls. ``laws`` are copied, not changed."""
    work = [law.copy() for law in laws]
    batch: list[int] = []
    values = [goal_value(goal, work, next_pull, batch)]
    sign = _better(goal)
    first = np.array([])
    for step in range(n_pulls):
        after = _candidate_values(goal, work, next_pull, batch)
        if step == 0:
            first = after
        best = int(np.argmax(sign * after))
        batch.append(best)
        _add(goal, work, best)
        values.append(float(after[best]))
    return batch, values, first


def value_after(
    goal: str, laws: list[LinearLaw], batch: list[int], next_pull: bool = False
) -> list[float]:
    """The goal's value after each prefix of ``batch`` (``len(batch) + 1``, none first)."""
    work = [law.copy() for law in laws]
    values = [goal_value(goal, work, next_pull, [])]
    for j, c in enumerate(batch):
        _add(goal, work, c)
        values.append(goal_value(goal, work, next_pull, batch[: j + 1]))
    return values


def uniform_batch(n_loads: int, n_amplitudes: int, n_pulls: int) -> list[int]:
    """A uniform grid of ``n_pulls`` pulls over a candidate grid of ``n_loads`` x
    ``n_amplitudes`` (candidate ``i * n_amplitudes + j``: load ``i``, amplitude ``j``):
    about ``sqrt(n_pulls)`` evenly spaced levels of each (the grid's corners included),
    each point once, then again from the first, until there are ``n_pulls``."""
    nl = min(n_loads, max(1, math.ceil(math.sqrt(n_pulls))))
    na = min(n_amplitudes, max(1, math.ceil(n_pulls / nl)))
    li = np.unique(np.linspace(0, n_loads - 1, nl).round().astype(int))
    ai = np.unique(np.linspace(0, n_amplitudes - 1, na).round().astype(int))
    grid = [int(i * n_amplitudes + j) for i in li for j in ai]
    if len(grid) > n_pulls:  # evenly thinned
        grid = [grid[int(i)] for i in np.linspace(0, len(grid) - 1, n_pulls).round()]
    return [grid[i % len(grid)] for i in range(n_pulls)]
