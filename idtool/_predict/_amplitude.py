"""The inverse prediction: the commanded amplitude for a target friction reduction.

Per draw, the amplitude fraction in [0, 1] at which the mean FR (the curve with its
discrepancy given the data) falls to ``1 - target / 100``, by bisection on the slip
amplitude (FR falls monotonically as it grows, and the command grows with it, loaded
horn or not), each step mapped back to its command by the coupling law. Draws for
which even full amplitude does not reach the target count as "out of reach" (+inf),
so the band's upper end, or the median itself, may be out of reach; the answer says
so, with the reduction full amplitude does give.
Averaged over coupling laws (:mod:`idtool._predict._mixture`), every law's draws are
pooled.
"""

from __future__ import annotations

import dataclasses
import math

import jax
import jax.numpy as jnp
import numpy as np

from idtool._fit._discrepancy import discrepancy_moments, operating_coordinates
from idtool._model._bench import on_contact
from idtool._model._benchmodel import BenchModel
from idtool._predict._predict import Draws, _band

__all__ = ["AmplitudeFor", "amplitude_for_reduction"]

# The slip amplitude's resolution, 2^-26 (1.5e-8) of the full command's: the example's
# amplitude for 30% moved by 1e-9 (of 0.123) from 40 halvings, a thousandth of its band's
# Monte-Carlo error, and a warm report.html took 25% less CPU (the amplitude map).
_BISECTIONS = 26


@dataclasses.dataclass(frozen=True)
class AmplitudeFor:
    """The amplitude fraction for a target reduction at one load and speed.

    ``amplitude`` is (median, 2.5%, 97.5%) over draws, ``inf`` where out of reach;
    ``max_reduction_percent`` is the reduction at full amplitude (median, band).
    """

    normal_load_n: float
    pull_speed_m_s: float
    target_reduction_percent: float
    probability_reachable: float
    amplitude: tuple[float, float, float]
    max_reduction_percent: tuple[float, float, float]

    @property
    def reachable(self) -> bool:
        return math.isfinite(self.amplitude[0])

    def statement(self) -> str:
        med, lo, hi = self.amplitude
        rmed, rlo, rhi = self.max_reduction_percent
        where = f"at {self.normal_load_n:g} N, {self.pull_speed_m_s:g} m/s"
        full = f"full amplitude gives {rmed:.1f}% (95% band {rlo:.1f}-{rhi:.1f}%)"
        target = f"{self.target_reduction_percent:g}% reduction"
        if not self.reachable:
            return (
                f"{target} is out of reach {where}: {full}; reachable in "
                f"{100 * self.probability_reachable:.0f}% of the draws"
            )
        if not math.isfinite(hi):
            return (
                f"{target} {where} needs amplitude {med:.3f} (95% band {lo:.3f} to out of "
                f"reach: {100 * (1 - self.probability_reachable):.0f}% of the draws do not "
                f"reach it at full amplitude; {full})"
            )
        return f"{target} {where} needs amplitude {med:.3f} (95% band {lo:.3f}-{hi:.3f})"

    def to_dict(self) -> dict:
        def num(x: float) -> float | None:
            return x if math.isfinite(x) else None

        med, lo, hi = self.amplitude
        rmed, rlo, rhi = self.max_reduction_percent
        return {
            "normal_load_n": self.normal_load_n,
            "pull_speed_m_s": self.pull_speed_m_s,
            "target_reduction_percent": self.target_reduction_percent,
            "reachable": self.reachable,
            "probability_reachable": self.probability_reachable,
            "amplitude_fraction": {"median": num(med), "ci95": [num(lo), num(hi)]},
            "max_reduction_percent": {"median": rmed, "ci95": [rlo, rhi]},
            "statement": self.statement(),
        }


