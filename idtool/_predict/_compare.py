"""Two fits side by side: does material A reduce friction more than material B?

At an operating point (normal load [N], commanded amplitude fraction, pull speed [m/s])
each fit gives draws of its mean friction ratio FR (the curve with its operating-point
discrepancy: :func:`~idtool._predict._predict.friction_ratio_draws`). The probability
that A reduces friction more than B is ``P(FR_A < FR_B)`` under the two posteriors.

The two sets of draws are independent, and rightly so: each fit is the posterior of its
own dataset (another material, or another session), and datasets measured on separate
pulls share no noise, no nuisances and no parameters, so the joint posterior is the
product of the two. The probability is then averaged over every pair ``(a_i, b_j)``
(the Mann-Whitney statistic, ties counted half: both capped at FR = 1, no reduction),
which does not depend on how the draws are paired; its Monte-Carlo standard error is
DeLong's (from the placement values), valid for independent draws. Posterior draws are
thinned but still somewhat autocorrelated, so for them it is a lower bound.

When a fit has no posterior, its draws are Gaussian on the fit's covariance (a local
approximation, :func:`~idtool._predict._predict.draws_from_covariance`); the result is
flagged (``Draws.source``), not refused: for well-identified fits the two agree.

Pure numbers on :class:`~idtool._predict._predict.Draws`; no files (the report is
:mod:`idtool._report._compare`).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence

import numpy as np

from idtool._data._blocks import FitData
from idtool._data._dataset import Rig
from idtool._errors import IdtoolError
from idtool._predict._predict import Draws, _thin, friction_ratio_draws

__all__ = [
    "PairPoint",
    "comparability",
    "compare_at",
    "probability_lower",
    "probability_lower_fr",
    "reduction_difference",
    "tested_values",
    "thinned",
]

# All-pairs quantiles of the difference: 2000 x 2000 draws (32 MB of float64) at most;
# beyond that a seeded random subset of pairs of that size (quantiles to ~1e-3).
_MAX_PAIRS = 4_000_000


@dataclasses.dataclass(frozen=True)
class PairPoint:
    """Fit A against fit B at one operating point.

    ``probability``: P(FR_A < FR_B), A's mean friction ratio below B's (A reduces
    friction more), with its Monte-Carlo ``standard_error``. ``probability_next_pull``:
    the same for one new pull on each (pull-to-pull scatter included).
    ``reduction_difference``: A's reduction minus B's, ``100 (FR_B - FR_A)``
    [percentage points], (median, 2.5%, 97.5%) over pairs of draws.
    """

    normal_load_n: float
    amplitude_fraction: float
    pull_speed_m_s: float
    probability: float
    standard_error: float
    probability_next_pull: float
    reduction_difference: tuple[float, float, float]

    def to_dict(self) -> dict:
        med, lo, hi = self.reduction_difference
        return {
            "normal_load_n": self.normal_load_n,
            "amplitude_fraction": self.amplitude_fraction,
            "pull_speed_m_s": self.pull_speed_m_s,
            "probability_a_reduces_more": self.probability,
            "standard_error": self.standard_error,
            "probability_next_pull": self.probability_next_pull,
            "reduction_difference_points": {"median": med, "ci95": [lo, hi]},
        }


def probability_lower(a: np.ndarray, b: np.ndarray) -> tuple[float, float]:
    """``P(A < B)`` for independent draws ``a`` and ``b`` (1-D): the mean over every
    pair of ``1[a_i < b_j] + 1/2 1[a_i = b_j]``, and its standard error (DeLong et al.
    1988: the variances of the placement values over each sample's size)."""
    a, b = np.asarray(a, float).ravel(), np.asarray(b, float).ravel()
    if a.size < 2 or b.size < 2:
        raise IdtoolError("probability_lower: give at least two draws of each")
    sa, sb = np.sort(a), np.sort(b)
    # placement of a_i among b: the share of b above it (ties half), and vice versa
    below_b = np.searchsorted(sb, a, side="left")
    upto_b = np.searchsorted(sb, a, side="right")
    v = (b.size - upto_b + 0.5 * (upto_b - below_b)) / b.size
    below_a = np.searchsorted(sa, b, side="left")
    upto_a = np.searchsorted(sa, b, side="right")
    w = (below_a + 0.5 * (upto_a - below_a)) / a.size
    p = float(np.mean(v))
    se = math.sqrt(float(np.var(v, ddof=1)) / a.size + float(np.var(w, ddof=1)) / b.size)
    return p, se


def reduction_difference(a: np.ndarray, b: np.ndarray, seed: int = 0) -> tuple[float, float, float]:
    """(median, 2.5%, 97.5%) of A's reduction minus B's, ``100 (b_j - a_i)``
    [percentage points], over every pair of the FR draws ``a`` and ``b`` (a seeded
    random subset of pairs when there are more than 4 million)."""
    a, b = np.asarray(a, float).ravel(), np.asarray(b, float).ravel()
    if a.size * b.size <= _MAX_PAIRS:
        diff = np.subtract.outer(b, a).ravel()
    else:
        rng = np.random.default_rng([seed, 4])
        diff = rng.choice(b, _MAX_PAIRS) - rng.choice(a, _MAX_PAIRS)
    lo, med, hi = np.percentile(100.0 * diff, [2.5, 50.0, 97.5])
    return float(med), float(lo), float(hi)


def compare_at(
    grid: np.ndarray,
    a: tuple[np.ndarray, np.ndarray],
    b: tuple[np.ndarray, np.ndarray],
    seed: int = 0,
) -> list[PairPoint]:
    """A against B at each row (load [N], amplitude fraction, speed [m/s]) of ``grid``,
    from each fit's ``(mean, new)`` FR draws (draws, points) of
    :func:`~idtool._predict._predict.friction_ratio_draws` at those rows."""
    out = []
    for k, (load, alpha, speed) in enumerate(np.asarray(grid, float)):
        p, se = probability_lower(a[0][:, k], b[0][:, k])
        p_new, _ = probability_lower(a[1][:, k], b[1][:, k])
        diff = reduction_difference(a[0][:, k], b[0][:, k], seed)
        out.append(PairPoint(float(load), float(alpha), float(speed), p, se, p_new, diff))
    return out


def probability_lower_fr(
    draws_a: Draws,
    draws_b: Draws,
    load_n: float | Sequence[float],
    amplitude: float | Sequence[float],
    speed_m_s: float,
) -> list[PairPoint]:
    """P(FR_A < FR_B) (A reduces friction more than B) and the difference in reduction
    [percentage points] over loads [N] x amplitude fractions at ``speed_m_s`` [m/s],
    from the two fits' independent draws (see the module's docstring for why they are
    independent; a fit without a posterior contributes its covariance approximation,
    said in ``draws.source``)."""
    loads = np.atleast_1d(np.asarray(load_n, float))
    amps = np.atleast_1d(np.asarray(amplitude, float))
    grid = np.array([(n, x, speed_m_s) for n in loads for x in amps], float).reshape(-1, 3)
    fr_a = friction_ratio_draws(draws_a, *grid.T)
    fr_b = friction_ratio_draws(draws_b, *grid.T)
    return compare_at(grid, fr_a, fr_b, draws_a.seed)


def thinned(draws: Draws, max_draws: int) -> Draws:
    """At most ``max_draws`` of ``draws``, evenly spaced (posterior draws come in chain
    order, so the first ones would all be early steps): for curves and the amplitude
    inverse, which solve the contact model per draw at many points (about 65 us a
    solve on 2 cores)."""
    total = sum(c.n for c in draws.components)
    if total <= max_draws:
        return draws
    # each coupling law's draws keep their share (:mod:`idtool._predict._mixture`)
    parts = [c.subset(_thin(c.n, max(1, round(max_draws * c.n / total)))) for c in draws.components]
    return dataclasses.replace(parts[0], mixture=tuple(parts[1:]))


def tested_values(data: FitData, name: str) -> list[float]:
    """The distinct values of ``name`` (``normal_load_n``, ``amplitude_fraction`` (0,
    no ultrasound, left out) or ``pull_speed_m_s``) over a fit's traces, ascending."""
    values = sorted(set(np.asarray(getattr(data, name), float).tolist()))
    return [v for v in values if v > 0.0] if name == "amplitude_fraction" else values


def _rig_text(rig: Rig) -> str:
    return f"horn {rig.vibration_frequency_hz:g} Hz, max amplitude {rig.max_amplitude_m * 1e6:g} um"


def comparability(
    labels: Sequence[str],
    rigs: Sequence[Rig],
    laws: Sequence[str],
    sha256: Sequence[str],
    data: Sequence[FitData],
) -> list[str]:
    """Refuse (IdtoolError naming the fits) what cannot be compared: fits from rigs
    with another horn frequency or maximum amplitude (a commanded amplitude fraction is
    another vibration there). Return warnings for what weakens the comparison: the same
    dataset twice (the draws are then not independent), different friction laws (the
    physical estimates mean other things; FR still compares), different tested loads
    or amplitudes (at a point only one of them tested, the other one interpolates or
    extrapolates)."""
    ref = rigs[0]
    for label, rig in zip(labels[1:], rigs[1:], strict=True):
        if not (
            math.isclose(rig.vibration_frequency_hz, ref.vibration_frequency_hz, rel_tol=1e-3)
            and math.isclose(rig.max_amplitude_m, ref.max_amplitude_m, rel_tol=1e-3)
        ):
            raise IdtoolError(
                f"{labels[0]} ({_rig_text(ref)}) and {label} ({_rig_text(rig)}) come from "
                "different rigs: the same commanded amplitude fraction is another vibration "
                "there, so their friction ratios do not compare; compare fits of one rig"
            )
    out = []
    for i in range(1, len(labels)):
        if sha256[i] == sha256[0]:
            out.append(
                f"{labels[0]} and {labels[i]} are fits of the same dataset: their draws are "
                "not independent, so the probability does not compare two materials"
            )
    if len(set(laws)) > 1:
        named = ", ".join(f"{n}: {law}" for n, law in zip(labels, laws, strict=True))
        out.append(
            f"the fits use different friction laws ({named}): the friction ratios compare, "
            "the physical estimates (Kt) mean different things"
        )
    for name, what, unit in (
        ("normal_load_n", "loads", " N"),
        ("amplitude_fraction", "amplitudes", ""),
    ):
        seen = [tested_values(d, name) for d in data]
        if any(s != seen[0] for s in seen[1:]):
            named = "; ".join(
                f"{n}: {', '.join(f'{v:g}' for v in s)}{unit}"
                for n, s in zip(labels, seen, strict=True)
            )
            out.append(
                f"the fits were tested at different {what} ({named}): where only one of them "
                "was tested, the other's friction ratio is interpolated or extrapolated"
            )
    return out
