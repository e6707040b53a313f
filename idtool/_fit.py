"""Joint least-squares fit of a dataset: multi-start Levenberg-Marquardt with a coloured
Jacobian (:mod:`idtool._lm`), AR(1) noise, Gauss-Newton covariance and identifiability
checks.

Procedure (one friction law, one coupling law):

1. Start values for the bench nuisances come from the data (:func:`start_values`).
2. Multi-start: from ``n_starts`` quasi-random points over the physical parameters
   (seeded; the coupling gain set through a velocity ratio below 1, see
   :func:`_start_point`), Levenberg-Marquardt moves every parameter, for a short step
   budget. Joint end points rank basins by their real loss (held nuisances let a
   spurious low-Kt basin win on two-load designs), and with the coloured Jacobian a
   step costs the same whichever parameters move. Distinct optima are summarised.
3. The lowest end point is taken to convergence. The lag-1 autocorrelation ``phi`` of
   the block residuals is estimated and the fit repeated on AR(1)-whitened residuals
   until ``phi`` settles: load-cell noise is correlated, and treating it as
   independent would make every interval too narrow.
4. Covariance ``sigma^2 (J^T J)^-1`` of the whitened problem, on the internal scale;
   95% intervals are mapped through the transforms (so they respect the bounds).
"""

from __future__ import annotations

import collections
import dataclasses
import math
from collections.abc import Callable

import jax
import jax.numpy as jnp
import numpy as np

from ._dataset import Dataset
from ._fitdata import FitData, prepare_fit_data, start_values
from ._fitmodel import FitModel
from ._lm import LMResult, levenberg_marquardt

__all__ = [
    "Z95",
    "Z_AT_BOUND",
    "Estimate",
    "FitResult",
    "compiled_lm",
    "fit_model",
    "fit_start",
    "model_for",
    "quasi_random",
]

Z95 = 1.959963984540054
# Internal scale: a bounded parameter beyond this sits at its bound (sigmoid > 0.999).
Z_AT_BOUND = 7.0
# Steps per multi-start run: enough to rank the basins (a joint fit from a start takes
# 20-40); the best is then continued. 10 of 10 two-load designs found the true basin.
_MULTISTART_STEPS = 20
_POLISH_STEPS = 100
# XLA's newer CPU fusion emitters compile the fit's programs ~30% slower for the same
# run time (2.6 s vs 1.9 s for the LM loop on the example; benchmarks/bench_fit.py).
_COMPILE = {"xla_cpu_use_fusion_emitters": False}
# Plausible region for multi-start points (the bounds themselves are much wider).
_START_BOX = {
    "Kt": (1e6, 1e11),
    "coupling_gain": (1e-3, 0.3),
    "power_load_n": (20.0, 2000.0),
    "static_ratio": (1.0, 2.0),
    "stribeck_velocity_m_s": (1e-3, 0.1),
}


@dataclasses.dataclass(frozen=True)
class Estimate:
    """A parameter's estimate, standard error and 95% interval, in its unit."""

    name: str
    unit: str
    estimate: float
    std_error: float
    ci95: tuple[float, float]
    at_bound: bool = False


@dataclasses.dataclass(frozen=True)
class FitResult:
    """Everything one fit found; ``model`` and ``z`` reproduce every prediction."""

    model: FitModel
    z: np.ndarray
    cov_z: np.ndarray
    phi: float
    sigma_n: float
    rss: float
    loglik: float
    estimates: dict[str, Estimate]
    correlation: np.ndarray
    friction_ratio: np.ndarray
    friction_ratio_se: np.ndarray
    optima: list[dict]
    warnings: list[str]
    lm_steps: int
    jacobian_evaluations: int  # linearisations: residuals plus one JVP per colour

    @property
    def n_data(self) -> int:
        return self.model.data.n_blocks

    @property
    def n_params(self) -> int:
        return int(self.z.size) + 2  # + noise sigma and AR(1) phi

    @property
    def aic(self) -> float:
        return 2 * self.n_params - 2 * self.loglik

    @property
    def bic(self) -> float:
        return self.n_params * math.log(self.n_data) - 2 * self.loglik


def compiled_lm(model: FitModel) -> Callable[..., LMResult]:
    """The compiled Levenberg-Marquardt run of ``model``: ``lm(z0, mask, phi,
    max_steps)`` fits the AR(1)-whitened residuals (:meth:`FitModel.normal_equations`)
    and returns them with the per-trace levels. Compiled once, cached on the model, and
    reused by every start, polish, AR(1) round and profile point."""
    cached = model.__dict__.get("_compiled_lm")
    if cached is None:

        def lm(z0, mask, phi, max_steps):
            return levenberg_marquardt(model.normal_equations, z0, phi, mask, max_steps)

        cached = model.__dict__["_compiled_lm"] = jax.jit(lm, compiler_options=_COMPILE)
    return cached  # (frozen dataclass: cached beside its fields)


