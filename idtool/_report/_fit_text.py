"""What a fit hands on: ``fit.json``, a report a person can read, residual plots."""

from __future__ import annotations

import itertools
from pathlib import Path
from typing import Any

import numpy as np

from idtool._diagnostic import records
from idtool._fit._derived import derived_estimates
from idtool._fit._folder import FIT_SCHEMA_VERSION, RESIDUALS_PNG, TRACES_PNG, law_state_file
from idtool._fit._plateau_drift import MIN_RELATIVE_CHANGE, P_ALARM
from idtool._fit._program import prediction_at
from idtool._fit._result import Estimate, FitResult
from idtool._fit._run import ChoiceWeight, FitRun
from idtool._plotting import MAX_WIDTH_IN, save_figure, subplots
from idtool._provenance import provenance
from idtool._version import __version__

__all__ = ["MAX_TRACE_PANELS", "fit_json", "fit_report", "plot_fit", "shown_traces"]

# Most panels traces.png draws (one per trace): a bench of 96 traces shows its worst 24
MAX_TRACE_PANELS = 24

# The model is an argument (its data are leaves): one program per dataset shape.


def _est(e: Estimate) -> dict:
    out = {
        "estimate": e.estimate,
        "std_error": e.std_error,
        "ci95": [e.ci95[0], e.ci95[1]],
        "unit": e.unit,
        "at_bound": bool(e.at_bound),
    }
    if e.one_sided:  # the data bound it on this side only ("lower": report "> lo")
        out["one_sided"] = e.one_sided
    if e.weakly_identified:  # bounded on both sides, but over two decades
        out["weakly_identified"] = True
    return out | {"fixed": True, "fixed_by": e.fixed_label} if e.fixed else out


def _fixed_physical(r: FitResult) -> list[str]:
    """The physical parameters the user fixed (reported with the estimated ones)."""
    physical = {p.name for p in r.model.declared_params if p.physical}
    return [n for n in r.model.fixed if n in physical]


def _shared_names(r: FitResult) -> list[str]:
    return [s.name for s in r.model.shared_params]


