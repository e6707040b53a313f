"""What ``fit-law`` found: :class:`SeriesFit`, its text report and ``fit_law.json``."""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path
from typing import Any

import numpy as np

from idtool._fit._result import Estimate, interval_statement, one_sided, weakly_identified
from idtool._lawfit._lag import LAG, LagCheck
from idtool._lawfit._problem import Problem
from idtool._lawfit._profile import Side
from idtool._lawfit._solve import Optimum

__all__ = ["SCHEMA_VERSION", "SeriesFit", "estimate_from_sides"]

SCHEMA_VERSION = "1"


def estimate_from_sides(param, z: float, se_z: float, lo: Side, hi: Side) -> Estimate:
    """The :class:`~idtool._fit._result.Estimate` of a parameter from its optimum, the
    Wald standard error on the internal scale and its interval's two sides; an open side
    runs to the range's end and makes the interval one-sided (or not identified)."""
    value = float(param.value(z))
    side = one_sided(lo.z, hi.z)
    ends = [float(param.value(float(np.clip(s.z, -50.0, 50.0)))) for s in (lo, hi)]
    # no standard error where the interval says the data do not fix the parameter
    weak = weakly_identified(ends[0], ends[1], side)
    usable = side == "" and not weak and math.isfinite(se_z)
    se = abs(param.slope(z)) * se_z if usable else math.nan
    return Estimate(param.name, param.unit, value, se, (ends[0], ends[1]), one_sided=side)