# A second fit of the same prepared data (other seed, profile, benchmark) reuses the
# model and so its compiled programs; a few recent ones are kept.
_MODELS: collections.OrderedDict[tuple, tuple[FitData, FitModel]] = collections.OrderedDict()


def model_for(data: FitData, law: str, coupling: str) -> FitModel:
    """The :class:`FitModel` of ``data`` (the same object for the same data and laws)."""
    key = (id(data), law, coupling)
    hit = _MODELS.get(key)
    if hit is not None and hit[0] is data:
        _MODELS.move_to_end(key)
        return hit[1]
    model = FitModel(data, start_values(data), law=law, coupling=coupling)
    _MODELS[key] = (data, model)
    while len(_MODELS) > 4:
        _MODELS.popitem(last=False)
    return model


def _ar1(e: np.ndarray, data: FitData) -> float:
    """Pooled lag-1 autocorrelation of residuals within traces."""
    first = np.zeros(e.size, bool)
    first[data.first_block] = True
    num = np.sum((e[1:] * e[:-1])[~first[1:]])
    return float(np.clip(num / np.sum(e**2), -0.99, 0.99))


def _unwhiten(w: np.ndarray, phi: float, data: FitData) -> np.ndarray:
    """Residuals ``e`` from AR(1)-whitened ones (inverse of FitModel.residuals'
    whitening): ``e_1 = w_1 / sqrt(1 - phi^2)``, ``e_t = w_t + phi e_(t-1)``."""
    e = np.array(w, float)
    starts = set(np.asarray(data.first_block).tolist())
    for t in range(e.size):
        if t in starts:
            e[t] = w[t] / math.sqrt(1.0 - phi**2)
        else:
            e[t] = w[t] + phi * e[t - 1]
    return e


def _loglik(w: np.ndarray, phi: float, n_traces: int) -> tuple[float, float]:
    """Exact Gaussian AR(1) log-likelihood at the MLE of sigma; and that sigma."""
    n = w.size
    s2 = float(np.sum(w**2) / n)
    return -0.5 * n * (math.log(2 * math.pi * s2) + 1) + 0.5 * n_traces * math.log(
        1 - phi**2
    ), math.sqrt(s2)


def _distinct(points: list[dict], rel: float = 1e-6, near: float = 0.05) -> list[dict]:
    """Group multi-start end points into optima, best first.

    Two end points are the same optimum if their losses agree to ``rel`` (a flat or
    saturated direction can leave them apart) or if they lie within ``near`` of each
    other on the internal scale in every physical parameter (a start stopped by its step
    budget short of the bottom of the same basin; standard errors there are ~0.01).
    """
    groups: list[dict] = []
    for p in sorted(points, key=lambda p: p["rss"]):
        for g in groups:
            same_loss = abs(p["rss"] - g["rss"]) <= rel * max(g["rss"], 1e-300) + 1e-12
            if same_loss or np.max(np.abs(p["z"] - g["z"])) < near:
                g["count"] += 1
                break
        else:
            groups.append(p | {"count": 1})
    return groups


def _start_point(model: FitModel, u: np.ndarray) -> dict[str, float]:
    """Physical start values from a point ``u`` of the unit cube.

    Log-uniform over :data:`_START_BOX`, except the coupling gain: it is set from a
    velocity ratio VR in [0.05, 0.95] at a reference operating point (largest commanded
    amplitude, median load). A gain drawn blindly often leaves every trace at VR >= 1,
    where FR = 1 exactly and the loss is flat in the coupling: a plateau that the
    optimiser crawls along for dozens of steps, while the data show FR < 1.
    """
    d = model.data
    start: dict[str, float] = {}
    for j, p in enumerate(model.specs[: len(u)]):
        if p.name in _START_BOX and p.name != "coupling_gain":
            lo, hi = _START_BOX[p.name]
            start[p.name] = float(np.exp(np.log(lo) + u[j] * (np.log(hi) - np.log(lo))))
    j = model.names.index("coupling_gain")
    ref = np.lexsort((np.abs(d.normal_load_n - np.median(d.normal_load_n)), -d.amplitude_fraction))[
        0
    ]
    w = 2.0 * np.pi * d.vibration_frequency_hz
    amplitude = d.pull_speed_m_s[ref] / ((0.05 + 0.9 * u[j]) * w)
    unit = model.coupling_of(
        {
            "coupling_gain": jnp.asarray(1.0),
            "power_load_n": jnp.asarray(start.get("power_load_n", 1.0)),
        }
    )
    per_gain = float(
        unit.amplitude_m(d.amplitude_fraction[ref], d.normal_load_n[ref], d.max_amplitude_m)
    )
    spec = model.specs[j]
    start["coupling_gain"] = float(np.clip(amplitude / per_gain, 1.01 * spec.lo, 0.99 * spec.hi))
    return start