@jax.jit
def _amplitude_draws(model: BenchModel, v, load, speed, target_fr, kriging, xi):
    """Per draw in ``v``: the amplitude fraction where the mean FR (the curve times
    exp(d), d the discrepancy given the data, ``d = mean + sd xi`` with ``xi`` one
    standard normal per draw: :attr:`Draws.kriging`) falls to ``target_fr`` at ``load``
    and ``speed`` (inf if full amplitude does not reach it), and that FR at full
    amplitude.

    The bisection runs on the slip amplitude ``a`` between 0 and full command's, and
    maps each ``a`` back to its command with the coupling's
    :meth:`~idtool.AbstractCoupling.drive_fraction`: a step then costs one cycle
    average of the contact, where a step on the command would cost a whole solve of
    the loaded horn (``sdof``: about 14 cycle averages). The FR falls as ``a`` grows
    and the command grows with it, so the two searches find the same point."""
    x_rows, scales, weights, s_inv, sd = kriging
    d = model.data
    w = 2.0 * jnp.pi * jnp.asarray(d.vibration_frequency_hz)

    def solve(v, weights, s_inv, sd, xi):
        law, coupling = model.law_at(v, load), model.coupling_of(v)

        def mean_fr(fr, alpha):
            x = operating_coordinates(load, alpha, speed)[None]
            mean, var = discrepancy_moments(x, x_rows, scales, weights, s_inv, sd)
            return jnp.minimum(fr * jnp.exp(mean[0] + jnp.sqrt(var[0]) * xi), 1.0)

        def at(a):  # (mean FR, command) at slip amplitude a
            cycle = model.direction.cycle_average(law, speed, a, w, load)
            alpha = coupling.drive_fraction(law, a, cycle, load, w, d.max_amplitude_m)
            return mean_fr(cycle.friction_ratio, alpha), alpha

        def step(_, bounds):
            lo, hi = bounds
            mid = 0.5 * (lo + hi)
            below = at(mid)[0] <= target_fr  # enough reduction already at mid
            return jnp.where(below, lo, mid), jnp.where(below, mid, hi)

        one = jnp.asarray(1.0)
        fr_full, a_full = on_contact(
            law,
            coupling,
            load,
            one,
            speed,
            d.vibration_frequency_hz,
            d.max_amplitude_m,
            model.direction,
        )
        fr_full = mean_fr(fr_full, one)
        lo, hi = jax.lax.fori_loop(0, _BISECTIONS, step, (jnp.zeros_like(a_full), a_full))
        alpha = jnp.minimum(at(0.5 * (lo + hi))[1], 1.0)
        return jnp.where(fr_full <= target_fr, alpha, jnp.inf), fr_full

    return jax.vmap(solve)(v, weights, s_inv, sd, xi)


def _amplitude_samples(
    draws: Draws, target_fr: float, load: float, speed: float
) -> tuple[np.ndarray, np.ndarray]:
    """Per draw (every law's pooled): the amplitude for ``target_fr`` (inf out of
    reach) and FR at full amplitude, at ``load`` [N] and ``speed`` [m/s]."""
    if draws.mixture:
        parts = [_amplitude_samples(c, target_fr, load, speed) for c in draws.components]
        return np.concatenate([a for a, _ in parts]), np.concatenate([f for _, f in parts])
    v = {k: jnp.asarray(x) for k, x in draws.values.items()}
    # The mean curve carries the discrepancy: one standard normal per draw for its
    # conditional spread along the amplitude axis.
    xi = np.random.default_rng([draws.seed, 3]).standard_normal(draws.n)
    kriging = tuple(jnp.asarray(a) for a in draws.kriging)
    alpha, fr_full = _amplitude_draws(
        draws.model,
        v,
        jnp.asarray(float(load)),
        jnp.asarray(float(speed)),
        jnp.asarray(target_fr),
        kriging,
        jnp.asarray(xi),
    )
    return np.asarray(alpha), np.asarray(fr_full)


def amplitude_for_reduction(
    draws: Draws, target_reduction_percent: float, loads_n, speeds_m_s
) -> list[AmplitudeFor]:
    """The amplitude for ``target_reduction_percent`` at every load x speed."""
    target_fr = 1.0 - target_reduction_percent / 100.0
    out = []
    for load in loads_n:
        for speed in speeds_m_s:
            alpha, fr_full = _amplitude_samples(draws, target_fr, float(load), float(speed))
            # quantiles that are actual draws: no interpolation towards +inf
            lo, med, hi = np.percentile(alpha, [2.5, 50.0, 97.5], method="inverted_cdf")
            med, lo, hi = float(med), float(lo), float(hi)
            rmed, rlo, rhi = (float(x) for x in _band(100.0 * (1.0 - fr_full)))
            out.append(
                AmplitudeFor(
                    normal_load_n=float(load),
                    pull_speed_m_s=float(speed),
                    target_reduction_percent=float(target_reduction_percent),
                    probability_reachable=float(np.mean(np.isfinite(alpha))),
                    amplitude=(med, lo, hi),
                    max_reduction_percent=(rmed, rlo, rhi),
                )
            )
    return out
