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
import functools
import math
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from idtool._data._blocks import FitData
from idtool._fit._discrepancy import Conditioning, discrepancy_moments, operating_coordinates
from idtool._fit._store import StoredFit
from idtool._model._benchmodel import BenchModel
from idtool._posterior._sample import Posterior
from idtool._posterior._store import POSTERIOR_FILE, PosteriorDraws, load_posterior

SD_NAMES = ("discrepancy_fr", "scatter_fr")  # the sds a prediction uses

__all__ = [
    "AmplitudeFor",
    "Draws",
    "Prediction",
    "amplitude_for_reduction",
    "draws_from_covariance",
    "draws_from_posterior",
    "draws_from_stored",
    "extrapolation_notes",
    "friction_ratio_draws",
    "predict_friction_ratio",
    "prediction_draws",
    "predictions_from_draws",
]

_BISECTIONS = 40  # amplitude resolution 2^-40


@dataclasses.dataclass(frozen=True)
class Draws:
    """Draws of the physical parameters (flat arrays) and where they come from.

    ``sds`` holds, per draw, the levels model's sds (``discrepancy_fr``, ``scatter_fr``;
    :mod:`idtool._fit._variability`) when the fit has them: the friction-ratio band then
    carries the operating-point discrepancy and the new-trace band the pull-to-pull
    scatter too. ``conditioning``: the traces' own friction ratios, on which the
    discrepancy is conditioned (:mod:`idtool._fit._discrepancy`); without it the
    discrepancy is unconditional everywhere. ``seed`` seeds those extra draws.
    """

    model: BenchModel
    values: dict[str, np.ndarray]
    source: str  # "posterior" or "fit covariance"
    note: str
    sds: dict[str, np.ndarray] = dataclasses.field(default_factory=dict)
    seed: int = 0
    conditioning: Conditioning | None = None

    @property
    def n(self) -> int:
        return int(next(iter(self.values.values())).size)

    @functools.cached_property
    def kriging(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Per draw, what the discrepancy's conditional moments need (arguments of
        :func:`~idtool._fit._discrepancy.discrepancy_moments` after ``x_new``): the
        rows' coordinates and length scales, ``S^-1 (y - g)``, ``S^-1`` and the sd; all
        zero but the sd without conditioning (the unconditional discrepancy)."""
        n = next(iter(self.sds.values())).size if self.sds else self.n
        zero = np.zeros(n)
        sd = self.sds.get("discrepancy_fr", zero)
        c = self.conditioning
        if c is None or not self.sds:
            return np.zeros((1, 3)), np.ones(3), np.zeros((n, 1)), np.zeros((n, 1, 1)), sd
        v = {k: jnp.asarray(x) for k, x in self.values.items()}
        load, alpha, speed = (jnp.asarray(r) for r in c.rows)
        g = np.log(np.asarray(_fr_draws(self.model, v, load, alpha, speed)))
        weights, s_inv = c.weights(g, sd, self.sds.get("scatter_fr", zero))
        return c.x, c.scales, weights, s_inv, sd

    def discrepancy(self, x_new: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Mean and variance of the discrepancy (log FR) at operating points ``x_new``
        (p, 3) per draw, given the data: (draws, p) each."""
        x_rows, scales, weights, s_inv, sd = self.kriging
        one = jax.vmap(discrepancy_moments, in_axes=(None, None, None, 0, 0, 0))
        mean, var = one(jnp.asarray(x_new), x_rows, scales, weights, s_inv, sd)
        return np.asarray(mean), np.asarray(var)


def _thin(n: int, max_draws: int) -> np.ndarray:
    return np.unique(np.linspace(0, n - 1, min(n, max_draws)).round().astype(int))


SdGrids = dict[str, tuple[np.ndarray, np.ndarray]]


def _sds(
    sampled: dict[str, np.ndarray], grids: SdGrids | None, n: int, seed: int
) -> tuple[dict[str, np.ndarray], str]:
    """Per-draw sds: the sampled ones, else draws from the fit's sd grids (REML
    likelihood times the spike-and-slab prior; seeded);
    and a note on where they came from."""
    if all(name in sampled for name in SD_NAMES):
        return {name: sampled[name] for name in SD_NAMES}, ""
    if not grids:
        return {}, "; no scatter or discrepancy in the model: the bands are the noise's only"
    rng = np.random.default_rng([seed, 1])
    out = {name: rng.choice(grid, size=n, p=prob) for name, (grid, prob) in grids.items()}
    return out, (
        "; scatter and discrepancy sds drawn from the fit's REML likelihood times a "
        "spike-and-slab prior"
    )


