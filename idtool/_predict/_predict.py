"""Predictions of the friction ratio from draws of the parameters (issue 5); the inverse
(the amplitude for a target) is :mod:`idtool._predict._amplitude`.

For every draw of the physical parameters, the contact model's friction ratio FR at an
operating point (normal load, commanded amplitude fraction, pull speed); the median and
the central 95% band over draws; the reduction is ``100 (1 - FR)`` %.

Draws come from ``posterior.nc`` when there is one; without it, from a Gaussian on the
fit's internal scale with the fit's covariance (say so: it is a local approximation).
This module knows draws, not where a chain lives: :func:`chain_draws` takes a chain's
kept draws by name, and :mod:`idtool._posterior._draws` hands it a posterior's (the
posterior stage predicts through this one, so this one never imports it).
"""

from __future__ import annotations

import dataclasses
import functools

import jax
import jax.numpy as jnp
import numpy as np

from idtool._data._blocks import FitData
from idtool._diagnostic import Diagnostic
from idtool._fit._cov import Covariance
from idtool._fit._discrepancy import Conditioning, discrepancy_moments, operating_coordinates
from idtool._fit._variability import ThetaGivenSds
from idtool._model._benchmodel import BenchModel

SD_NAMES = ("discrepancy_fr", "scatter_fr")  # the sds a prediction uses

__all__ = [
    "Draws",
    "Prediction",
    "chain_draws",
    "draws_from_covariance",
    "extrapolation_notes",
    "friction_ratio_draws",
    "predict_friction_ratio",
    "predictions_from_draws",
]


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
    # other coupling laws' draws, each as many as its BIC weight's share: predictions
    # pool them with these (:mod:`idtool._predict._mixture`); law -> weight of each
    mixture: tuple[Draws, ...] = ()
    law_weights: dict[str, float] = dataclasses.field(default_factory=dict)
    # this component's name in ``law_weights`` (its coupling law's when empty)
    label: str = ""

    @property
    def n(self) -> int:
        """Draws of this component (of its own law)."""
        return int(next(iter(self.values.values())).size)

    @functools.cached_property
    def components(self) -> tuple[Draws, ...]:
        """This law's draws, then each other law's (one component without a mixture)."""
        if not self.mixture:
            return (self,)
        return (dataclasses.replace(self, mixture=()), *self.mixture)

    def subset(self, idx: np.ndarray) -> Draws:
        """The draws at ``idx`` (of this component; no mixture)."""
        return dataclasses.replace(
            self,
            values={k: x[idx] for k, x in self.values.items()},
            sds={k: x[idx] for k, x in self.sds.items()},
            mixture=(),
        )

    @functools.cached_property
    def kriging(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Per draw, what the discrepancy's conditional moments need (arguments of
        :func:`~idtool._fit._discrepancy.discrepancy_moments` after ``x_new``): the
        distinct measured points' coordinates and length scales, ``P^T S^-1 (y - g)``,
        ``P^T S^-1 P`` (:meth:`~idtool._fit._discrepancy.Conditioning.weights`) and the
        sd; all zero but the sd without conditioning (the unconditional discrepancy)."""
        n = next(iter(self.sds.values())).size if self.sds else self.n
        zero = np.zeros(n)
        sd = self.sds.get("discrepancy_fr", zero)
        c = self.conditioning
        if c is None or not self.sds:
            return np.zeros((1, 3)), np.ones(3), np.zeros((n, 1)), np.zeros((n, 1, 1)), sd
        v = {k: jnp.asarray(x) for k, x in self.values.items()}
        # the model's FR at the distinct measured points only (Conditioning.rows): many
        # rows share one (repeats, ON windows of other lengths)
        load, alpha, speed = (jnp.asarray(r) for r in c.rows)
        g = np.log(np.asarray(_fr_draws(self.model, v, load, alpha, speed)))
        weights, s_inv = c.weights(g, sd, self.sds.get("scatter_fr", zero))
        return c.points, c.scales, weights, s_inv, sd

    def discrepancy(self, x_new: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Mean and variance of the discrepancy (log FR) at operating points ``x_new``
        (p, 3) per draw, given the data: (draws, p) each."""
        x_rows, scales, weights, s_inv, sd = self.kriging
        mean, var = _discrepancy_draws(jnp.asarray(x_new), x_rows, scales, weights, s_inv, sd)
        return np.asarray(mean), np.asarray(var)


# one compiled program per shape: run op by op, the same moments were ~15 programs each,
# compiled for every new number of points or draws (8 CPU s of the compilation in
# tests/test_variability.py and tests/test_artefact.py)
_discrepancy_draws = jax.jit(jax.vmap(discrepancy_moments, in_axes=(None, None, None, 0, 0, 0)))


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


