"""Posterior predictive check (issue 5): replicated traces against the measured ones.

For ``n_draws`` posterior draws: the block-mean model trace (with each trace's nuisances
at their conditional mode given the draw) plus a fresh noise series from the draw's
noise model (AR(1) started in its stationary state, Gaussian or Student-t innovations).
Reported: the 95% band of the replicated block means over the measured ones (and the
band of the noise-free model), the fraction of measured block means inside the band
(about 0.95 if the model is right), and the pooled lag-1 autocorrelation of the
residuals, measured against replicated, with its posterior predictive p-value: an
independent-noise model fails this check on load-cell data (p near 0).
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from idtool._atomic import atomic_file
from idtool._plotting import MAX_WIDTH_IN, save_figure, subplots
from idtool._posterior._likelihood import (
    Target,
    build_target,
    marginal_loglik,
    physical_values,
    predict_blocks,
)
from idtool._posterior._record import FitLike, PosteriorRecord

__all__ = ["PredictiveCheck", "plot_predictive", "posterior_predictive", "replicate_blocks"]


@dataclasses.dataclass(frozen=True)
class PredictiveCheck:
    """Per block: the measured mean and the bands; the summary statistics."""

    time_s: np.ndarray
    trace: np.ndarray
    measured: np.ndarray
    median: np.ndarray
    band: tuple[np.ndarray, np.ndarray]  # replicated block means, 95%
    model_band: tuple[np.ndarray, np.ndarray]  # noise-free model, 95%
    inside_fraction: float
    lag1_measured: float  # posterior mean of the measured residuals' lag-1 autocorrelation
    lag1_replicated: tuple[float, float]  # 95% band over replicated series
    lag1_p_value: float

    def to_dict(self) -> dict:
        return {
            "inside_95_band_fraction": self.inside_fraction,
            "lag1_autocorrelation": {
                "measured": self.lag1_measured,
                "replicated_ci95": list(self.lag1_replicated),
                "p_value": self.lag1_p_value,
            },
        }


def _model_means(theta: jax.Array, target: Target) -> jax.Array:
    v = physical_values(theta, target)
    pred = predict_blocks(v, target)
    _, shift = marginal_loglik(pred - target.force_n, v, target)
    return pred + jnp.sum(target.jac_e * shift[target.model.data.block_trace], axis=1)


_means = jax.jit(jax.vmap(_model_means, in_axes=(0, None)))


def _lag1(e: np.ndarray, first: np.ndarray) -> np.ndarray:
    """Pooled within-trace lag-1 autocorrelation of each row of ``e``."""
    e = e - e.mean(axis=1, keepdims=True)
    prod = (e[:, 1:] * e[:, :-1])[:, ~first[1:]]
    return prod.sum(axis=1) / np.sum(e**2, axis=1)


def replicate_blocks(theta: np.ndarray, target: Target, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """Replicated block means [N] (draws, blocks) for internal draws ``theta`` (draws,
    ndim): the model at each draw, its nuisances at their conditional mode, plus the
    noise model's noise at the draw (:meth:`AbstractNoise.simulate`, seeded); and the
    noise-free model means."""
    means = np.asarray(_means(jnp.asarray(theta), target))
    by_name = {
        p.name: np.asarray(p.value(np.asarray(theta[:, i], float)))
        for i, p in enumerate(target.params)
    }
    rng = np.random.default_rng(seed)
    noise = target.model.noise.simulate(rng, by_name, np.asarray(target.first))
    return means + noise, means


def posterior_predictive(
    post: PosteriorRecord,
    fit: FitLike,
    n_draws: int = 200,
    seed: int = 0,
    target: Target | None = None,
) -> PredictiveCheck:
    """Replicate the measured traces from ``n_draws`` kept draws of ``post``."""
    if target is None:
        target = build_target(fit.model, post.z_lin, post.noise, post.priors)
    kept = post.chain[post.diagnostics.burn :].reshape(-1, post.chain.shape[-1])
    idx = np.unique(np.linspace(0, kept.shape[0] - 1, min(n_draws, kept.shape[0])).astype(int))
    replicated, means = replicate_blocks(kept[idx], target, seed)
    noise = replicated - means
    first = np.asarray(target.first)
    measured = np.asarray(target.force_n)
    lo, med, hi = np.percentile(replicated, [2.5, 50.0, 97.5], axis=0)
    mlo, mhi = np.percentile(means, [2.5, 97.5], axis=0)
    lag_meas = _lag1(measured[None, :] - means, first)
    lag_rep = _lag1(noise, first)
    d = fit.model.data
    return PredictiveCheck(
        time_s=np.asarray(d.block_time_s),
        trace=np.asarray(d.block_trace),
        measured=measured,
        median=med,
        band=(lo, hi),
        model_band=(mlo, mhi),
        inside_fraction=float(np.mean((measured >= lo) & (measured <= hi))),
        lag1_measured=float(np.mean(lag_meas)),
        lag1_replicated=(float(np.percentile(lag_rep, 2.5)), float(np.percentile(lag_rep, 97.5))),
        lag1_p_value=float(np.mean(lag_rep >= lag_meas)),
    )


def plot_predictive(check: PredictiveCheck, trace_ids: tuple[str, ...], path: str | Path) -> Path:
    """``ppc.png``: every trace with its bands, and the autocorrelation check."""
    n = len(trace_ids)
    cols = 4
    rows = int(np.ceil((n + 1) / cols))
    fig, axes = subplots(rows, cols, figsize=(MAX_WIDTH_IN, 2.4 * rows + 1.0), squeeze=False)
    lo, hi = check.band
    mlo, mhi = check.model_band
    med = check.median
    for i, ax in enumerate(axes.flat):
        if i >= n:
            ax.axis("off")
            continue
        sel = check.trace == i
        t = check.time_s[sel]
        m = med[sel]
        band = {"color": "C3", "lw": 0}
        ax.fill_between(t, lo[sel] - m, hi[sel] - m, alpha=0.25, label="95% predictive", **band)
        ax.fill_between(t, mlo[sel] - m, mhi[sel] - m, alpha=0.7, label="95% model", **band)
        ax.plot(t, check.measured[sel] - m, ".", ms=1.5, color="k", label="measured")
        ax.set_title(trace_ids[i], fontsize=9)
        ax.tick_params(labelsize=9)
        ax.locator_params(nbins=3)
    axes.flat[0].legend(fontsize=9, loc="lower right")
    ax = axes.flat[n]
    ax.axis("on")
    r_lo, r_hi = check.lag1_replicated
    ax.axvspan(r_lo, r_hi, color="C3", alpha=0.3, label="replicated 95%")
    ax.axvline(check.lag1_measured, color="k", label="measured")
    ax.set(xlim=(min(r_lo, check.lag1_measured) - 0.1, max(r_hi, check.lag1_measured) + 0.1))
    ax.set_title(f"lag-1 autocorrelation (p = {check.lag1_p_value:.2f})", fontsize=9)
    ax.legend(fontsize=9)
    ax.tick_params(labelsize=9)
    ax.set_yticks([])
    fig.suptitle(
        "Posterior predictive check: measured block means minus the posterior median trace,\n"
        "with the 95% band of replicated traces (light) and of the noise-free model (dark); "
        f"{100 * check.inside_fraction:.1f}% inside the predictive band",
        fontsize=9,
    )
    fig.supxlabel("time [s]; last panel: lag-1 autocorrelation [-]")
    fig.supylabel("force - posterior median [N] (block means)")
    fig.tight_layout(rect=(0, 0, 1, 0.98))
    path = Path(path)
    with atomic_file(path) as tmp:
        save_figure(fig, tmp, tight=False, format="png")
    return path
