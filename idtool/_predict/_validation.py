"""Held-out validation of a fit (issue 13, item 2): how well does it predict traces it
did not see?

For each held-out trace (same bench, same model; a trace of the fitted dataset left out
by ``idtool fit --traces``, or a later session's):

1. **Its force trace, predicted.** The shared parameters (contact, coupling, actuator)
   stay at the fit's estimates; only the trace's own nuisances (load-cell offset, pull
   start, horn lags: what no model can know before the pull) are fitted to it, as
   MATLAB's ``compare`` estimates initial conditions. Reported per trace: the fit
   percentage ``100 (1 - |y - y_hat| / |y - mean(y)|)`` (MATLAB's NRMSE fit: 100 is
   perfect, 0 no better than the trace's mean) and the RMSE [N] of the block means.
2. **Its friction ratio against the predicted band.** The trace's own FR, estimated
   from that trace alone (:func:`~idtool._fit._free_levels.free_levels`, SE from its
   own noise), against the fit's 95% band for a *new pull* at its operating point
   (:func:`~idtool._predict._predict.predict_friction_ratio`: the curve, the
   discrepancy and the pull-to-pull scatter), widened by the trace's own measurement
   error: what is compared is a *measured* FR, the new pull's plus its estimation error.
   In log FR, where both are near normal, the half-widths add in quadrature:
   ``sqrt(h^2 + (1.96 se / FR)^2)`` about the band's centre. Coverage: the share of
   held-out traces inside; about 95% if the bands are honest.
"""

from __future__ import annotations

import dataclasses
import math

import jax.numpy as jnp
import numpy as np

from idtool._data._blocks import prepare_fit_data
from idtool._data._dataset import Dataset
from idtool._errors import IdtoolError
from idtool._fit._free_levels import free_levels
from idtool._fit._program import prediction_at, run_lm
from idtool._model._benchmodel import BenchModel, bench_model
from idtool._predict._predict import Draws, predict_friction_ratio

__all__ = ["TraceValidation", "Validation", "validate"]

_STEPS = 200  # nuisance-only LM: a few unknowns per trace, converges in tens of steps


@dataclasses.dataclass(frozen=True)
class TraceValidation:
    """One held-out trace: how well its force is predicted, and its own FR against
    the predicted band for a new pull (NaN/None where its ON level is not measured)."""

    id: str
    normal_load_n: float
    amplitude_fraction: float
    pull_speed_m_s: float
    fit_percent: float
    rmse_n: float
    friction_ratio: float | None
    friction_ratio_se: float | None
    band: tuple[float, float]  # 95% of a new pull's FR

    @property
    def measured_band(self) -> tuple[float, float] | None:
        """95% of a new pull's FR as this trace measures it: the band widened by the
        trace's own estimation error (module docstring), or None without a measured FR."""
        if self.friction_ratio is None or self.friction_ratio_se is None:
            return None
        lo, hi = np.log(self.band)
        half = math.hypot(0.5 * (hi - lo), 1.96 * self.friction_ratio_se / self.friction_ratio)
        centre = 0.5 * (lo + hi)
        return math.exp(centre - half), math.exp(centre + half)

    @property
    def inside(self) -> bool | None:
        band = self.measured_band
        if band is None or self.friction_ratio is None:
            return None
        return band[0] <= self.friction_ratio <= band[1]

    def to_dict(self) -> dict:
        return {
            "id": self.id,
            "normal_load_n": self.normal_load_n,
            "amplitude_fraction": self.amplitude_fraction,
            "pull_speed_m_s": self.pull_speed_m_s,
            "fit_percent": self.fit_percent,
            "rmse_n": self.rmse_n,
            "friction_ratio": self.friction_ratio,
            "friction_ratio_se": self.friction_ratio_se,
            "new_trace_ci95": list(self.band),
            "measured_ci95": None if self.measured_band is None else list(self.measured_band),
            "inside": self.inside,
        }