def fit_json(run: FitRun, dataset_path: str | None, argv: list[str] | None) -> dict:
    """The ``fit.json`` document (schema in the README)."""
    r = run.chosen
    d = run.data
    phys = list(r.model.physical_names)
    shared = _shared_names(r)
    params = {name: _est(r.estimates[name]) for name in [*phys, *_fixed_physical(r)]}
    for name, prof in run.profiles.items():
        params[name]["profile_ci95"] = [prof.ci95[0], prof.ci95[1]]
    idx = [r.model.names.index(n) for n in shared]
    traces = []
    for i, tid in enumerate(d.trace_ids):
        traces.append(
            {
                "id": tid,
                "normal_load_n": float(d.normal_load_n[i]),
                "amplitude_fraction": float(d.amplitude_fraction[i]),
                "pull_speed_m_s": float(d.pull_speed_m_s[i]),
                "friction_ratio": {
                    "estimate": float(r.friction_ratio[i]),
                    "std_error": float(r.friction_ratio_se[i]),
                },
                **{key: _est(r.estimates[f"{key}[{tid}]"]) for key, _, _ in r.model.trace_groups},
            }
        )
        if _relaxing(r):
            traces[-1]["friction_ratio_steady"] = steady_friction_ratio(r, i)
    var = r.variability
    if var is not None:
        free_fr, free_se = var.free.friction_ratio, var.free.friction_ratio_se
        for i, tr in enumerate(traces):
            measured = bool(var.free.measured[i])
            tr["free_friction_ratio"] = {
                "estimate": float(free_fr[i]) if measured else None,
                "std_error": float(free_se[i]) if measured else None,
                "measured": measured,
            }
    prov = provenance(argv)
    law, coupling = r.model.law.name, r.model.coupling.name
    return {
        "schema_version": FIT_SCHEMA_VERSION,  # datasets_schema/fit.schema.json
        "parameters": params,
        # quantities that follow from the parameters (the sdof law's drive force)
        "derived": {
            name: _est(e) | {"description": what}
            for name, (e, what) in derived_estimates(r).items()
        },
        "bench": {
            name: _est(r.estimates[name])
            for name in [*shared, *r.model.fixed]
            if name not in phys and name not in params
        },
        # the user's fixed values, bounds, scales, starts and priors (--fix, --parameters)
        "parameter_settings": [s.to_dict() for s in r.model.settings],
        "traces": traces,
        "law": law,
        "coupling": coupling,
        "actuator": {
            "name": r.model.actuator.name,
            "parameters": [p.name for p in r.model.actuator.fit_params],
        },
        "offset": {
            "name": r.model.offset.name,
            "trace_parameters": [name for name, _, _ in r.model.offset.trace_params],
        },
        "level": {
            "name": r.model.level.name,
            "parameters": [p.name for p in r.model.level.fit_params],
            "trace_parameters": [name for name, _, _ in r.model.level.trace_params],
        },
        # the direction of vibration the contact kernel assumes (no parameters)
        "direction": {
            "name": r.model.direction.name,
            "description": r.model.direction.description,
        },
        "aic": r.aic,
        "bic": r.bic,
        "loglik": r.loglik,
        "n_data": r.n_data,
        "n_params": r.n_params,
        "noise": {
            "name": r.model.noise.name,
            "model": f"{r.model.noise.description} on block means over whole mains periods",
            "block_s": d.block_s,
            "mains_hz": d.mains_hz,
            "mains_source": d.mains_source,
            "periods_per_block": d.periods_per_block,
            "periods_requested": d.periods_requested,
            "residual_hum_fraction": d.residual_hum_fraction,
            "phi": r.phi,
            "sigma_n": r.sigma_n,
            # the noise model's correlation state by name (AbstractNoise.state_params)
            "parameters": r.model.noise.state_by_name(r.noise_state),
        },
        "variability": _variability_json(r),
        # the levels' trends within their plateaus (_fit/_plateau_drift.py)
        "plateau_drift": _plateau_drift_json(r),
        "correlation": {"names": shared, "matrix": r.correlation[np.ix_(idx, idx)].tolist()},
        "model_comparison": [
            {"model": key, "aic": c.aic, "bic": c.bic, "loglik": c.loglik, "n_params": c.n_params}
            for key, c in run.ranking
        ],
        "choice": run.reason,
        # each coupling law's best candidate and its Akaike/Schwarz weight
        # (with the state file of each other law that predictions average over)
        "coupling_laws": [
            w.to_dict() | ({"state_file": law_state_file(w.law)} if w.law in run.alternates else {})
            for w in run.coupling_weights.values()
        ],
        **_direction_tables(run),
        "multistart": [
            {
                "rss": o["rss"],
                "count": o["count"],
                "converged": bool(o["converged"]),
                **{n: float(r.model.params[j].value(float(o["z"][j]))) for j, n in enumerate(phys)},
            }
            for o in r.optima
        ],
        "warnings": r.warnings,
        "notes": r.notes,
        # every doubt and note as a record (code, severity, message, values), which the
        # report and compare read by code: idtool._diagnostic
        "diagnostic_records": [*records(r.warnings), *records(r.notes, severity="note")],
        "lm_steps": r.lm_steps,
        "jacobian_evaluations": r.jacobian_evaluations,
        # the fitted traces: all of the dataset's, or those --traces selected
        "dataset": {
            "name": d.name,
            "sha256": d.sha256,
            "path": dataset_path,
            "traces": list(d.trace_ids),
        },
        "idtool_version": __version__,
        "seed": run.seed,
        "command": prov["command"],
        "versions": prov["versions"],
        "created_utc": prov["created_utc"],
    }


def _direction_tables(run: FitRun) -> dict[str, Any]:
    """``direction="auto"``'s records: each direction's best candidate and weights
    (``directions``), and the models predictions average over (``model_weights``: each
    direction's, or each coupling law and direction pair's, with the state file of each
    kept beside the chosen one); nothing when one direction was fitted."""
    if "direction" not in run.compared:
        return {}
    return {
        "directions": [w.to_dict("direction") for w in run.direction_weights.values()],
        "model_weights": [
            w.to_dict("model")
            | ({"state_file": law_state_file(w.name)} if w.name in run.alternates else {})
            for w in run.model_weights.values()
        ],
    }


