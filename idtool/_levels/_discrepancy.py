"""How sure a table is of its discrepancy: the sd's posterior on a grid, and the value
the intervals and bands use (:func:`discrepancy_posterior`).

A table's conditions share no curve: each has its own discrepancy ``d ~ N(0, tau^2)``
in log FR (:mod:`idtool._levels._estimate`), and only the spread of the conditions'
means about the model, beyond what their rows' scatter explains, tells ``tau``. Where
the scatter is large against ``tau`` (a 2% discrepancy under 5% scatter, three repeats:
the means' own noise is 2.9%), REML's estimate sits at its floor on about half of such
tables, and bands read at the estimate leave a new condition's discrepancy out: the
held-out FR of simulated tables whose horn gain drifts over the campaign fell inside the
mean band on 18 of 24 (benchmarks/study_benches.py).

So ``tau`` is integrated, not plugged in: its REML likelihood on a grid (the other sds
and theta at their estimates, as the trace fit's grids,
:mod:`idtool._fit._variability`) times the sampler's prior on an sd (half-normal, scale
0.1: :data:`idtool._posterior._levels.SD_PRIOR`, so that a sampled fit and the default
one integrate over the same prior), and the intervals and bands use the sd whose
variance is the posterior mean of ``tau^2`` (the mean of the predictive variance of a
new condition's discrepancy). Its 95% interval is reported beside the REML estimate.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable

import numpy as np

from idtool._posterior._levels import SD_PRIOR

__all__ = ["DiscrepancyPosterior", "discrepancy_posterior", "summary"]

_POINTS = 161  # grid points from 0 to the top
_DROP = 12.0  # -log likelihood above its minimum at the grid's top (e^-12: nothing left)
_TOP_CEIL = 2.0  # the sds' range's top (SD_CEIL)


@dataclasses.dataclass(frozen=True)
class DiscrepancyPosterior:
    """The discrepancy sd's posterior (module docstring).

    Attributes:
        grid: sd values from 0 [-] (relative).
        weights: their posterior probabilities.
        reml: REML's estimate [-].
        band_sd: ``sqrt(E[tau^2])`` [-]: what intervals and bands use.
        ci95: the 2.5 and 97.5 percentiles [-].
    """

    grid: np.ndarray
    weights: np.ndarray
    reml: float
    band_sd: float
    ci95: tuple[float, float]

    def to_json(self) -> dict:
        """``fit.json``'s record (without the grid: :func:`summary` reads it back)."""
        return {"reml": self.reml, "band_sd": self.band_sd, "ci95": list(self.ci95)}


def summary(doc: dict) -> DiscrepancyPosterior:
    """A posterior's record (:meth:`DiscrepancyPosterior.to_json`) read back: its grid
    empty (the intervals and bands read ``band_sd`` alone)."""
    lo, hi = (float(x) for x in doc["ci95"])
    empty = np.zeros(0)
    return DiscrepancyPosterior(empty, empty, float(doc["reml"]), float(doc["band_sd"]), (lo, hi))


def discrepancy_posterior(nll: Callable[[float], float], reml: float) -> DiscrepancyPosterior:
    """The posterior of the discrepancy sd from ``nll`` (its negative REML
    log-likelihood at an sd value, the rest held) and REML's estimate ``reml``: a grid
    from 0 to where ``nll`` has risen by :data:`_DROP` above the lowest seen, times the
    half-normal prior (module docstring)."""
    top = max(4.0 * reml, 0.04)
    floor = nll(reml)
    while nll(top) - floor < _DROP and top < _TOP_CEIL:
        top = min(2.0 * top, _TOP_CEIL)
    grid = np.linspace(0.0, top, _POINTS)
    values = np.array([nll(float(t)) for t in grid])
    log_w = -(values - values.min()) - 0.5 * (grid / SD_PRIOR.b) ** 2  # half-normal
    w = np.exp(log_w - log_w.max())
    w /= w.sum()
    cdf = np.cumsum(w)
    lo, hi = (float(np.interp(q, cdf, grid)) for q in (0.025, 0.975))
    return DiscrepancyPosterior(
        grid=grid,
        weights=w,
        reml=float(reml),
        band_sd=float(math.sqrt(np.sum(w * grid**2))),
        ci95=(0.0 if cdf[0] >= 0.025 else lo, hi),
    )