@dataclasses.dataclass(frozen=True)
class SeriesFit:
    """A friction law fitted to a velocity-force series (:func:`idtool.fit_law`).

    Attributes:
        problem: the series, the law and the parameters.
        optimum: the internal optimum, covariance and noise state.
        estimates: each physical parameter's :class:`~idtool.Estimate` by name.
        sides: each physical parameter's interval ends and how they were found.
        force_model_n: the fitted friction force at every sample [N].
        seconds: wall time of the fit [s].
        lag_check: the likelihood-ratio test of a load-cell lag
            (:mod:`idtool._lawfit._lag`); where it rejects the lag-free model, the fit
            carries the lag.
        posterior: the emcee summary when one was run (``posterior=True``), else None.
    """

    problem: Problem
    optimum: Optimum
    estimates: dict[str, Estimate]
    sides: dict[str, tuple[Side, Side]]
    force_model_n: np.ndarray
    seconds: float
    lag_check: LagCheck | None = None
    posterior: dict[str, Any] | None = None

    @property
    def law(self) -> str:
        return self.problem.law.name

    @property
    def residuals_n(self) -> np.ndarray:
        """Measured minus fitted force [N]."""
        return self.problem.series.force_n - self.force_model_n

    @property
    def noise_sd_n(self) -> float:
        """Residual sd [N] (of the innovations when AR(1)-whitened)."""
        return math.sqrt(self.optimum.sigma2) * self.problem.force_scale_n

    @property
    def sensor_lag_s(self) -> float | None:
        """The fitted load-cell lag [s], or None where the fit carries none."""
        names = [p.name for p in self.problem.params]
        if LAG.name not in names:
            return None
        k = names.index(LAG.name)
        return float(self.problem.params[k].value(self.optimum.z[k]))

    def _lag_line(self) -> str:
        c = self.lag_check
        if c is None:
            return "not tested"
        test = f"likelihood ratio {c.statistic:.3g}, p = {c.p_value:.2g}"
        lag = self.sensor_lag_s
        if lag is not None:
            return f"{lag * 1e3:.4g} ms, fitted ({test})"
        return f"not needed ({test}; the lag model's {c.lag_s * 1e3:.3g} ms)"

    @property
    def statements(self) -> dict[str, str]:
        """Each parameter's interval as a reader should take it (one-sided, weakly or
        not identified: :func:`idtool._fit._result.interval_statement`)."""
        return {k: interval_statement(*e.ci95, e.one_sided) for k, e in self.estimates.items()}

    @property
    def warnings(self) -> list[str]:
        out = []
        for name, e in self.estimates.items():
            if e.one_sided or e.weakly_identified:
                out.append(f"{name}: {self.statements[name]}: the series does not fix it")
        lo_hi = self.sides
        for name, (lo, hi) in lo_hi.items():
            if "profile" in (lo.method, hi.method):
                out.append(
                    f"{name}: the Wald interval disagreed with the profile likelihood "
                    "(rise of -2 log L below 1 at an end); the profile's end is reported"
                )
        lag = self.sensor_lag_s
        if lag is not None:
            out.append(
                f"the load cell lags the force (first order, {lag * 1e3:.3g} ms; "
                f"{self._lag_line().split('(', 1)[1][:-1]}): the lag is fitted with the "
                "law; without it the delay reads as bristle compliance"
            )
        if self.optimum.phi:
            out.append(
                f"the residuals are autocorrelated (lag-1 {self.optimum.phi_white:+.2f} in "
                f"the white fit): AR(1)-whitened, phi = {self.optimum.phi:+.3f}; the "
                "intervals account for it"
            )
        return out

    def to_json(self, provenance: dict | None = None) -> dict[str, Any]:
        """``fit_law.json``'s content."""
        s, opt = self.problem.series, self.optimum
        params = {}
        for name, e in self.estimates.items():
            lo, hi = self.sides[name]
            params[name] = {
                "unit": e.unit,
                "estimate": e.estimate,
                "std_error": None if math.isnan(e.std_error) else e.std_error,
                "ci95": list(e.ci95),
                "one_sided": e.one_sided,
                "statement": self.statements[name],
                "interval_method": [lo.method, hi.method],
                "wald_end_rise": [lo.wald_rise, hi.wald_rise],
            }
        nuisance = {
            p.name: float(p.value(opt.z[k]))
            for k, p in enumerate(self.problem.params)
            if k >= self.problem.n_physical
        }
        p = self.problem.n_physical
        corr = _correlation(opt.cov_z[:p, :p])
        return {
            "schema_version": SCHEMA_VERSION,
            "law": self.law,
            "series": {
                "source": s.source,
                "sha256": s.sha256,
                "n_samples": s.n_samples,
                "duration_s": float(s.time_s[-1] - s.time_s[0]),
                "slip_input": s.slip_input,
                "normal_load": s.normal_load_n is not None,
            },
            "parameters": params,
            "nuisance": nuisance,
            "correlation": {"names": list(self.estimates), "matrix": corr.tolist()},
            "residuals": {
                "sd_n": float(np.std(self.residuals_n)),
                "innovation_sd_n": self.noise_sd_n,
                "lag1_autocorrelation_white_fit": opt.phi_white,
                "ar1_phi": opt.phi,
                "noise_model": "AR(1)" if opt.phi else "white",
            },
            "sensor_lag": {
                "lag_s": self.sensor_lag_s,
                "check": None if self.lag_check is None else self.lag_check.to_json(),
            },
            "lm_steps": opt.steps,
            "seconds": self.seconds,
            "warnings": self.warnings,
            "posterior": self.posterior,
            "provenance": provenance,
        }

    def report(self) -> str:
        """A readable report (lmfit style): fit statistics, then each parameter's value,
        standard error and 95% interval as a reader should take it."""
        s, opt = self.problem.series, self.optimum
        lines = [
            f"[[Fit of {self.law} to {s.source}]]",
            f"    samples            = {s.n_samples} ({s.slip_input} input, "
            f"{'normal load given' if s.normal_load_n is not None else 'no normal load'})",
            f"    residual sd        = {np.std(self.residuals_n):.4g} N",
            f"    lag-1 autocorr.    = {opt.phi_white:+.3f} (white fit); noise model "
            + (f"AR(1), phi = {opt.phi:+.3f}" if opt.phi else "white"),
            f"    sensor lag         = {self._lag_line()}",
            f"    LM steps           = {opt.steps}",
            f"    time               = {self.seconds:.2f} s",
            "[[Parameters]] (95% intervals; se where the data bound both sides)",
        ]
        width = max(len(n) for n in self.estimates)
        for name, e in self.estimates.items():
            se = "" if math.isnan(e.std_error) else f" +/- {e.std_error:.3g}"
            lines.append(
                f"    {name:<{width}} = {e.estimate:.5g}{se} {e.unit}  {self.statements[name]}"
            )
        p = self.problem.n_physical
        corr = _correlation(opt.cov_z[:p, :p])
        names = list(self.estimates)
        pairs = [
            (abs(corr[i, j]), names[i], names[j], corr[i, j])
            for i in range(p)
            for j in range(i + 1, p)
            if np.isfinite(corr[i, j]) and abs(corr[i, j]) > 0.5
        ]
        if pairs:
            lines.append("[[Correlations]] (internal scale, |C| > 0.5)")
            for _, a, b, c in sorted(pairs, reverse=True):
                lines.append(f"    C({a}, {b}) = {c:+.3f}")
        if self.posterior:
            lines.append("[[Posterior]] (emcee: median and 95% interval)")
            for name, row in self.posterior["parameters"].items():
                lines.append(
                    f"    {name:<{width}} = {row['median']:.5g} [{row['q2.5']:.5g}, "
                    f"{row['q97.5']:.5g}]"
                )
        if self.warnings:
            lines.append("[[Warnings]]")
            lines += [f"    {w}" for w in self.warnings]
        return "\n".join(lines)

    def save(self, out: str | Path, *, force: bool = False, argv=None) -> Path:
        """Write ``fit_law.json``, ``report.txt`` and ``fit_law.png`` into the folder
        ``out`` (written to a temporary folder, then renamed; an existing ``out`` is
        replaced only with ``force``)."""
        import json

        from idtool._atomic import atomic_output_dir
        from idtool._lawfit._plot import plot_fit
        from idtool._provenance import provenance

        with atomic_output_dir(out, force=force) as tmp:
            data = self.to_json(provenance(argv))
            (tmp / "fit_law.json").write_text(json.dumps(data, indent=2, allow_nan=False))
            (tmp / "report.txt").write_text(self.report() + "\n")
            plot_fit(self, tmp / "fit_law.png")
        return Path(out)


def _correlation(cov: np.ndarray) -> np.ndarray:
    d = np.sqrt(np.diag(cov))
    with np.errstate(invalid="ignore", divide="ignore"):
        c = cov / np.outer(d, d)
    return np.where(np.isfinite(c), c, 0.0)