def _choice_lines(title: str, what: str, weights: dict[str, ChoiceWeight]) -> list[str]:
    """A model choice's table for the text report (nothing for a single option)."""
    if len(weights) < 2:
        return []
    width = max(len(n) for n in weights)
    best = next(iter(weights.values())).bic
    basis = (
        "; the levels model's criteria: pull-to-pull scatter and discrepancy in its "
        "likelihood, the same free levels for every option"
        if next(iter(weights.values())).criterion == "levels"
        else ""
    )
    lines = [
        f"[[{title}]]  (each {what}'s best model; weights exp(-delta/2), normalised: "
        f"BIC's ~ the {what}'s posterior probability, AIC's its predictive standing{basis})"
    ]
    first = next(iter(weights.values())).criterion
    for w in weights.values():
        flag = "  comparable" if w.bic_weight > 0.05 and w.bic > best else ""
        if w.criterion != first:  # its levels model could not be estimated
            flag += "  (levels model not estimable; ruled out by the traces)"
            delta = "      -"
        else:
            delta = f"{w.bic - best:7.1f}"
        lines.append(
            f"    {w.name:{width}s}  BIC weight {w.bic_weight:6.3f}  AIC weight "
            f"{w.aic_weight:6.3f}  dBIC {delta}  ({w.key}){flag}"
        )
    return lines


def _relaxing(r: FitResult) -> bool:
    """Whether ``r``'s ON levels relax (a rise per trace: the relaxing ON level)."""
    return any(name == "on_rise" for name, _, _ in r.model.level.trace_params)


def steady_friction_ratio(r: FitResult, i: int) -> dict[str, float | list[float]]:
    """Trace ``i``'s friction ratio at steady state under the relaxing ON level,
    ``min(FR0 (1 + r_i), 1)`` (eq. R2 of :mod:`idtool._model._level_model`): estimate and
    95% interval from its rise's (FR0 at its estimate), and the rise itself."""
    fr0 = float(r.friction_ratio[i])
    rise = r.estimates[f"on_rise[{r.model.data.trace_ids[i]}]"]

    def steady(x: float) -> float:
        return min(fr0 * (1.0 + x), 1.0)

    return {
        "estimate": steady(rise.estimate),
        "ci95": [steady(rise.ci95[0]), steady(rise.ci95[1])],
        "on_rise": float(rise.estimate),
    }


def _plateau_drift_json(r: FitResult) -> dict:
    """Per kind of plateau (ON, OFF): how many were tested and significant, the median
    relative change and duration, the pooled statistic and p-value; with a drifting offset,
    the creep test on its rates (``creep``) (``_fit/_plateau_drift.py``)."""
    if r.plateau_drift is None:
        return {"on": False}
    return {
        "on": True,
        "test": "Stouffer's z of the plateaus' residual slopes, AR(1) standard errors; creep: "
        "t test of the fitted offset drift rates' slope against the OFF levels",
        "p_alarm": P_ALARM,
        "min_relative_change": dict(MIN_RELATIVE_CHANGE),
        **{kind: p.to_dict() for kind, p in r.plateau_drift.items()},
    }


def _variability_json(r: FitResult) -> dict:
    """The levels model's sds, lack-of-fit test and notes (``_fit/_variability.py``)."""
    var = r.variability
    if var is None:
        return {"on": False}
    return {
        "on": True,
        "model": "log levels: trace scatter of mu and FR, operating-point discrepancy of FR",
        "sds": {
            name: {"estimate": est, "ci95": [lo, hi], "unit": "1 (relative)"}
            for name, (est, lo, hi) in var.sds.items()
        },
        "separable": var.separable,
        "lack_of_fit": {"chi2": var.chi2, "dof": var.dof, "p_value": var.p_value},
        "loglik": var.loglik,
        "loglik_without": var.loglik_without,
    }


