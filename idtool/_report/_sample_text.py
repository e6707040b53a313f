"""What a posterior run leaves in the fit folder: ``posterior.nc``, ``sample.json``,
``report_sample.txt`` (the plain-text report below) and ``ppc.png``."""

from __future__ import annotations

import json
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from idtool._atomic import write_text_atomic
from idtool._diagnostic import records
from idtool._fit._folder import CHAIN_H5, POSTERIOR_NC, PPC_PNG, REPORT_SAMPLE_TXT, SAMPLE_JSON
from idtool._fit._result import Estimate, interval_statement
from idtool._model._noise import DEFAULT_NOISE
from idtool._plotting import MAX_WIDTH_IN, save_figure, subplots
from idtool._posterior._groups import model_check_groups
from idtool._posterior._levels import (
    LevelsCheck,
    LevelsTarget,
    build_levels_target,
    levels_predictive,
)
from idtool._posterior._likelihood import Target, build_target, conditioning_shrinkage
from idtool._posterior._posterior import LEVELS, FitLike, Posterior
from idtool._posterior._ppc import PredictiveCheck, plot_predictive, posterior_predictive
from idtool._posterior._store import write_posterior
from idtool._provenance import provenance
from idtool._version import __version__

__all__ = ["POSTERIOR_FILES", "sample_report", "write_posterior_outputs"]

POSTERIOR_FILES = tuple(
    f.name for f in (CHAIN_H5, POSTERIOR_NC, SAMPLE_JSON, REPORT_SAMPLE_TXT, PPC_PNG)
)


def _fmt(x: float) -> str:
    return f"{x:.5g}"


def sample_report(
    post: Posterior,
    estimates: Mapping[str, Estimate],
    check: PredictiveCheck | LevelsCheck,
    source: str,
    shrink: np.ndarray,
) -> str:
    """A plain-text report of a posterior run: estimates against the fit's (``source``
    names the fit), diagnostics, the predictive check, priors, nuisances, warnings."""
    model = post.model
    assert model is not None
    t = post.timing
    est = estimates
    lines = [
        "[[Posterior]]",
        f"    fit          {source} ({model.law.name} friction, {model.coupling.name} coupling)",
        (
            "    model        levels model: the traces' own levels, scatter and "
            "discrepancy sampled (nuisances and noise integrated in the fit)"
            if post.noise == LEVELS
            else f"    noise        {post.noise}"
            + (" (default)" if post.noise == DEFAULT_NOISE else "")
            + "; the per-trace nuisances are integrated out, not fixed"
        ),
        f"    sampler      emcee, {post.chain.shape[1]} walkers x {post.chain.shape[0]} steps, "
        f"seed {post.seed}; compile {t['compile_s']:.1f} s, sampling {t['sampling_s']:.1f} s "
        f"for {t['steps_this_run']:.0f} steps",
        "[[Parameters]]  (posterior median and 95% interval; the fit's for comparison)",
    ]
    for name, s in post.summary().items():
        fit_ci = ""
        if name in est:
            lo, hi = est[name].ci95
            fit_ci = f"   fit {_fmt(est[name].estimate)} [{_fmt(lo)}, {_fmt(hi)}]"
        # said as the fit's: "> lo" where the data bound it on one side only, "weakly
        # identified" over two decades
        lo, hi = s["ci95"]
        interval = interval_statement(lo, hi, s["one_sided"], weak=s["weakly_identified"])
        lines.append(f"    {name:20s}{_fmt(s['median']):>12s} {s['unit']:4s} {interval}{fit_ci}")
    lines += ["[[Diagnostics]]", post.diagnostics.report()]
    if isinstance(check, LevelsCheck):
        lines += [
            "[[Posterior predictive check]]  (levels model)",
            f"    {100 * check.inside_fraction:.1f}% of the traces' own levels (log OFF, log FR) "
            "lie inside their 95% predictive band",
            f"    chi-square discrepancy: posterior predictive p = {check.p_value:.2f} "
            "(near 0: the model misses the levels even with its scatter and discrepancy)",
        ]
    else:
        lines += [
            "[[Posterior predictive check]]",
            f"    {100 * check.inside_fraction:.1f}% of the measured block means lie inside the "
            "95% predictive band",
            f"    lag-1 autocorrelation of the residuals: measured {check.lag1_measured:.3f}, "
            f"replicated 95% [{check.lag1_replicated[0]:.3f}, {check.lag1_replicated[1]:.3f}], "
            f"p = {check.lag1_p_value:.2f}",
        ]
    lines.append("[[Priors]]")
    lines += [f"    {n:20s}{p.describe()}" for n, p in post.priors.items()]
    if not isinstance(check, LevelsCheck):  # the levels model has no nuisances left
        lines += [
            "[[Nuisances]]",
            f"    holding the per-trace nuisances at the fit's values would shrink the shared "
            f"parameters' sds to {100 * min(shrink):.0f}-{100 * max(shrink):.0f}% of their "
            "marginal values (fit covariance), so they are integrated out",
        ]
    lines.append("[[Warnings]]")
    lines += [f"    - {w}" for w in post.warnings] or ["    none"]
    return "\n".join(lines)


