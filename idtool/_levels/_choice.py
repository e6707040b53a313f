"""Model choice on a friction table: every coupling law and/or direction of vibration
fitted (``fit_levels(..., coupling="auto", direction="auto")``; by default the power
limit and the load-power law where the table resolves speeds), ranked by BIC, the
others kept by their BIC weights for the predictions, as the trace fit does
(:func:`idtool._fit._run.choice_weights`).

``BIC = -2 log L + k log m``, with ``log L`` the table's Gaussian log-likelihood at the
estimate (:attr:`~idtool._levels._estimate.Optimum.loglik`: its sds included), ``k``
the physical parameters plus the sds estimated, ``m`` the table's log levels (two per
row: OFF and FR). The weights ``exp(-delta/2)`` approximate each model's posterior
probability under equal prior odds (Kass & Raftery 1995, J. Am. Stat. Assoc. 90, 773).

A prediction averaged over the models (:func:`pool`): each model's bands as a split
log-normal (its median, and each side's 95% point), draws in proportion to the weights,
pooled, the 2.5 and 97.5 percentiles: a mixture's band, wider than any one model's
where they disagree.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from idtool._fit._run import MIN_LAW_WEIGHT, ChoiceWeight
from idtool._model._coupling import COUPLINGS, reacts_on_vibration
from idtool._model._directions import DIRECTIONS
from idtool._model._names import BY_DESIGN, DEFAULT_COUPLING, SPEED_RESOLVED_COUPLINGS

__all__ = ["AUTO", "POOL_DRAWS", "options", "pool", "rank", "table_bic"]

AUTO = "auto"
POOL_DRAWS = 4000  # draws of the pooled band: its 2.5% point to ~0.5% of the band


def options(coupling: str, direction: str, speed_resolved: bool = False) -> list[tuple[str, str]]:
    """The (coupling, direction) pairs to fit: every registered coupling law a table can
    take (not one that models the horn's transducer) where ``coupling`` is ``auto``;
    where it is ``by-design``, the power limit, and the load-power law too on a table
    that measured some load and amplitude at two or more speeds (``speed_resolved``:
    the trace fit's rule, :data:`idtool._model._names.BY_DESIGN`); every direction where
    ``direction`` is ``auto``."""
    if coupling == AUTO:
        couplings = [c for c in COUPLINGS if not reacts_on_vibration(COUPLINGS.get(c))]
    elif coupling == BY_DESIGN:
        couplings = list(SPEED_RESOLVED_COUPLINGS) if speed_resolved else [DEFAULT_COUPLING]
    else:
        couplings = [coupling]
    directions = list(DIRECTIONS) if direction == AUTO else [direction]
    return [(c, d) for d in directions for c in couplings]


def table_bic(loglik: float, k: int, m: int) -> tuple[float, float]:
    """BIC and AIC of a table fit of ``k`` free quantities to ``m`` log levels."""
    return -2.0 * loglik + k * math.log(m), -2.0 * loglik + 2.0 * k


def label(coupling: str, direction: str, compared: Sequence[str]) -> str:
    """A model's name in the ranking: the option that varies (``coupling@direction``
    when both do), as the trace fit names them."""
    if "direction" not in compared:
        return coupling
    if "coupling" not in compared:
        return direction
    return f"{coupling}@{direction}"


def rank(entries: Sequence[tuple[str, str, float, float]]) -> list[ChoiceWeight]:
    """``(label, key, bic, aic)`` per model -> :class:`ChoiceWeight`, best first."""
    order = sorted(range(len(entries)), key=lambda i: entries[i][2])
    bic = np.array([entries[i][2] for i in order])
    aic = np.array([entries[i][3] for i in order])

    def weights(v: np.ndarray) -> np.ndarray:
        w = np.exp(-0.5 * (v - v.min()))
        return w / w.sum()

    wb, wa = weights(bic), weights(aic)
    return [
        ChoiceWeight(
            entries[i][0], entries[i][1], float(bic[j]), float(aic[j]), float(wb[j]), float(wa[j])
        )
        for j, i in enumerate(order)
    ]


def kept(ranking: Sequence[ChoiceWeight]) -> list[ChoiceWeight]:
    """The models a prediction averages over: BIC weight at least
    :data:`~idtool._fit._run.MIN_LAW_WEIGHT`."""
    return [w for w in ranking if w.bic_weight >= MIN_LAW_WEIGHT]


def _split_draws(fr, lo, hi, z):
    """Draws of a split log-normal with median ``fr`` and 95% points ``lo``, ``hi``
    (points,), from standard normals ``z`` (draws, points), or (draws, 1) shared."""
    up = np.log(hi / fr) / 1.96
    down = np.log(fr / lo) / 1.96
    return fr * np.exp(np.where(z > 0, z * up, z * down))


def pool(
    weights: Sequence[float],
    fr: Sequence[np.ndarray],
    mean_bands: Sequence[tuple[np.ndarray, np.ndarray]],
    next_bands: Sequence[tuple[np.ndarray, np.ndarray]],
    seed: int = 0,
) -> tuple[np.ndarray, tuple[np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray]]:
    """The models' predictions at the same points (arrays of one shape each) averaged by
    ``weights`` (module docstring): the pooled median of the mean draws and the two 95%
    bands. A point any model leaves unpinned (NaN band) stays NaN. Seeded."""
    w = np.asarray(weights, float) / np.sum(weights)
    counts = np.maximum(1, np.round(POOL_DRAWS * w).astype(int))
    rng = np.random.default_rng(seed)
    shape = np.shape(fr[0])
    mean_draws, next_draws = [], []
    for i, c in enumerate(counts):
        f = np.ravel(fr[i])
        # one normal per draw, shared by every point (common random numbers): each
        # point's band is the same Monte Carlo estimate, and a curve of them is smooth
        # instead of jagged by independent errors from point to point
        z = rng.standard_normal((c, 1))
        (m0, m1), (n0, n1) = (
            (np.ravel(b[0]), np.ravel(b[1])) for b in (mean_bands[i], next_bands[i])
        )
        mean_draws.append(_split_draws(f, m0, m1, z))
        next_draws.append(_split_draws(f, n0, n1, z))
    mean, nxt = np.concatenate(mean_draws), np.concatenate(next_draws)
    with np.errstate(invalid="ignore"):
        median = np.median(mean, axis=0)
        mlo, mhi = np.percentile(mean, [2.5, 97.5], axis=0)
        nlo, nhi = np.percentile(nxt, [2.5, 97.5], axis=0)
    unpinned = np.any(np.isnan(mean), axis=0) | np.any(np.isnan(nxt), axis=0)
    median = np.where(unpinned, np.ravel(fr[int(np.argmax(w))]), median)

    def shaped(x):
        return np.where(unpinned, np.nan, x).reshape(shape)

    return median.reshape(shape), (shaped(mlo), shaped(mhi)), (shaped(nlo), shaped(nhi))