def draws_from_posterior(
    post: Posterior,
    model: BenchModel,
    max_draws: int = 2000,
    sd_grids: SdGrids | None = None,
    seed: int = 0,
    conditioning: Conditioning | None = None,
) -> Draws:
    """Prediction draws from an in-memory :class:`~idtool._posterior._sample.Posterior`
    (kept draws, thinned evenly to ``max_draws``); the sds from the posterior, else
    from the fit's ``sd_grids``; the discrepancy conditioned on ``conditioning`` (default:
    the posterior's own)."""
    unconverged = "" if post.diagnostics.converged else "; the chain is NOT converged"
    cond = conditioning or post.conditioning
    chain = post.draws()
    return _chain_draws(chain, post.noise, unconverged, model, max_draws, sd_grids, seed, cond)


def draws_from_stored(
    post: PosteriorDraws,
    model: BenchModel,
    max_draws: int = 2000,
    sd_grids: SdGrids | None = None,
    seed: int = 0,
    conditioning: Conditioning | None = None,
) -> Draws:
    """Prediction draws from ``posterior.nc`` read back (:func:`load_posterior`)."""
    unconverged = ""
    if not post.meta["diagnostics"]["converged"]:
        unconverged = "; the chain is NOT converged, see sample.json"
    noise = post.meta["noise"]
    return _chain_draws(
        post.values, noise, unconverged, model, max_draws, sd_grids, seed, conditioning
    )


def _chain_draws(
    chain: dict[str, np.ndarray],
    noise: str,
    unconverged: str,
    model: BenchModel,
    max_draws: int,
    sd_grids: SdGrids | None,
    seed: int,
    conditioning: Conditioning | None,
) -> Draws:
    """Draws from a posterior's kept draws (flat, by name), thinned evenly to
    ``max_draws``; the sds sampled, else from the fit's ``sd_grids``."""
    n = next(iter(chain.values())).size
    idx = _thin(n, max_draws)
    values = {k: chain[k][idx] for k in model.physical_names}
    sampled = {k: chain[k][idx] for k in SD_NAMES if k in chain}
    sds, how = _sds(sampled, sd_grids, idx.size, seed)
    note = f"posterior ({noise} noise, {idx.size} of {n} draws){how}"
    note += _conditioned(sds, conditioning) + unconverged
    return Draws(model, values, "posterior", note, sds, seed, conditioning)


def _conditioned(sds: dict, conditioning: Conditioning | None) -> str:
    if not sds:
        return ""
    if conditioning is None:
        return "; the discrepancy unconditional (not conditioned on the traces)"
    return "; the discrepancy conditioned on the traces' own friction ratios"


def draws_from_covariance(
    model: BenchModel,
    z: np.ndarray,
    cov_z: np.ndarray,
    max_draws: int = 2000,
    seed: int = 0,
    sd_grids: SdGrids | None = None,
    conditioning: Conditioning | None = None,
) -> Draws:
    """Gaussian draws on the internal scale from a fit's covariance: a local
    approximation of the posterior, mapped through the transforms; the sds from the
    fit's sd grids ``sd_grids``; the discrepancy conditioned on ``conditioning``."""
    k = model.n_physical
    rng = np.random.default_rng(seed)
    draws = rng.multivariate_normal(z[:k], cov_z[:k, :k], size=max_draws, method="eigh")
    values = {
        p.name: np.asarray(p.value(jnp.asarray(draws[:, i])))
        for i, p in enumerate(model.shared_params[:k])
    }
    sds, how = _sds({}, sd_grids, max_draws, seed)
    note = (
        "no posterior: Gaussian draws on the internal scale from the fit's covariance "
        "(a local approximation; run 'idtool sample' or Fit.sample() for the posterior)"
        + how
        + _conditioned(sds, conditioning)
    )
    return Draws(model, values, "fit covariance", note, sds, seed, conditioning)