def chain_draws(
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
    cov_z: Covariance,
    max_draws: int = 2000,
    seed: int = 0,
    sd_grids: SdGrids | None = None,
    conditioning: Conditioning | None = None,
    theta_given_sds: ThetaGivenSds | None = None,
) -> Draws:
    """Gaussian draws on the internal scale from a fit's covariance: a local
    approximation of the posterior, mapped through the transforms; the sds from the
    fit's sd grids ``sd_grids``; the discrepancy conditioned on ``conditioning``.

    With ``theta_given_sds`` (the levels model's covariance as a function of the sds,
    :class:`~idtool._fit._variability.ThetaGivenSds`) each draw's physical parameters
    are drawn given its own sds, ``theta_k ~ N(theta_hat, Sigma(s_k))`` with ``Sigma(s)
    = (G^T C(s)^-1 G)^-1``: an uncertain discrepancy or scatter widens the parameters'
    spread with it, as the planner's linear-Gaussian model has it
    (:mod:`idtool._plan._linear`). The mean stays at the estimate: the generalised
    least-squares estimate moves with the sds too, but its shift is of second order
    (the linearised model's residuals are small against their covariance). Without it
    (the levels model off, or a fit folder written before the Jacobian), every draw
    uses ``cov_z``'s block, the covariance at the REML sds (when the levels model is
    on the two are equal there: the fit sets its block to the levels model's)."""
    k = model.n_physical
    rng = np.random.default_rng(seed)
    sds, how = _sds({}, sd_grids, max_draws, seed)
    if theta_given_sds is not None and sds:
        draws = z[:k] + _conditional_steps(
            theta_given_sds, sds, rng.standard_normal((max_draws, k))
        )
        how = (
            "; the physical parameters drawn given each draw's sds (their covariance "
            "(G^T C(sds)^-1 G)^-1, the mean at the estimate)" + how
        )
    else:
        cov = _psd(cov_z.leading(k))  # the physical parameters' block: all the draws need
        draws = rng.multivariate_normal(
            z[:k], cov, size=max_draws, method="eigh", check_valid="ignore"
        )
        if sd_grids and theta_given_sds is None:
            how += (
                "; the physical parameters' covariance at the REML sds for every draw (a "
                "fit folder without the levels model's Jacobian: fit again for draws "
                "given each draw's sds)"
            )
    values = {
        p.name: np.asarray(p.value(np.asarray(draws[:, i], float)))
        for i, p in enumerate(model.shared_params[:k])
    }
    note = (
        "no posterior: Gaussian draws on the internal scale from the fit's covariance "
        "(a local approximation; run 'idtool sample' or Fit.sample() for the posterior)"
        + how
        + _conditioned(sds, conditioning)
    )
    return Draws(model, values, "fit covariance", note, sds, seed, conditioning)


def _psd(block: np.ndarray) -> np.ndarray:
    """A covariance block symmetrised, its spectrum clipped at zero: a degenerate fit (a
    parameter at its bound, a direction the data do not inform: the fit warns of both)
    leaves round-off below zero in the pseudo-inverse's spectrum; those directions get
    no spread."""
    cov = 0.5 * (block + block.T)
    s, v = np.linalg.eigh(cov)
    if s.min() < 0.0:
        cov = (v * np.clip(s, 0.0, None)) @ v.T
    return cov


def _conditional_steps(
    theta_given_sds: ThetaGivenSds, sds: dict[str, np.ndarray], eps: np.ndarray
) -> np.ndarray:
    """Per draw, ``theta_k - theta_hat = R(s_k) eps_k`` (draws, k), ``R(s) R(s)^T =
    Sigma(s)`` (its eigenvectors times the square roots of its eigenvalues, clipped at
    zero as :func:`_psd`), from standard normals ``eps`` (draws, k) and the draws' sds.
    The sds come from grids, so many draws share theirs (the spike at zero, the grid's
    cells): ``Sigma`` is factored once per distinct draw of the sds."""
    names = list(sds)
    table = np.stack([np.asarray(sds[n], float) for n in names], axis=1)
    distinct, where = np.unique(table, axis=0, return_inverse=True)
    where = np.ravel(where)
    out = np.empty_like(eps)
    for i, row in enumerate(distinct):
        cov = theta_given_sds.at(dict(zip(names, row, strict=True)))
        s, v = np.linalg.eigh(0.5 * (cov + cov.T))
        root = v * np.sqrt(np.clip(s, 0.0, None))
        mine = where == i
        out[mine] = eps[mine] @ root.T
    return out


def extrapolation_notes(data: FitData, loads_n=(), amplitudes=(), speeds_m_s=()) -> list[str]:
    """One note per quantity whose requested values leave the range the fit saw."""
    notes: list[str] = []
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
                Diagnostic(
                    "extrapolation",
                    f"{label} {vals} lies outside the fitted range [{lo:g}, {hi:g}]: extrapolation",
                    quantity=label,
                    values=[float(v) for v in given if v < lo * (1 - 1e-9) or v > hi * (1 + 1e-9)],
                    range=(lo, hi),
                )
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
    # averaged over coupling laws: each law's median mean FR, (law, median), chosen first
    by_law: tuple[tuple[str, float], ...] = ()

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
        } | ({"by_coupling_law": dict(self.by_law)} if self.by_law else {})


def _band(x: np.ndarray, axis: int = 0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    lo, med, hi = np.percentile(x, [2.5, 50.0, 97.5], axis=axis)
    return med, lo, hi


def friction_ratio_draws(
    draws: Draws, load_n, amplitude, speed_m_s
) -> tuple[np.ndarray, np.ndarray]:
    """Per draw, FR at the operating points ``(load_n[i] [N], amplitude[i] (fraction of
    the maximum), speed_m_s[i] [m/s])`` (equal-length sequences): the mean FR there
    (the curve with its discrepancy) and a next pull's (scatter added), each (draws,
    points); :func:`with_variability`. Every forward prediction goes through here;
    averaged over coupling laws, every law's draws pooled."""
    if draws.mixture:
        parts = [friction_ratio_draws(c, load_n, amplitude, speed_m_s) for c in draws.components]
        return np.concatenate([m for m, _ in parts]), np.concatenate([n for _, n in parts])
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
    out = predictions_from_draws(grid, mean, new)
    if not draws.mixture:
        return out
    # each law's own median curve, for the report and to show where the laws disagree
    medians, start = [], 0
    for c in draws.components:
        name = c.label or c.model.coupling.name
        medians.append((name, np.median(mean[start : start + c.n], axis=0)))
        start += c.n
    return [
        dataclasses.replace(p, by_law=tuple((law, float(m[i])) for law, m in medians))
        for i, p in enumerate(out)
    ]


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
