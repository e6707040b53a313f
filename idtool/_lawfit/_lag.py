"""The load cell's lag: a first-order sensor between the contact and the recorded force,
and the likelihood-ratio test that decides whether a series needs it.

A load cell and its amplifier of finite bandwidth record ``y`` with ``tau y' + y = F``
(time constant ``tau`` [s]; :func:`idtool._model._series_force.series_force` integrates
it with the bristles). At 1 kHz a 0.25 or 0.5 ms lag delays the force after each
reversal as a stiffer, more damped contact does, and a fit without it read the delay
as bristle dynamics: Kt 1.8x its truth and outside its 95% interval on 8 of 8 sliding
series (``benchmarks/study_benches.py``). The lag-free optimum is then a basin of its
own: a score test there (the residuals regressed on the Jacobian and ``-dF/dt``) gave
chi-squared 0.3-5 on series whose likelihood ratio for the lag was 580-710. So every
fit is refitted with the lag as a parameter, :data:`LAG` (declared in sample intervals),
from starts spread over a tenth of a sample interval to four
(:func:`idtool._lawfit._solve.fit_lag`), and the lag is kept where the likelihood
ratio rejects the lag-free model at :data:`LEVEL` (the lag's null value is its range's
lower end, so the ratio's null distribution is half chi-squared with 1 degree of
freedom, half zero).
"""

from __future__ import annotations

import dataclasses
import math

from idtool._model._params import Param

__all__ = ["LAG", "LEVEL", "LagCheck", "lag_test", "minus_two_log_l"]

# declared in sample intervals (the median; make_problem's scale): 1e-3 of one is no lag
LAG = Param(
    "sensor_lag_s", "s", "log", 1e-3, 30.0, start=0.2,
    description="time constant of the load cell's first-order lag",
)  # fmt: skip
# Keep the lag where the test's p-value is below this (a false alarm costs a parameter
# the series does not need: the lag model nests the lag-free one; a missed lag, Kt).
LEVEL = 0.01


@dataclasses.dataclass(frozen=True)
class LagCheck:
    """The likelihood-ratio test of a load-cell lag.

    Attributes:
        lag_s: the lag model's estimate of the time constant [s].
        statistic: ``-2 log L`` of the lag-free optimum minus the lag model's (each with
            its own AR(1) whitening, the Prais-Winsten Jacobian included).
        p_value: against the null mixture (module docstring).
        fitted: whether the fit carries the lag (``p_value < LEVEL``).
    """

    lag_s: float
    statistic: float
    p_value: float

    @property
    def fitted(self) -> bool:
        return self.p_value < LEVEL

    def to_json(self) -> dict:
        return {
            "lag_s": self.lag_s,
            "statistic": self.statistic,
            "p_value": self.p_value,
            "level": LEVEL,
            "fitted": self.fitted,
        }


def minus_two_log_l(rss: float, n: int, phi: float) -> float:
    """``-2 log L`` (up to a constant) of Gaussian AR(1) residuals of whitened sum of
    squares ``rss`` over ``n`` samples, the variance profiled out."""
    return n * math.log(rss / n) - math.log(1.0 - phi**2)


def lag_test(lag_s: float, free: tuple[float, int, float], lagged_: tuple[float, int, float]):
    """:class:`LagCheck` from the lag-free and the lag model's ``(rss, n, phi)``."""
    stat = max(minus_two_log_l(*free) - minus_two_log_l(*lagged_), 0.0)
    p = 0.5 * math.erfc(math.sqrt(stat / 2.0))  # half the chi-squared(1) tail
    return LagCheck(lag_s, stat, p)
