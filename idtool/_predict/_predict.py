"""Predictions of the friction ratio from a posterior (issue 5), and the inverse.

Forward: for every draw of the physical parameters, the contact model's friction ratio
FR at an operating point (normal load, commanded amplitude fraction, pull speed); the
median and the central 95% band over draws; the reduction is ``100 (1 - FR)`` %.

Inverse: the amplitude fraction in [0, 1] at which FR falls to ``1 - target / 100``, per
draw by bisection (FR falls monotonically as the commanded amplitude grows: the slip
amplitude grows with it, power-limited or not). Draws for which even full amplitude
does not reach the target count as "out of reach" (+inf), so the band's upper end, or
the median itself, may be out of reach; the answer says so, with the reduction full
amplitude does give.

Draws come from ``posterior.nc`` when there is one; without it, from a Gaussian on the
fit's internal scale with the fit's covariance (say so: it is a local approximation).
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from idtool._data._blocks import FitData
from idtool._fit._store import StoredFit
from idtool._model._benchmodel import BenchModel
from idtool._posterior._sample import Posterior
from idtool._posterior._store import POSTERIOR_FILE, PosteriorDraws, load_posterior

__all__ = [
    "AmplitudeFor",
    "Draws",
    "Prediction",
    "amplitude_for_reduction",
    "draws_from_covariance",
    "draws_from_posterior",
    "draws_from_stored",
    "extrapolation_notes",
    "predict_friction_ratio",
    "prediction_draws",
]

_BISECTIONS = 40  # amplitude resolution 2^-40


@dataclasses.dataclass(frozen=True)
class Draws:
    """Draws of the physical parameters (flat arrays) and where they come from."""

    model: BenchModel
    values: dict[str, np.ndarray]
    source: str  # "posterior" or "fit covariance"
    note: str

    @property
    def n(self) -> int:
        return int(next(iter(self.values.values())).size)


def _thin(n: int, max_draws: int) -> np.ndarray:
    return np.unique(np.linspace(0, n - 1, min(n, max_draws)).round().astype(int))


def draws_from_posterior(post: Posterior, model: BenchModel, max_draws: int = 2000) -> Draws:
    """Prediction draws from an in-memory :class:`~idtool._posterior._sample.Posterior`
    (kept draws, thinned evenly to ``max_draws``)."""
    all_draws = post.draws()
    n = next(iter(all_draws.values())).size
    idx = _thin(n, max_draws)
    values = {k: all_draws[k][idx] for k in model.physical_names}
    note = f"posterior ({post.noise} noise, {idx.size} of {n} draws)"
    if not post.diagnostics.converged:
        note += "; the chain is NOT converged"
    return Draws(model, values, "posterior", note)


def draws_from_stored(post: PosteriorDraws, model: BenchModel, max_draws: int = 2000) -> Draws:
    """Prediction draws from ``posterior.nc`` read back (:func:`load_posterior`)."""
    n = post.n_draws
    idx = _thin(n, max_draws)
    values = {k: post.values[k][idx] for k in model.physical_names}
    note = f"posterior ({post.meta['noise']} noise, {idx.size} of {n} draws)"
    if not post.meta["diagnostics"]["converged"]:
        note += "; the chain is NOT converged, see sample.json"
    return Draws(model, values, "posterior", note)


def draws_from_covariance(
    model: BenchModel, z: np.ndarray, cov_z: np.ndarray, max_draws: int = 2000, seed: int = 0
) -> Draws:
    """Gaussian draws on the internal scale from a fit's covariance: a local
    approximation of the posterior, mapped through the transforms."""
    k = model.n_physical
    rng = np.random.default_rng(seed)
    draws = rng.multivariate_normal(z[:k], cov_z[:k, :k], size=max_draws, method="eigh")
    values = {
        p.name: np.asarray(p.value(jnp.asarray(draws[:, i])))
        for i, p in enumerate(model.shared_params[:k])
    }
    note = (
        "no posterior: Gaussian draws on the internal scale from the fit's covariance "
        "(a local approximation; run 'idtool sample' or Fit.sample() for the posterior)"
    )
    return Draws(model, values, "fit covariance", note)


def prediction_draws(fit: StoredFit, max_draws: int = 2000, seed: int = 0) -> Draws:
    """Posterior draws of a stored fit (``posterior.nc`` beside it), or Gaussian draws
    from its covariance when it has none."""
    path = Path(fit.folder) / POSTERIOR_FILE
    if path.is_file():
        return draws_from_stored(load_posterior(path), fit.model, max_draws)
    return draws_from_covariance(fit.model, fit.z, fit.cov_z, max_draws, seed)


def extrapolation_notes(data: FitData, loads_n=(), amplitudes=(), speeds_m_s=()) -> list[str]:
    """One note per quantity whose requested values leave the range the fit saw."""
    notes = []
    for label, given, seen in (
        ("normal load", loads_n, data.normal_load_n),
        ("amplitude fraction", amplitudes, data.amplitude_fraction),
        ("pull speed", speeds_m_s, data.pull_speed_m_s),
    ):
        lo, hi = float(np.min(seen)), float(np.max(seen))
        out = [f"{v:.3g}" for v in given if v < lo * (1 - 1e-9) or v > hi * (1 + 1e-9)]
        if out:
            vals = ", ".join(out)
            notes.append(
                f"{label} {vals} lies outside the fitted range [{lo:g}, {hi:g}]: extrapolation"
            )
    return notes


@jax.jit
def _fr_draws(model: BenchModel, v, load, alpha, speed):
    """FR (draws, points) at operating points for every draw in ``v``."""
    return jax.vmap(lambda vv: model.friction_ratios(vv, load, alpha, speed))(v)


@dataclasses.dataclass(frozen=True)
class Prediction:
    """FR at one operating point: median and 95% band over draws."""

    normal_load_n: float
    amplitude_fraction: float
    pull_speed_m_s: float
    median: float
    ci95: tuple[float, float]

    @property
    def reduction_percent(self) -> tuple[float, tuple[float, float]]:
        """Median and 95% band of the reduction ``100 (1 - FR)``."""
        lo, hi = self.ci95
        return 100 * (1 - self.median), (100 * (1 - hi), 100 * (1 - lo))

    def to_dict(self) -> dict:
        red, (rlo, rhi) = self.reduction_percent
        return {
            "normal_load_n": self.normal_load_n,
            "amplitude_fraction": self.amplitude_fraction,
            "pull_speed_m_s": self.pull_speed_m_s,
            "friction_ratio": {"median": self.median, "ci95": list(self.ci95)},
            "reduction_percent": {"median": red, "ci95": [rlo, rhi]},
        }


def _band(x: np.ndarray, axis: int = 0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    lo, med, hi = np.percentile(x, [2.5, 50.0, 97.5], axis=axis)
    return med, lo, hi


def predict_friction_ratio(draws: Draws, loads_n, amplitudes, speeds_m_s) -> list[Prediction]:
    """FR over the grid ``loads x amplitudes x speeds`` (in that order)."""
    grid = np.array(
        [(n, a, s) for n in loads_n for a in amplitudes for s in speeds_m_s], float
    ).reshape(-1, 3)
    v = {k: jnp.asarray(x) for k, x in draws.values.items()}
    fr = np.asarray(
        _fr_draws(
            draws.model,
            v,
            jnp.asarray(grid[:, 0]),
            jnp.asarray(grid[:, 1]),
            jnp.asarray(grid[:, 2]),
        )
    )
    med, lo, hi = _band(fr)
    return [
        Prediction(float(g[0]), float(g[1]), float(g[2]), float(m), (float(a), float(b)))
        for g, m, a, b in zip(grid, med, lo, hi, strict=True)
    ]


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
def _amplitude_draws(model: BenchModel, v, load, speed, target_fr):
    """Per draw in ``v``: the amplitude fraction where FR falls to ``target_fr`` at
    ``load`` and ``speed`` (inf if full amplitude does not reach it), and FR at full
    amplitude."""

    def solve(v):
        def fr_at(alpha):
            return model.friction_ratios(v, load[None], alpha[None], speed[None])[0]

        def step(_, bounds):
            lo, hi = bounds
            mid = 0.5 * (lo + hi)
            below = fr_at(mid) <= target_fr  # enough reduction already at mid
            return jnp.where(below, lo, mid), jnp.where(below, mid, hi)

        fr_full = fr_at(jnp.asarray(1.0))
        lo, hi = jax.lax.fori_loop(0, _BISECTIONS, step, (jnp.asarray(0.0), jnp.asarray(1.0)))
        alpha = jnp.where(fr_full <= target_fr, 0.5 * (lo + hi), jnp.inf)
        return alpha, fr_full

    return jax.vmap(solve)(v)


def amplitude_for_reduction(
    draws: Draws, target_reduction_percent: float, loads_n, speeds_m_s
) -> list[AmplitudeFor]:
    """The amplitude for ``target_reduction_percent`` at every load x speed."""
    target_fr = 1.0 - target_reduction_percent / 100.0
    v = {k: jnp.asarray(x) for k, x in draws.values.items()}
    out = []
    for load in loads_n:
        for speed in speeds_m_s:
            alpha, fr_full = _amplitude_draws(
                draws.model,
                v,
                jnp.asarray(float(load)),
                jnp.asarray(float(speed)),
                jnp.asarray(target_fr),
            )
            alpha, fr_full = np.asarray(alpha), np.asarray(fr_full)
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