def quasi_random(n: int, d: int, seed: int) -> np.ndarray:
    """``n`` quasi-random points in the unit cube ``[0, 1)^d``, randomly shifted by ``seed``.

    Richtmyer's Kronecker sequence ``frac(shift + i sqrt(p_j))`` over the first primes
    ``p_j``: low discrepancy for every ``n`` (not only powers of two, as Sobol points),
    each coordinate's gaps below ~2/n, and no scipy.stats import (half a second of the
    time to a first fit). Up to 12 dimensions.
    """
    primes = np.array([2, 3, 5, 7, 11, 13, 17, 19, 23, 29, 31, 37], float)
    if not 1 <= d <= primes.size:
        raise ValueError(f"d = {d}: quasi_random supports 1 to {primes.size} dimensions")
    alpha = np.sqrt(primes[:d]) % 1.0
    shift = np.random.default_rng(seed).random(d)
    return (shift + np.arange(1, n + 1)[:, None] * alpha) % 1.0


def fit_start(dataset: Dataset, mains_hz: float = 50.0, **kw) -> FitData:
    """Prepare the dataset for fitting (block means over whole mains periods)."""
    return prepare_fit_data(dataset, mains_hz=mains_hz, **kw)


def fit_model(
    data: FitData,
    law: str = "dahl",
    coupling: str = "power-limited",
    seed: int = 0,
    n_starts: int = 8,
) -> FitResult:
    """Fit one law and coupling to prepared data; see the module docstring."""
    model = model_for(data, law, coupling)
    lm = compiled_lm(model)
    k = len(model.physical_names)
    base = model.z0()
    everything = jnp.ones(base.size, bool)
    count = {"steps": 0, "jacobians": 0}

    def run(z, mask, phi, max_steps):
        out = lm(jnp.asarray(z), mask, phi, max_steps)
        count["steps"] += int(out.steps)
        count["jacobians"] += int(out.n_jacobians)
        return out

    # 2. multi-start: from each quasi-random point of the physical parameters (the
    # nuisances at their data-driven start values) everything is fitted jointly. A step
    # costs the same whichever parameters move, and joint end points rank basins by
    # their real loss: held nuisances ranked a spurious low-Kt basin first on two-load
    # designs (nuisance misfit was ~60x the final loss there).
    points, ends = [], []
    for u in quasi_random(n_starts, k, seed):
        start = _start_point(model, u)
        z = base.copy()
        z[:k] = model.z0(**start)[:k]
        out = run(z, everything, 0.0, _MULTISTART_STEPS)
        ends.append(out)
        points.append(
            {
                "z": np.asarray(out.z)[:k],
                "rss": 2.0 * float(out.loss),
                "converged": bool(out.converged),
                "start": start,
            }
        )
    optima = _distinct(points)

    # 3. the lowest end point, taken to convergence
    best = min(ends, key=lambda o: float(o.loss))
    if not bool(best.converged):
        best = run(best.z, everything, 0.0, _POLISH_STEPS)

    # then AR(1) whitening until phi settles
    phi = 0.0
    for _ in range(3):
        new_phi = _ar1(_unwhiten(np.asarray(best.residuals), phi, data), data)
        # Stop once phi settles (the estimates then move far less than their errors);
        # phi stays the one the parameters were fitted with.
        if abs(new_phi - phi) < 0.02:
            break
        phi = new_phi
        best = run(best.z, everything, phi, _POLISH_STEPS)
    return _summarise(model, best, phi, optima, count)