def _variability_lines(r: FitResult) -> list[str]:
    var = r.variability
    if var is None:
        return ["[[Scatter and discrepancy]]  off (--variability off): noise-only intervals"]
    lines = [
        "[[Scatter and discrepancy]]  (sds on the log scale, i.e. relative; REML, "
        "95% from each sd's likelihood times a prior with P(zero) = 1/2)"
    ]
    fr_typ = float(np.nanmedian(var.free.friction_ratio)) if var.free.measured.any() else 1.0
    for name, (est, lo, hi) in var.sds.items():
        extra = f"  ~ {fr_typ * est:.4f} in FR" if name.endswith("_fr") else ""
        lines.append(f"    {name:22s}{100 * est:7.2f}%  [{100 * lo:.2f}%, {100 * hi:.2f}%]{extra}")
    lines.append(
        f"    lack of fit            chi2 = {var.chi2:.1f} on {var.dof} dof, p = {var.p_value:.3g} "
        "(free per-trace levels against the physical model, noise only)"
    )
    return lines


def _fmt(e: Estimate) -> str:
    if e.fixed:
        return f"{e.estimate:12.5g} {e.unit:4s} {e.fixed_label or 'fixed'} (not estimated)"
    rel = f"({100 * e.std_error / abs(e.estimate):.2g}%)" if e.estimate else ""
    flag = "  AT BOUND" if e.at_bound else ""
    return f"{e.estimate:12.5g} {e.unit:4s} +/- {e.std_error:9.3g} {rel:9s} {e.statement}{flag}"


def _direction_words(direction: str) -> str:
    """The direction of vibration for the model line: nothing for the default (along:
    the line stays what it was), else ", vibration NAME"."""
    return "" if direction == "along" else f", vibration {direction}"


def fit_report(run: FitRun) -> str:
    """A plain-text report: estimates, intervals, correlations, statistics, warnings."""
    r, d = run.chosen, run.data
    lines = [
        "[[Fit]]",
        f"    dataset      {d.name} (sha256 {d.sha256[:12]}...), {d.n_traces} traces, "
        f"{d.n_blocks} block means of {d.block_size} samples",
        f"    model        {r.model.law.name} friction, {r.model.coupling.name} coupling, "
        f"{r.model.actuator.name} actuator, {r.model.offset.name} load-cell offset, "
        f"{r.model.level.name} levels{_direction_words(r.model.direction.name)}",
        f"    choice       {run.reason}",
        f"    noise        {r.model.noise.description} ({r.model.noise.name}), "
        + "".join(f"{k} = {v:.3f}, " for k, v in _noise_state_shown(r).items())
        + f"innovation sigma = {r.sigma_n:.3g} N",
        f"    statistics   log L = {r.loglik:.1f}, AIC = {r.aic:.1f}, BIC = {r.bic:.1f}, "
        f"{r.n_params} parameters, {r.lm_steps} Levenberg-Marquardt steps",
        "[[Physical parameters]]  (95% intervals from the Gauss-Newton covariance"
        + (", scatter and discrepancy included)" if r.variability is not None else ")"),
    ]
    for name in [*r.model.physical_names, *_fixed_physical(r)]:
        lines.append(f"    {name:22s}{_fmt(r.estimates[name])}")
        if name in run.profiles:
            lo, hi = run.profiles[name].ci95
            lines.append(f"    {'':22s}profile likelihood 95%: [{lo:.5g}, {hi:.5g}]")
    for name, (e, what) in derived_estimates(r).items():
        lines.append(f"    {name:22s}{_fmt(e)}")
        lines.append(f"    {'':22s}(derived: {what})")
    lines += _variability_lines(r)
    lines.append("[[Bench parameters]]")
    shared = _shared_names(r)
    for name in [*shared, *r.model.fixed]:
        if name not in r.model.physical_names and name not in _fixed_physical(r):
            lines.append(f"    {name:22s}{_fmt(r.estimates[name])}")
    lines.append("[[Correlations]]  (|r| > 0.3)")
    idx = [r.model.names.index(n) for n in shared]
    corr = r.correlation[np.ix_(idx, idx)]
    pairs = [
        (abs(corr[a, b]), shared[a], shared[b], corr[a, b])
        for a in range(len(shared))
        for b in range(a + 1, len(shared))
        if abs(corr[a, b]) > 0.3
    ]
    lines += [f"    C({a}, {b}) = {c:+.3f}" for _, a, b, c in sorted(pairs, reverse=True)]
    lines.append("[[Model comparison]]  (ranked by BIC)")
    best = run.ranking[0][1].bic
    width = max(len(key) for key, _ in run.ranking)  # law/coupling/actuator/offset
    for key, c in run.ranking:
        lines.append(
            f"    {key:{width}s}  AIC {c.aic:10.1f}  BIC {c.bic:10.1f}  dBIC {c.bic - best:7.1f}"
        )
    lines += _choice_lines("Coupling laws", "law", run.coupling_weights)
    lines += _choice_lines("Directions of vibration", "direction", run.direction_weights)
    lines.append("[[Friction ratio at each operating point]]")
    seen = set()
    for i in range(d.n_traces):
        op = (d.normal_load_n[i], d.amplitude_fraction[i], d.pull_speed_m_s[i])
        if op in seen:
            continue
        seen.add(op)
        line = (
            f"    {op[0]:6.0f} N, {100 * op[1]:3.0f}%, {op[2]:.3g} m/s   FR = "
            f"{r.friction_ratio[i]:.4f} +/- {r.friction_ratio_se[i]:.4f}"
        )
        if _relaxing(r):  # at steady state too
            same = [
                j
                for j in range(d.n_traces)
                if (d.normal_load_n[j], d.amplitude_fraction[j], d.pull_speed_m_s[j]) == op
            ]
            steady = [steady_friction_ratio(r, j)["estimate"] for j in same]
            line += f" at the window's start, {np.mean(steady):.4f} at steady state"
        lines.append(line)
    lines.append(
        "[[Multi-start]]  (each start a short joint fit, RSS at phi = 0; the lowest is then "
        "taken to convergence)"
    )
    for o in r.optima:
        lines.append(
            f"    RSS {o['rss']:14.6g}  found {o['count']}x  "
            f"{'converged' if o['converged'] else 'step budget reached'}"
        )
    lines.append("[[Warnings]]")
    lines += [f"    - {w}" for w in r.warnings] or ["    none"]
    if r.notes:
        lines.append("[[Notes]]")
        lines += [f"    - {n}" for n in r.notes]
    return "\n".join(lines)