@dataclasses.dataclass(frozen=True)
class Validation:
    """The held-out traces' results, their coverage and where the bands came from."""

    traces: tuple[TraceValidation, ...]
    dataset: str
    dataset_sha256: str
    draws: str
    warnings: tuple[str, ...] = ()

    @property
    def coverage(self) -> float | None:
        """Share of held-out traces (with a measured FR) inside their 95% band."""
        inside = [t.inside for t in self.traces if t.inside is not None]
        return float(np.mean(inside)) if inside else None

    def table(self) -> str:
        """One line per held-out trace, for a terminal."""
        lines = [
            f"{'trace':<18} {'load_N':>7} {'ampl':>5} {'fit_%':>6} {'rmse_N':>7}  "
            "own FR (se)        new pull 95%      as measured 95%   inside"
        ]
        for t in self.traces:
            own = "-"
            if t.friction_ratio is not None:
                own = f"{t.friction_ratio:.3f} ({t.friction_ratio_se:.3f})"
            meas = t.measured_band
            meas_text = "-" if meas is None else f"[{meas[0]:.3f}, {meas[1]:.3f}]"
            inside = {None: "-", True: "yes", False: "NO"}[t.inside]
            lines.append(
                f"{t.id:<18} {t.normal_load_n:>7g} {t.amplitude_fraction:>5.0%} "
                f"{t.fit_percent:>6.1f} {t.rmse_n:>7.3f}  {own:<18} "
                f"[{t.band[0]:.3f}, {t.band[1]:.3f}]  {meas_text:<16}  {inside}"
            )
        return "\n".join(lines)

    def summary(self) -> str:
        fits = [t.fit_percent for t in self.traces]
        n_fr = sum(t.inside is not None for t in self.traces)
        cov = self.coverage
        text = (
            f"{len(self.traces)} held-out trace(s) of {self.dataset}: force fit "
            f"{min(fits):.1f}-{max(fits):.1f}% (median {np.median(fits):.1f}%)"
        )
        if cov is None:
            return text + "; no trace's own friction ratio measured"
        inside = round(cov * n_fr)
        return text + (
            f"; own friction ratio inside the 95% new-pull band for {inside} of {n_fr} "
            f"({100 * cov:.0f}%, about 95% expected)"
        )

    def to_dict(self) -> dict:
        return {
            "dataset": self.dataset,
            "dataset_sha256": self.dataset_sha256,
            "draws": self.draws,
            "coverage_95": self.coverage,
            "summary": self.summary(),
            "traces": [t.to_dict() for t in self.traces],
            "warnings": list(self.warnings),
        }


def _model_for(model: BenchModel, dataset: Dataset) -> BenchModel:
    """The fitted model's laws and noise on ``dataset``'s traces, blocked the same way."""
    d = model.data
    data = prepare_fit_data(
        dataset,
        mains_hz=float(d.mains_hz),
        periods_per_block=int(d.periods_per_block),
        mains_source=str(d.mains_source),
    )
    return bench_model(
        data,
        model.law,
        model.coupling,
        type(model.noise),
        model.actuator,
        model.offset,
        level=model.level,
        direction=model.direction,
    )


def validate(
    model: BenchModel, z: np.ndarray, state: np.ndarray, draws: Draws, dataset: Dataset
) -> Validation:
    """Validate the fit (``model`` at internal ``z``, noise correlation ``state``;
    prediction ``draws``) on ``dataset``'s traces (module docstring)."""
    held = _model_for(model, dataset)
    shared = {q.name: float(z[i]) for i, q in enumerate(model.shared_params)}
    z0 = np.asarray(held.z0(), float)
    for i, q in enumerate(held.shared_params):
        z0[i] = shared[q.name]
    mask = np.zeros(z0.size, bool)
    mask[held.n_shared :] = True  # the traces' own nuisances only
    out = run_lm(held, jnp.asarray(z0), jnp.asarray(mask), state, _STEPS)
    if not bool(out.converged):
        raise IdtoolError(
            f"{dataset.name}: the held-out traces' nuisances did not converge in "
            f"{_STEPS} steps; are they from the same bench and model?"
        )
    zv = np.asarray(out.z)
    # from the program that just ran (no step): op by op, the model's prediction was
    # ~100 operations compiled one by one
    pred = prediction_at(held, zv, state)[0]
    d = held.data
    try:
        free = free_levels(held, zv, state)
    except np.linalg.LinAlgError as err:
        raise IdtoolError(
            f"{dataset.name}: the held-out traces' own levels cannot be read ({err}); "
            "are they from the same bench and model?"
        ) from None
    points = [
        (float(d.normal_load_n[i]), float(d.amplitude_fraction[i]), float(d.pull_speed_m_s[i]))
        for i in range(d.n_traces)
    ]
    rows = []
    for i, (load, amp, speed) in enumerate(points):
        sel = np.asarray(d.block_trace) == i
        y, y_hat = np.asarray(d.force_n)[sel], pred[sel]
        spread = float(np.linalg.norm(y - y.mean()))
        fit_pct = 100.0 * (1.0 - float(np.linalg.norm(y - y_hat)) / spread) if spread else math.nan
        band: tuple[float, float] = (math.nan, math.nan)
        own = se = None
        if amp > 0:
            p = predict_friction_ratio(draws, [load], [amp], [speed])[0]
            band = p.new_trace[1] if p.new_trace else p.ci95
            if bool(free.measured[i]):
                own = float(free.friction_ratio[i])
                se = float(free.friction_ratio_se[i])
        rows.append(
            TraceValidation(
                id=d.trace_ids[i],
                normal_load_n=load,
                amplitude_fraction=amp,
                pull_speed_m_s=speed,
                fit_percent=fit_pct,
                rmse_n=float(np.sqrt(np.mean((y - y_hat) ** 2))),
                friction_ratio=own,
                friction_ratio_se=se,
                band=(float(band[0]), float(band[1])),
            )
        )
    return Validation(tuple(rows), dataset.name, dataset.sha256, draws.note)
