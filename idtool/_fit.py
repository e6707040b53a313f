"""Joint least-squares fit of a dataset: multi-start Levenberg-Marquardt (optimistix),
AR(1) noise, Gauss-Newton covariance and identifiability checks.

Procedure (one friction law, one coupling law):

1. Start values for the bench nuisances come from the data (:func:`start_values`).
2. Multi-start: from ``n_starts`` scrambled-Sobol points over the physical parameters
   (seeded), Levenberg-Marquardt moves the physical parameters only, nuisances held at
   their start values: cheap, and enough to find the basins. Distinct optima are
   summarised.
3. The best optimum is polished jointly (all parameters). The lag-1 autocorrelation
   ``phi`` of the block residuals is estimated and the fit repeated on AR(1)-whitened
   residuals until ``phi`` settles: load-cell noise is correlated, and treating it as
   independent would make every interval too narrow.
4. Covariance ``sigma^2 (J^T J)^-1`` of the whitened problem, on the internal scale;
   95% intervals are mapped through the transforms (so they respect the bounds).
"""

from __future__ import annotations

import dataclasses
import math

import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx
from scipy.stats import qmc

from ._dataset import Dataset
from ._fitdata import FitData, prepare_fit_data, start_values
from ._fitmodel import TRACE_GROUPS, FitModel

__all__ = ["Estimate", "FitResult", "fit_model", "fit_start"]

_Z95 = 1.959963984540054
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
    residual_evaluations: int
    # The compiled solvers of this model, kept for profiling without recompiling.
    solvers: tuple = dataclasses.field(default=(), repr=False, compare=False)

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


def _solver(rtol: float = 1e-7):
    # Stops when a step changes the parameters by less than rtol (relative, on the
    # internal scale) and the loss by less than rtol: 1e-7 is far below the standard
    # errors (>1e-3 on that scale), so tighter only costs iterations.
    return optx.LevenbergMarquardt(rtol=rtol, atol=rtol)


def _make_solvers(model: FitModel):
    """Compiled LM runs: physical parameters only, and all parameters under a mask."""
    k = len(model.physical_names)

    def run_physical(zp, base, phi):
        def fn(y, _):
            return model.residuals(base.at[:k].set(y), phi)

        sol: optx.Solution = optx.least_squares(fn, _solver(), zp, max_steps=60, throw=False)
        return sol.value, sol.stats["num_steps"], sol.result == optx.RESULTS.successful

    def run_masked(z0, mask, phi):
        def fn(y, _):
            return model.residuals(jnp.where(mask, y, z0), phi)

        sol: optx.Solution = optx.least_squares(fn, _solver(), z0, max_steps=80, throw=False)
        z = jnp.where(mask, sol.value, z0)
        return z, sol.stats["num_steps"], sol.result == optx.RESULTS.successful

    return jax.jit(run_physical), jax.jit(run_masked), jax.jit(model.residuals)


def _ar1(e: np.ndarray, data: FitData) -> float:
    """Pooled lag-1 autocorrelation of residuals within traces."""
    first = np.zeros(e.size, bool)
    first[data.first_block] = True
    num = np.sum((e[1:] * e[:-1])[~first[1:]])
    return float(np.clip(num / np.sum(e**2), -0.99, 0.99))


def _loglik(w: np.ndarray, phi: float, n_traces: int) -> tuple[float, float]:
    """Exact Gaussian AR(1) log-likelihood at the MLE of sigma; and that sigma."""
    n = w.size
    s2 = float(np.sum(w**2) / n)
    return -0.5 * n * (math.log(2 * math.pi * s2) + 1) + 0.5 * n_traces * math.log(
        1 - phi**2
    ), math.sqrt(s2)