def _values_and_jacobian(
    model: FitModel, z: np.ndarray, levels: np.ndarray, dlevels: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Every parameter's value in its unit, then each trace's friction ratio ON/OFF;
    and their Jacobian in ``z``, from the levels and their derivatives that the last
    linearisation of the fit computed (so no further program to compile)."""
    specs = model.specs
    p, m, k = len(specs), model.data.n_traces, len(model.physical_names)
    vals, jac = np.empty(p + m), np.zeros((p + m, p))
    for i, spec in enumerate(specs):
        vals[i], jac[i, i] = float(spec.value(z[i])), spec.slope(z[i])
    off, on = levels[:m], levels[m:]
    vals[p:] = on / off
    jac[p:, :k] = (dlevels[m:] * off[:, None] - on[:, None] * dlevels[:m]) / off[:, None] ** 2
    return vals, jac


def _summarise(
    model: FitModel, best: LMResult, phi: float, optima: list[dict], count: dict[str, int]
) -> FitResult:
    data = model.data
    z = np.asarray(best.z)
    w = np.asarray(best.residuals)
    n, p = w.size, z.size
    rss = float(w @ w)
    sigma2 = rss / (n - p)
    jtj = np.asarray(best.jtj)
    converged = bool(best.converged)
    # A parameter the data do not move at all (saturated at a bound) has a zero column;
    # the bound warning below names it.
    scale = np.sqrt(np.diag(jtj))
    scale = np.where(scale > 0.0, scale, 1.0)
    scaled = jtj / np.outer(scale, scale)
    evals, evecs = np.linalg.eigh(scaled)
    cov = sigma2 * np.linalg.pinv(scaled, rcond=1e-13, hermitian=True) / np.outer(scale, scale)
    se_z = np.sqrt(np.maximum(np.diag(cov), 0.0))
    se_safe = np.where(se_z > 0.0, se_z, 1.0)
    corr = cov / np.outer(se_safe, se_safe)

    # delta method for the physical values (and the per-trace friction ratios)
    vals, dvals = _values_and_jacobian(model, z, *(np.asarray(x) for x in best.aux))
    se_vals = np.sqrt(np.maximum(np.einsum("ij,jk,ik->i", dvals, cov, dvals), 0.0))

    warnings: list[str] = []
    estimates: dict[str, Estimate] = {}
    specs = model.specs
    for i, spec in enumerate(specs):
        value, se = float(vals[i]), float(se_vals[i])
        if spec.bounded:
            lo = float(spec.value(z[i] - Z95 * se_z[i]))
            hi = float(spec.value(z[i] + Z95 * se_z[i]))
            at_bound = abs(z[i]) > Z_AT_BOUND
        else:
            lo, hi, at_bound = value - Z95 * se, value + Z95 * se, False
        estimates[spec.name] = Estimate(spec.name, spec.unit, value, se, (lo, hi), at_bound)
        if spec.physical and at_bound:
            warnings.append(
                f"{spec.name} = {value:.4g} {spec.unit} sits at the bound of its range "
                f"[{spec.lo:g}, {spec.hi:g}]: the data push it outside what the model allows"
            )
        elif spec.physical and spec.bounded and hi / max(lo, 1e-300) > 100.0:
            warnings.append(
                f"{spec.name}: its 95% interval spans more than a factor of 100 "
                f"({lo:.3g} to {hi:.3g} {spec.unit}); the data cannot inform it"
            )
    k = len(model.physical_names)
    for a in range(k):
        for b in range(a + 1, k):
            if abs(corr[a, b]) > 0.95:
                warnings.append(
                    f"{names_of(specs)[a]} and {names_of(specs)[b]} are correlated at "
                    f"{corr[a, b]:+.3f}: the data mostly inform a combination of the two"
                )
    if evals[0] < 1e-12 * evals[-1]:
        v = evecs[:, 0]
        top = np.argsort(-np.abs(v))[:3]
        combo = ", ".join(f"{specs[j].name} ({v[j]:+.2f})" for j in top)
        warnings.append(f"near-singular direction in parameter space: {combo}")
    loads = np.unique(data.normal_load_n)
    if model.coupling == "power-limited" and loads.size == 1:
        warnings.append(
            f"all traces share one normal load ({loads[0]:g} N): the power limit only shows "
            "through the load dependence, so the constant and power-limited couplings "
            "cannot be told apart; use --coupling constant or add loads"
        )
    if not converged:
        warnings.append("Levenberg-Marquardt stopped before its tolerance; check the fit")

    offs = len(specs)
    fr = vals[offs : offs + data.n_traces]
    fr_se = se_vals[offs : offs + data.n_traces]
    loglik, sigma = _loglik(w, phi, data.n_traces)
    return FitResult(
        model=model,
        z=z,
        cov_z=cov,
        phi=phi,
        sigma_n=sigma,
        rss=rss,
        loglik=loglik,
        estimates=estimates,
        correlation=corr,
        friction_ratio=fr,
        friction_ratio_se=fr_se,
        optima=optima,
        warnings=warnings,
        lm_steps=count["steps"],
        jacobian_evaluations=count["jacobians"],
    )


def names_of(specs) -> list[str]:
    return [s.name for s in specs]