def write_posterior_outputs(
    fit: FitLike,
    estimates: Mapping[str, Estimate],
    post: Posterior,
    folder: str | Path,
    command: Sequence[str] | None = None,
) -> str:
    """Write ``posterior.nc``, ``sample.json``, ``report_sample.txt`` and ``ppc.png`` of
    ``post`` into ``folder`` (each file atomically); returns the text report."""
    folder = Path(folder)
    model = fit.model
    shrink = conditioning_shrinkage(fit.cov_z, model.n_shared)
    check: PredictiveCheck | LevelsCheck
    target: Target | LevelsTarget
    if post.noise == LEVELS:
        target = build_levels_target(model, fit.levels[0], post.priors)
        check = levels_predictive(post.chain, post.diagnostics.burn, target, seed=post.seed)
        nuisances: dict[str, Any] = {
            "treatment": "levels model: the traces' own levels with their covariance "
            "(nuisances, slopes and noise integrated in the fit's stage 1)"
        }
    else:
        target = build_target(model, post.z_lin, post.noise, post.priors)
        check = posterior_predictive(post, fit, seed=post.seed, target=target)
        nuisances = {
            "treatment": "integrated out (linearised at the fit, Gaussian)",
            "sd_ratio_if_fixed": dict(
                zip(model.names[: model.n_shared], map(float, shrink), strict=True)
            ),
        }
    report = sample_report(post, estimates, check, str(folder), shrink)
    prov = provenance(command)
    doc = {
        "schema_version": SAMPLE_JSON.schema_version,  # datasets_schema/sample.schema.json
        "posterior": post.summary(),
        "noise": post.noise,
        "priors": {n: p.to_dict() for n, p in post.priors.items()},
        "diagnostics": post.diagnostics.to_dict(),
        "posterior_predictive": check.to_dict(),
        "nuisances": nuisances,
        "warnings": list(post.warnings),
        # every doubt as a record (code, severity, message, values): idtool._diagnostic
        "diagnostic_records": records([*post.warnings, *post.diagnostics.records()]),
        "timing_s": post.timing,
        "seed": post.seed,
        "idtool_version": __version__,
        "command": prov["command"],
        "versions": prov["versions"],
        "created_utc": prov["created_utc"],
    }
    groups, steps = model_check_groups(post, target)
    extra = {"fit_folder": str(folder)}
    write_posterior(post, folder / POSTERIOR_NC.name, extra, groups, steps)
    write_text_atomic(folder / SAMPLE_JSON.name, json.dumps(doc, indent=1) + "\n")
    write_text_atomic(folder / REPORT_SAMPLE_TXT.name, report + "\n")
    if isinstance(check, LevelsCheck):
        plot_levels_check(check, fit.levels[0], model, folder / PPC_PNG.name)
    else:
        plot_predictive(check, model.data.trace_ids, folder / PPC_PNG.name)
    return report


def plot_levels_check(check: LevelsCheck, free, model, path: Path) -> Path:
    """``ppc.png`` of a levels-model posterior: each trace's own friction ratio and OFF
    level (relative to the median) with their error bars, over the 95% predictive band."""
    m = model.data.n_traces
    y, (lo, hi) = check.y, check.band
    fig, (a1, a2) = subplots(1, 2, figsize=(MAX_WIDTH_IN, 5.0))
    x_off = np.arange(m)
    sd_off = np.sqrt(free.variances()[:m])
    ref = np.median(y[:m])
    a1.fill_between(
        x_off, 100 * (lo[:m] - ref), 100 * (hi[:m] - ref), alpha=0.3, label="95% predictive"
    )
    a1.errorbar(x_off, 100 * (y[:m] - ref), 196 * sd_off, fmt="o", ms=3, label="trace (own level)")
    a1.set_xticks(x_off, model.data.trace_ids, rotation=90, fontsize=9)
    a1.set(ylabel="log OFF level - median [%]", title="OFF levels")
    idx = np.flatnonzero(free.measured)
    fr = np.exp(y[m:])
    a2.fill_between(
        np.arange(idx.size), np.exp(lo[m:]), np.exp(hi[m:]), alpha=0.3, label="95% predictive"
    )
    a2.errorbar(
        np.arange(idx.size),
        fr,
        1.96 * fr * np.sqrt(free.variances()[m:]),
        fmt="o",
        ms=3,
        label="trace (own FR)",
    )
    a2.set_xticks(
        np.arange(idx.size), [model.data.trace_ids[i] for i in idx], rotation=90, fontsize=9
    )
    a2.set(
        ylabel="friction ratio [-]",
        title=f"FR per trace ({100 * check.inside_fraction:.0f}% inside)",
    )
    for a in (a1, a2):
        a.legend(fontsize=9)
    return save_figure(fig, path)
