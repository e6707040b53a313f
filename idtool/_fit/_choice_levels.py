"""The options of a model choice weighed by the levels model's likelihood, which carries
the pull-to-pull scatter and the operating points' discrepancy
(:mod:`idtool._fit._variability`).

The trace-level likelihood takes each trace's OFF and ON levels as known to their block
noise. With pull-to-pull scatter (a few % of FR from pull to pull) it reads the scatter
as signal: on a scatter bench its BIC told the coupling laws apart about 100 times more
decisively than the levels model's (differences of 1,475-6,653 against 17-75), and on
the laws study of issue 29 (20 truths drawn from a scatter bench's fit) the true law held
a trace-level weight of 0.000 on the existing pulls in 5 of the 20 (its Kt then read
through a wrong law at weight 1).

What the coupling law and the direction of vibration say about the data is the friction
ratio of each operating point, i.e. the levels. Between the options of those choices
the criterion is therefore the levels model's: the ML log-likelihood of one set of free
levels (the best trace-level candidate's, so that every option is scored on the same
data) at the option's physical parameters and REML sds (``Variability.loglik``), with
BIC's penalty of its physical parameters and sds on the number of levels. Within an
option the actuator, offset and level models (what the traces show between and around
their levels) stay chosen by the trace-level BIC.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Mapping

import numpy as np

from idtool._fit._free_levels import free_levels
from idtool._fit._result import FitResult
from idtool._fit._variability import NoMeasuredLevels, estimate_variability

__all__ = ["LevelsCriterion", "levels_criteria", "option_bests"]


@dataclasses.dataclass(frozen=True)
class LevelsCriterion:
    """An option's standing under the levels model: ``loglik`` (ML at the REML sds, on
    the shared free levels), ``n_levels`` (the free levels' rows: OFF levels and measured
    friction ratios) and ``n_params`` (physical parameters and sds fitted to them)."""

    loglik: float
    n_levels: int
    n_params: int

    @property
    def bic(self) -> float:
        return self.n_params * math.log(self.n_levels) - 2.0 * self.loglik

    @property
    def aic(self) -> float:
        return 2.0 * self.n_params - 2.0 * self.loglik


def option_bests(candidates: Mapping[str, FitResult], of: Callable[[FitResult], str]) -> dict:
    """Per option ``of`` a candidate, the key of its best candidate by the trace-level
    BIC (the other parts of the model chosen for it)."""
    best: dict[str, str] = {}
    for key, fit in candidates.items():
        option = of(fit)
        if option not in best or fit.bic < candidates[best[option]].bic:
            best[option] = key
    return best


def levels_criteria(
    candidates: Mapping[str, FitResult],
    of: Callable[[FitResult], str],
    reference: str,
    min_weight: float,
) -> dict[str, LevelsCriterion]:
    """The :class:`LevelsCriterion` of each option's best candidate (by candidate key),
    all scored on the free levels of candidate ``reference`` (the best trace-level fit).

    Empty (the choice stays the trace-level BIC's) when there are fewer than two options,
    or the levels model cannot be estimated on those levels for the reference or for an
    option the trace-level BIC gives a weight of ``min_weight`` or more (it could not be
    weighed against the others). An option below that weight whose levels model cannot
    be estimated gets no criterion (:func:`~idtool._fit._run.choice_weights` lists it
    with weight 0)."""
    bests = option_bests(candidates, of)
    if len(bests) < 2:
        return {}
    trace_bic = np.array([candidates[key].bic for key in bests.values()])
    trace_w = np.exp(-0.5 * (trace_bic - trace_bic.min()))
    trace_w /= trace_w.sum()
    ref = candidates[reference]
    try:
        free = free_levels(ref.model, ref.z, ref.noise_state)
    except np.linalg.LinAlgError:
        return {}
    out: dict[str, LevelsCriterion] = {}
    for key, weight in zip(bests.values(), trace_w, strict=True):
        fit = candidates[key]
        try:
            v = estimate_variability(fit.model, fit.z, fit.noise_state, free)
        except (np.linalg.LinAlgError, NoMeasuredLevels):
            if key == reference or weight >= min_weight:
                return {}
            continue
        k = fit.model.n_physical
        out[key] = LevelsCriterion(float(v.loglik), int(v.dof) + k, k + len(v.sds))
    return out