def _distinct(points: list[dict], rel: float = 1e-6) -> list[dict]:
    """Group multi-start end points that share a loss and a location."""
    groups: list[dict] = []
    for p in sorted(points, key=lambda p: p["rss"]):
        for g in groups:
            same_loss = abs(p["rss"] - g["rss"]) <= rel * max(g["rss"], 1e-300) + 1e-12
            # Same loss to 1e-6: the same optimum, even where a flat or saturated
            # direction leaves the end points apart.
            if same_loss:
                g["count"] += 1
                break
        else:
            groups.append(p | {"count": 1})
    return groups


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
    model = FitModel(data, start_values(data), law=law, coupling=coupling)
    run_physical, run_masked, residuals = _make_solvers(model)
    names = model.names
    k = len(model.physical_names)
    base = jnp.asarray(model.z0())
    steps = 0

    # 2. multi-start over the physical parameters
    sobol = qmc.Sobol(d=k, scramble=True, seed=seed).random(n_starts)
    points = []
    for u in sobol:
        start = {}
        for j, p in enumerate(model.specs[:k]):
            if p.name in _START_BOX:
                lo, hi = _START_BOX[p.name]
                start[p.name] = float(np.exp(np.log(lo) + u[j] * (np.log(hi) - np.log(lo))))
        zp = jnp.asarray(model.z0(**start)[:k])
        y, n, ok = run_physical(zp, base, 0.0)
        steps += int(n)
        z = np.asarray(base.at[:k].set(y))
        rss = float(jnp.sum(residuals(jnp.asarray(z), 0.0) ** 2))
        points.append({"z": z[:k], "rss": rss, "converged": bool(ok), "start": start})
    optima = _distinct(points)

    # 3. joint polish, then AR(1) whitening until phi settles
    zj = jnp.asarray(base.at[:k].set(optima[0]["z"]))
    mask = jnp.ones(len(names), bool)
    phi = 0.0
    converged = True
    for round_ in range(3):
        zj, n, ok = run_masked(zj, mask, phi)
        steps += int(n)
        converged = bool(ok)
        new_phi = _ar1(np.asarray(residuals(zj, 0.0)), data)
        # Stop once phi settles (the estimates then move far less than their errors);
        # phi stays the one the parameters were fitted with.
        if abs(new_phi - phi) < 0.02 or round_ == 2:
            break
        phi = new_phi
    result = _summarise(model, np.asarray(zj), phi, optima, steps, converged)
    return dataclasses.replace(result, solvers=(run_physical, run_masked, residuals))


def _summarise(
    model: FitModel, z: np.ndarray, phi: float, optima: list[dict], steps: int, converged: bool
) -> FitResult:
    data = model.data
    zj = jnp.asarray(z)
    w = np.asarray(jax.jit(model.residuals)(zj, phi))
    jac = np.asarray(jax.jit(jax.jacfwd(model.residuals))(zj, phi))
    n, p = jac.shape
    rss = float(w @ w)
    sigma2 = rss / (n - p)
    jtj = jac.T @ jac
    scale = np.sqrt(np.maximum(np.diag(jtj), 1e-300))
    scaled = jtj / np.outer(scale, scale)
    evals, evecs = np.linalg.eigh(scaled)
    cov = sigma2 * np.linalg.pinv(scaled, rcond=1e-13) / np.outer(scale, scale)
    se_z = np.sqrt(np.maximum(np.diag(cov), 0.0))
    corr = cov / np.outer(np.maximum(se_z, 1e-300), np.maximum(se_z, 1e-300))

    # delta method for the physical values (and the per-trace friction ratios)
    n_shared = model.n_shared

    def flat_values(zz):
        v = model.values(zz)
        _, _, fr = model.levels(v)
        shared = jnp.stack([v[s.name] for s in model.specs[:n_shared]])
        return jnp.concatenate([shared, *(v[g] for g, _, _ in TRACE_GROUPS), fr])

    dvals = np.asarray(jax.jit(jax.jacfwd(flat_values))(zj))
    vals = np.asarray(jax.jit(flat_values)(zj))
    se_vals = np.sqrt(np.maximum(np.einsum("ij,jk,ik->i", dvals, cov, dvals), 0.0))

    warnings: list[str] = []
    estimates: dict[str, Estimate] = {}
    specs = model.specs
    for i, spec in enumerate(specs):
        value, se = float(vals[i]), float(se_vals[i])
        if spec.bounded:
            lo = float(spec.value(z[i] - _Z95 * se_z[i]))
            hi = float(spec.value(z[i] + _Z95 * se_z[i]))
            at_bound = abs(z[i]) > 7.0
        else:
            lo, hi, at_bound = value - _Z95 * se, value + _Z95 * se, False
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
        lm_steps=steps,
        residual_evaluations=steps,
    )


def names_of(specs) -> list[str]:
    return [s.name for s in specs]