def shown_traces(resid_n: np.ndarray, block_trace: np.ndarray, n_traces: int) -> np.ndarray:
    """Which traces ``traces.png`` draws, in trace order: all of them up to
    :data:`MAX_TRACE_PANELS`, else the :data:`MAX_TRACE_PANELS` with the largest rms
    residual [N] (the ones a reader must look at; the others are in ``residuals.png``)."""
    if n_traces <= MAX_TRACE_PANELS:
        return np.arange(n_traces)
    ss = np.bincount(block_trace, weights=resid_n**2, minlength=n_traces)
    count = np.maximum(np.bincount(block_trace, minlength=n_traces), 1)
    worst = np.argsort(-(ss / count), kind="stable")[:MAX_TRACE_PANELS]
    return np.sort(worst)


def _noise_state_shown(r: FitResult) -> dict[str, float]:
    """The noise's correlation state the report prints, by name: phi = 0 for a model
    without one, as reports before the state did."""
    return r.model.noise.state_by_name(r.noise_state) or {"phi": r.phi}


def plot_fit(run: FitRun, out_dir: str | Path) -> list[Path]:
    """``traces.png`` (data and fit, with the 95% band of the block means' noise around
    the fit: +-1.96 times the noise's stationary sd (AR(1): sigma_n / sqrt(1 - phi^2)); one
    panel per trace, at most :data:`MAX_TRACE_PANELS`: :func:`shown_traces`),
    ``residuals.png`` and, if profiled, ``profile.png``."""
    r, d = run.chosen, run.data
    out = Path(out_dir)
    pred, w = prediction_at(r.model, r.z, r.noise_state)
    resid = d.force_n - pred
    half = 1.96 * r.sigma_n * r.model.noise.stationary_sd_factor(r.noise_state)
    shown = shown_traces(resid, np.asarray(d.block_trace), d.n_traces)
    cols = 4
    rows = int(np.ceil(shown.size / cols))
    height = 2.3 * rows + 0.9 + (0.3 if shown.size < d.n_traces else 0.0)
    fig, axes = subplots(rows, cols, figsize=(MAX_WIDTH_IN, height), sharex=False, squeeze=False)
    # Fixed margins rather than tight_layout, and few ticks: laying out and ticking 24
    # panels was 2 of the 3 s this figure took, most of a repeated fit's time.
    # (right: room for the last panel's last tick label, half outside its panel)
    top = 0.75 + (0.3 if shown.size < d.n_traces else 0.0)
    fig.subplots_adjust(left=0.08, right=0.975, bottom=0.5 / height, top=1.0 - top / height)
    fig.subplots_adjust(hspace=0.5, wspace=0.3)
    for ax, i in itertools.zip_longest(axes.flat, shown):
        if i is None:
            ax.axis("off")
            continue
        sel = d.block_trace == i
        t, p = d.block_time_s[sel], pred[sel]
        ax.fill_between(t, p - half, p + half, color="C3", alpha=0.25, lw=0, label="95% noise")
        ax.plot(t, d.force_n[sel], ".", ms=2, color="0.4", label="measured")
        ax.plot(t, p, "-", lw=1.0, color="C3", label="fit")
        # y given: matplotlib then skips measuring the tick labels to place the title
        ax.set_title(d.trace_ids[i], fontsize=9, pad=2, y=1.0)
        ax.tick_params(labelsize=9)
        ax.locator_params(nbins=3)
    # above the panels, where it hides no data
    handles, labels = axes.flat[0].get_legend_handles_labels()
    # a bounded figure (96 panels took 8 of a 96-trace fit's 28 s, issue 28) says so
    note = (
        f"the {shown.size} of {d.n_traces} traces with the largest rms residual "
        "(all of them in residuals.png)"
        if shown.size < d.n_traces
        else None
    )
    fig.legend(
        handles,
        labels,
        loc="upper center",
        ncol=3,
        fontsize=9,
        frameon=False,
        title=note,
        title_fontsize=9,
    )
    fig.supxlabel("time [s]", fontsize=10)
    fig.supylabel("force [N] (block means)", fontsize=10)
    paths = [out / TRACES_PNG.name]
    save_figure(fig, paths[-1], tight=False)

    fig, (a1, a2, a3) = subplots(1, 3, figsize=(MAX_WIDTH_IN, 3.6))
    # fixed margins, as above (tight_layout measured every text: 0.2 s)
    fig.subplots_adjust(left=0.065, right=0.99, bottom=0.15, top=0.9, wspace=0.28)
    for i in range(d.n_traces):
        sel = d.block_trace == i
        a1.plot(d.block_time_s[sel], resid[sel], lw=0.5)
    a1.set(xlabel="time [s]", ylabel="residual [N]", title="residuals (block means)")
    lags = np.arange(1, 21)
    for series, label in ((resid, "raw"), (w, "AR(1)-whitened")):
        s = series - series.mean()
        acf = [np.sum(s[k:] * s[:-k]) / np.sum(s * s) for k in lags]
        a2.plot(lags, acf, marker=".", label=label)
    a2.axhline(0, color="k", lw=0.5)
    a2.set(xlabel="lag [blocks]", ylabel="autocorrelation [-]", title="autocorrelation")
    a2.legend()
    a3.hist(w / r.sigma_n, bins=60, density=True, color="0.6")
    x = np.linspace(-4, 4, 200)
    a3.plot(x, np.exp(-(x**2) / 2) / np.sqrt(2 * np.pi), "C3")
    a3.set(
        xlabel="whitened residual / sigma [-]",
        ylabel="density [-]",
        title="whitened vs N(0, 1)",
    )
    paths.append(save_figure(fig, out / RESIDUALS_PNG.name, tight=False))

    if run.profiles:
        n = len(run.profiles)
        fig, axes = subplots(1, n, figsize=(min(3.5 * n, MAX_WIDTH_IN), 3), squeeze=False)
        for ax, prof in zip(axes.flat, run.profiles.values(), strict=True):
            unit = r.estimates[prof.name].unit
            ax.plot(prof.values, prof.delta, marker="o")
            ax.axhline(3.84, color="C3", ls="--", lw=0.8)
            ax.set(xlabel=f"{prof.name} [{unit}]", ylabel="rise of -2 log L [-]")
        paths.append(save_figure(fig, out / "profile.png"))
    return paths