def prediction_draws(fit: StoredFit, max_draws: int = 2000, seed: int = 0) -> Draws:
    """Posterior draws of a stored fit (``posterior.nc`` beside it), or Gaussian draws
    from its covariance when it has none."""
    path = Path(fit.folder) / POSTERIOR_FILE
    cond = fit.conditioning
    if path.is_file():
        stored = load_posterior(path)
        return draws_from_stored(stored, fit.model, max_draws, fit.sd_grids, seed, cond)
    return draws_from_covariance(fit.model, fit.z, fit.cov_z, max_draws, seed, fit.sd_grids, cond)


def extrapolation_notes(data: FitData, loads_n=(), amplitudes=(), speeds_m_s=()) -> list[str]:
    """One note per quantity whose requested values leave the range the fit saw."""
    notes = []
    for label, given, seen in (
        ("normal load", loads_n, data.normal_load_n),
        ("amplitude fraction", amplitudes, data.amplitude_fraction),
        ("pull speed", speeds_m_s, data.pull_speed_m_s),
    ):
        lo, hi = float(np.min(seen)), float(np.max(seen))
        out = [f"{v:.4g}" for v in given if v < lo * (1 - 1e-9) or v > hi * (1 + 1e-9)]
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
    """FR at one operating point: median and 95% band over draws.

    ``median``/``ci95``: the mean friction ratio at this operating point (the curve,
    its operating-point discrepancy included): what many pulls here average to.
    ``new_trace``: (median, (lo, hi)) of the next single pull, its scatter added.
    """

    normal_load_n: float
    amplitude_fraction: float
    pull_speed_m_s: float
    median: float
    ci95: tuple[float, float]
    new_trace: tuple[float, tuple[float, float]] | None = None

    @property
    def reduction_percent(self) -> tuple[float, tuple[float, float]]:
        """Median and 95% band of the reduction ``100 (1 - FR)``."""
        lo, hi = self.ci95
        return 100 * (1 - self.median), (100 * (1 - hi), 100 * (1 - lo))

    def to_dict(self) -> dict:
        red, (rlo, rhi) = self.reduction_percent
        nmed, (nlo, nhi) = self.new_trace or (self.median, self.ci95)
        return {
            "normal_load_n": self.normal_load_n,
            "amplitude_fraction": self.amplitude_fraction,
            "pull_speed_m_s": self.pull_speed_m_s,
            "friction_ratio": {"median": self.median, "ci95": list(self.ci95)},
            "new_trace": {"median": nmed, "ci95": [nlo, nhi]},
            "reduction_percent": {"median": red, "ci95": [rlo, rhi]},
        }


def _band(x: np.ndarray, axis: int = 0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    lo, med, hi = np.percentile(x, [2.5, 50.0, 97.5], axis=axis)
    return med, lo, hi


def friction_ratio_draws(
    draws: Draws, load_n, amplitude, speed_m_s
) -> tuple[np.ndarray, np.ndarray]:
    """Per draw, FR at the operating points ``(load_n[i] [N], amplitude[i] (fraction of
    the maximum), speed_m_s[i] [m/s])`` (equal-length sequences): the mean FR there
    (the curve with its discrepancy) and a next pull's (scatter added), each (draws,
    points); :func:`with_variability`. Every forward prediction goes through here."""
    load, alpha, speed = (np.asarray(x, float).reshape(-1) for x in (load_n, amplitude, speed_m_s))
    v = {k: jnp.asarray(x) for k, x in draws.values.items()}
    fr = np.asarray(
        _fr_draws(draws.model, v, jnp.asarray(load), jnp.asarray(alpha), jnp.asarray(speed))
    )
    return with_variability(fr, draws, np.asarray(operating_coordinates(load, alpha, speed)))


def predict_friction_ratio(draws: Draws, loads_n, amplitudes, speeds_m_s) -> list[Prediction]:
    """FR over the grid ``loads x amplitudes x speeds`` (in that order)."""
    grid = np.array(
        [(n, a, s) for n in loads_n for a in amplitudes for s in speeds_m_s], float
    ).reshape(-1, 3)
    mean, new = friction_ratio_draws(draws, grid[:, 0], grid[:, 1], grid[:, 2])
    return predictions_from_draws(grid, mean, new)


def predictions_from_draws(grid: np.ndarray, mean: np.ndarray, new: np.ndarray) -> list[Prediction]:
    """One :class:`Prediction` per row (load [N], amplitude fraction, speed [m/s]) of
    ``grid`` from :func:`friction_ratio_draws`' ``mean`` and ``new`` (draws, points)."""
    med, lo, hi = _band(mean)
    nmed, nlo, nhi = _band(new)
    return [
        Prediction(
            float(g[0]),
            float(g[1]),
            float(g[2]),
            float(m),
            (float(a), float(b)),
            (float(nm), (float(na), float(nb))),
        )
        for g, m, a, b, nm, na, nb in zip(grid, med, lo, hi, nmed, nlo, nhi, strict=True)
    ]


def with_variability(fr: np.ndarray, draws: Draws, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """FR draws (draws, points) of the physical curve at operating points ``x`` (points,
    3; :func:`~idtool._fit._discrepancy.operating_coordinates`) -> the mean FR at each
    point (the curve times exp(d), d the discrepancy given the data, per draw and point:
    :meth:`Draws.discrepancy`) and a new pull's FR (times exp(d + c), c ~ N(0,
    scatter_fr^2)); both capped at 1 (ultrasound does not raise friction; the simulator
    and the bench agree). Without sds, both are the curve."""
    if not draws.sds:
        return fr, fr
    rng = np.random.default_rng([draws.seed, 2])
    zero = np.zeros(fr.shape[0])
    d_mean, d_var = draws.discrepancy(x)
    disc = d_mean + np.sqrt(d_var) * rng.standard_normal(fr.shape)
    scatter = draws.sds.get("scatter_fr", zero)[:, None]
    new = disc + scatter * rng.standard_normal(fr.shape)
    return np.minimum(fr * np.exp(disc), 1.0), np.minimum(fr * np.exp(new), 1.0)


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
    amplitude."""
    x_rows, scales, weights, s_inv, sd = kriging

    def solve(v, weights, s_inv, sd, xi):
        def fr_at(alpha):
            fr = model.friction_ratios(v, load[None], alpha[None], speed[None])[0]
            x = operating_coordinates(load, alpha, speed)[None]
            mean, var = discrepancy_moments(x, x_rows, scales, weights, s_inv, sd)
            return jnp.minimum(fr * jnp.exp(mean[0] + jnp.sqrt(var[0]) * xi), 1.0)

        def step(_, bounds):
            lo, hi = bounds
            mid = 0.5 * (lo + hi)
            below = fr_at(mid) <= target_fr  # enough reduction already at mid
            return jnp.where(below, lo, mid), jnp.where(below, mid, hi)

        fr_full = fr_at(jnp.asarray(1.0))
        lo, hi = jax.lax.fori_loop(0, _BISECTIONS, step, (jnp.asarray(0.0), jnp.asarray(1.0)))
        alpha = jnp.where(fr_full <= target_fr, 0.5 * (lo + hi), jnp.inf)
        return alpha, fr_full

    return jax.vmap(solve)(v, weights, s_inv, sd, xi)


def amplitude_for_reduction(
    draws: Draws, target_reduction_percent: float, loads_n, speeds_m_s
) -> list[AmplitudeFor]:
    """The amplitude for ``target_reduction_percent`` at every load x speed."""
    target_fr = jnp.asarray(1.0 - target_reduction_percent / 100.0)
    v = {k: jnp.asarray(x) for k, x in draws.values.items()}
    # The mean curve carries the discrepancy: one standard normal per draw for its
    # conditional spread along the amplitude axis.
    xi = np.random.default_rng([draws.seed, 3]).standard_normal(draws.n)
    kriging = tuple(jnp.asarray(a) for a in draws.kriging)
    out = []
    for load in loads_n:
        for speed in speeds_m_s:
            alpha, fr_full = _amplitude_draws(
                draws.model,
                v,
                jnp.asarray(float(load)),
                jnp.asarray(float(speed)),
                target_fr,
                kriging,
                jnp.asarray(xi),
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
