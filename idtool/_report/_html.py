"""``fits/NAME/report.html``: one self-contained uncertainty report (images embedded).

Built from what ``idtool fit`` and ``idtool sample`` left in the folder; the same figures
are written as PNG files under ``figures/`` and a short ``report.md`` sums it up. The
first screen is the answer (:mod:`idtool._report._answer`) under a header that names
the data, the date and the report id, and any verdict banners; the evidence follows,
and a sign-off block closes it. Sections without their inputs (no posterior yet) say
what to run instead of vanishing.
"""

from __future__ import annotations

import html
import json
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from idtool._atomic import atomic_output_dir, write_text_atomic
from idtool._diagnostic import BANNER_CODES, banner_label, from_records, with_code
from idtool._errors import IdtoolError
from idtool._fit._artefact import FitArtefact
from idtool._fit._folder import (
    FIT_JSON,
    PLAN_CSV,
    PPC_PNG,
    REPORT_HTML,
    REPORT_MD,
    RESIDUALS_PNG,
    TRACES_PNG,
)
from idtool._fit._result import interval_statement
from idtool._fit._store import load_artefact
from idtool._fit._summary import VariabilitySummary
from idtool._levels._store import is_levels_fit
from idtool._plan._options import GoalOptions
from idtool._posterior._diagnostics import STOP_REASONS, import_arviz
from idtool._posterior._draws import fit_draws, stored_posterior
from idtool._posterior._store import POSTERIOR_FILE
from idtool._report._answer import answer
from idtool._report._figures import (
    amplitude_map_figure,
    corner_figure,
    correlation_figure,
    friction_ratio_figures,
    walker_figure,
)
from idtool._report._html_levels import write_levels_report
from idtool._report._html_plan import NEXT_PULLS, NextPulls, next_pulls
from idtool._report._html_validation import validation_banner, validation_section
from idtool._report._page import (
    G,
    g,
    img,
    kv_table,
    now_utc,
    options_bytes,
    page,
    report_id,
    signoff,
    table,
)

__all__ = ["SECTIONS", "write_report"]

SECTIONS = (
    "Answer",
    "Dataset",
    "Estimates",
    "Correlations",
    "Traces and posterior predictive check",
    "Residuals",
    "Posterior: corner plot",
    "Sampling: walkers and convergence",
    "Friction ratio against amplitude and load",
    "Amplitude needed for a target reduction",
    "Held-out validation",
    "Model comparison",
    "Warnings",
    "Provenance",
    "Sign-off",
)
TARGETS = (30.0, 50.0)


def _variability_table(var: VariabilitySummary | None) -> str:
    """The levels model's sds and lack-of-fit test."""
    if var is None:
        return "<p>Scatter and discrepancy: off (noise-only intervals).</p>"
    rows = [
        [name, f"{100 * est:.2f}%", f"[{100 * lo:.2f}%, {100 * hi:.2f}%]"]
        for name, (est, lo, hi) in var.sds.items()
    ]
    return (
        "<p>Pull-to-pull scatter and model discrepancy (relative sds, REML; 95% from "
        "each sd's REML likelihood times a prior that gives 'zero' probability 1/2). "
        f"Lack of fit of the physical model: chi2 = {var.chi2:.1f} "
        f"on {var.dof} dof, p = {var.p_value:.3g}.</p>" + table(["sd", "estimate", "95%"], rows)
    )


def _posterior(folder: Path):
    """(arviz posterior group, idtool metadata) or (None, None)."""
    path = folder / POSTERIOR_FILE
    if not path.is_file():
        return None, None
    idata = import_arviz().from_netcdf(str(path))
    return idata.posterior, json.loads(idata.posterior.attrs["idtool"])


def _banners(fit: FitArtefact, meta: dict | None, extrapolation: Sequence[str] = ()) -> str:
    """Verdicts that must be seen before anything else: a posterior chain that has not
    converged (its columns, bands and plots are not to be trusted yet), a physical
    model that misses the data by more than their noise explains, and answers that
    extrapolate beyond the tested loads or amplitudes."""
    out = []
    chain = [] if meta is None else from_records(meta.get("diagnostic_records", []))
    unconverged = with_code(chain, "not_converged") or (  # posterior.nc before the records
        meta is not None and not meta["diagnostics"].get("converged", True)
    )
    if unconverged:
        assert meta is not None
        diag = meta["diagnostics"]
        stop = STOP_REASONS.get(diag.get("stopped_by", ""), "")
        out.append(
            f"The posterior chain did NOT converge ({diag.get('steps')} steps"
            + (f", stopped: {stop}" if stop else "")
            + f"; about {diag.get('steps_needed')} more needed): the posterior's columns, "
            "bands and plots below are not to be trusted yet. Continue it with idtool sample "
            "FIT --resume, then report again."
        )
    fit_records = [*fit.warnings, *fit.notes]
    out += [f"{banner_label(w)}: {w}" for w in with_code(fit_records, *BANNER_CODES)]
    out += [
        f"Extrapolated answer: {n.removesuffix(': extrapolation')}"
        for n in with_code(extrapolation, "extrapolation")
    ]
    return "".join(f'<p class="banner">{html.escape(b)}</p>' for b in out)


def _convergence(diag: dict) -> str:
    """The chain's verdict, the rule and what stopped the run, then one row per parameter
    (tau, its change, ESS, bulk ESS, R-hat): ``sample.json``'s ``diagnostics``."""
    head = {k: v for k, v in diag.items() if k != "parameters"}
    formats = {"tau": ".1f", "tau_change": ".1%", "ess": ".0f", "ess_bulk": ".0f", "rhat": ".3f"}
    rows = [
        [name, *(format(p[k], f) if k in p else "-" for k, f in formats.items())]
        for name, p in diag.get("parameters", {}).items()
    ]
    header = ["parameter", "tau [steps]", "tau change (last 10%)", "ESS", "bulk ESS", "R-hat"]
    return kv_table(head) + table(header, rows)


def _unasked_note(extrapolation: Sequence[str]) -> str:
    """The default targets' extrapolations, under the answer's tables (not a banner: the
    report chose those targets, nobody asked them of the data)."""
    items = "".join(
        f"<li>{html.escape(n.removesuffix(': extrapolation'))}</li>" for n in extrapolation
    )
    return (
        f'<p class="note">Extrapolated: the default targets '
        f"({', '.join(f'{t:g}%' for t in TARGETS)}) need amplitudes outside the tested "
        f"range at some loads (marked above); ask for targets the tests reach with idtool "
        f'report FIT --targets.</p><ul class="note">{items}</ul>'
    )


def _header(fit: FitArtefact, meta: dict | None, rid: str) -> str:
    """What a qualification file needs to know first: the material and data, when the
    fit and this report were made, the report id, and the lab's own ``x_*`` fields."""
    ds, prov = fit.dataset, fit.summary.provenance
    if meta is None:
        posterior = "none (bands from the fit's covariance)"
    else:
        converged = meta["diagnostics"].get("converged")
        posterior = f"{meta['diagnostics'].get('steps')} steps, " + (
            "converged" if converged else "NOT converged"
        )
    rows = [
        ["material", ds.material],
        ["dataset", f"{ds.name}: {len(ds.traces)} traces; sha256 {ds.sha256}"],
        ["description", ds.description or "-"],
        ["fit", f"{prov.created_utc}; {prov.command}"],
        ["model", _model_line(fit)],
        ["posterior", posterior],
        ["report", f"{rid}, {now_utc()}, idtool {prov.idtool_version}"],
    ]
    rows += [[key, str(value)] for key, value in ds.extensions.items()]
    return table(None, rows, cls="meta")


def _model_line(fit: FitArtefact) -> str:
    """The chosen model in words, and the coupling laws predictions average over."""
    m = fit.model
    line = (
        f"{m.law.name} friction, {m.coupling.name} coupling, {m.actuator.name} actuator, "
        f"{m.offset.name} load-cell offset, {m.level.name} levels"
    )
    if m.direction.name != "along":
        line += f", vibration {m.direction.name}"
    if fit.alternates:
        table = fit.model_weights or fit.coupling_laws
        weights = {law: w["bic_weight"] for law, w in table.items()}
        kept = [fit.chosen_label, *fit.alternates]
        what = "models (coupling law and direction)" if fit.model_weights else "coupling laws"
        line += f"; predictions averaged over the {what} by BIC weight: " + ", ".join(
            f"{law} {weights.get(law, 0.0):.2f}" for law in kept
        )
    return line


def _choice_table(title: str, what: str, entries: Mapping[str, Mapping[str, Any]]) -> str:
    """A model choice's BIC table (each option's best model and weights), options that
    fit comparably (BIC weight above 0.05 beside the chosen) flagged; nothing for one."""
    if len(entries) < 2:
        return ""
    first = next(iter(entries.values())).get("criterion", "traces")
    rows = []
    best = min(float(e["bic"]) for e in entries.values() if e.get("criterion", "traces") == first)
    for name, e in entries.items():
        close = float(e["bic_weight"]) > 0.05 and float(e["bic"]) > best
        weighed = e.get("criterion", "traces") == first
        rows.append(
            [
                name,
                f"{float(e['bic']) - best:.1f}" if weighed else "levels model not estimable",
                f"{float(e['bic_weight']):.3f}",
                f"{float(e['aic_weight']):.3f}",
                str(e["key"]),
                "fits comparably" if close else ("chosen" if float(e["bic"]) == best else ""),
            ]
        )
    levels = first == "levels"
    basis = (
        "<p>Weighed by the levels model's likelihood (pull-to-pull scatter and "
        "discrepancy in it), on the same free levels for every option.</p>"
        if levels
        else ""
    )
    return (
        f"<h3>{html.escape(title)}</h3>"
        + basis
        + table([what, "delta BIC", "BIC weight", "AIC weight", "best model", ""], rows)
    )


def _report_id(
    folder: Path,
    targets: Sequence[float],
    loads_n: Sequence[float],
    goal: GoalOptions | None,
) -> str:
    parts = [(folder / FIT_JSON.name).read_bytes()]
    if (folder / POSTERIOR_FILE).is_file():
        parts.append((folder / POSTERIOR_FILE).read_bytes())
    options = options_bytes(
        targets=list(targets),
        loads_n=list(loads_n),
        plan=None if goal is None else goal.as_dict(),
    )
    return report_id(*parts, options)


def write_report(
    fit_folder: str | Path,
    targets: Sequence[float] | None = None,
    loads_n: Sequence[float] = (),
    *,
    goal: str = "parameters",
    n_pulls: int = 10,
    at: Sequence[tuple[float, float]] | None = None,
    half_width: float = 0.01,
    rel: float = 0.05,
    weight: float = 0.95,
    plan: bool = True,
) -> Path:
    """Write ``report.html``, ``report.md`` and ``figures/*.png`` into ``fit_folder``,
    and ``plan.csv`` when the goal is unmet.

    Args:
        fit_folder: a folder written by ``idtool fit`` (or :meth:`idtool.Fit.save`).
        targets: friction reductions [%] for which the answer gives the amplitude needed
            (default :data:`TARGETS`).
        loads_n: loads [N] at which to give it, besides the tested ones (those beyond
            the tested range are flagged as extrapolation).
        goal: the planning goal whose next pulls the section "What to measure next"
            gives while the fit does not meet it (:meth:`idtool.Fit.plan`'s, with its
            options below; default: every physical parameter to a relative sd of
            0.05), with ``plan.csv`` beside the report (the conditions table ``idtool
            import --conditions`` reads) and ``figures/plan.png``. A met goal is one
            line under the answer.
        n_pulls: the pulls to plan.
        at: the band goal's operating points, (load [N], amplitude fraction) pairs.
        half_width: the band goal's target half-width [FR].
        rel: the parameters goal's target relative sd.
        weight: the laws goal's target weight of the true law.
        plan: False leaves the section (and the goal's check) out.

    An answer that extrapolates beyond the tested loads or amplitudes is a red banner
    when it answers what was asked (``targets`` or ``loads_n`` given); for the default
    targets, which the report chose and the data may not reach, the answer's table marks
    it and a note under the table says so.
    """
    asked = targets is not None or bool(loads_n)
    targets = TARGETS if targets is None else targets
    for t in targets:
        if not 0.0 < t < 100.0:
            raise IdtoolError(f"targets: {t:g}% is not a reduction in (0, 100)")
    for load in loads_n:
        if not load > 0.0:
            raise IdtoolError(f"loads_n: {load:g} N is not a positive load")
    goal_options = (
        GoalOptions(
            goal,
            n_pulls,
            tuple((float(n), float(a)) for n, a in at or ()),
            half_width,
            rel,
            weight,
        )
        if plan
        else None
    )

    folder = Path(fit_folder)
    if is_levels_fit(folder):  # a friction table's fit: its own page (no answer options)
        return write_levels_report(folder)
    fit = load_artefact(folder)
    summary, prov = fit.summary, fit.summary.provenance
    post, meta = _posterior(folder)
    # 400 draws put the 2.5% and 97.5% points within about 1% of their limits while
    # keeping the inverse (bisection per draw) quick.
    stored = stored_posterior(folder)
    draws = fit_draws(fit, stored, max_draws=400)
    names = list(fit.model.physical_names)
    speed = float(np.median(fit.model.data.pull_speed_m_s))
    rid = _report_id(folder, targets, loads_n, goal_options)
    first = answer(fit, draws, targets, loads_n)
    unasked = "" if asked or not first.extrapolation else _unasked_note(first.extrapolation)
    sec: dict[str, str] = {"Answer": f'<div class="answer">{first.html}{unasked}</div>'}
    md: list[str] = [f"# idtool report: {fit.dataset.name}", "", f"Report {rid}", ""]
    md += [*first.markdown, ""]

    with atomic_output_dir(folder / "figures", force=True) as figs:
        nxt = NextPulls()
        if goal_options is not None:
            nxt = next_pulls(fit, folder, stored, goal_options, figs)
        sec["Answer"] = sec["Answer"].removesuffix("</div>") + nxt.note + "</div>"
        if nxt.section is not None:
            sec[NEXT_PULLS] = nxt.section
        md += [*nxt.markdown, ""]
        ds = fit.dataset
        sec["Dataset"] = (
            f"<p>{html.escape(ds.name)}: {len(ds.traces)} traces; "
            f"horn {ds.rig.vibration_frequency_hz:g} Hz, max amplitude "
            f"{ds.rig.max_amplitude_m * 1e6:g} um; sha256 <code>{ds.sha256}</code></p>"
            + table(
                ["trace", "load [N]", "amplitude", "speed [m/s]", "duration [s]", "ON [s]"],
                [
                    [
                        t.id,
                        g(t.normal_load_n),
                        g(t.amplitude_fraction),
                        g(t.pull_speed_m_s),
                        f"{t.duration_s:.2f}",
                        ", ".join(f"{a:.2f}-{b:.2f}" for a, b in t.on_windows_s) or "none",
                    ]
                    for t in ds.traces
                ],
            )
        )
        rows = []
        meaning = {q.name: q.description for q in fit.model.declared_params}
        physical = {q.name for q in fit.model.declared_params if q.physical}
        fixed = [n for n, e in fit.estimates.items() if e.fixed and n in physical]
        for n in [*names, *fixed]:
            e = fit.estimates[n]
            row = [n, meaning.get(n, ""), e.unit, g(e.estimate)]
            # "> lo" where the data bound it on one side only, "not identified" or
            # "weakly identified" where they barely bound it
            row += [interval_statement(*e.ci95, e.one_sided, G)]
            if n in fixed:
                row[-1:] = [e.fixed_label or "fixed by the user", "-", "fixed (not sampled)"]
            elif post is not None and n in post:
                v = np.asarray(post[n].values).ravel()
                lo, med, hi = np.percentile(v, [2.5, 50, 97.5])
                side = (meta or {}).get("one_sided", {}).get(n, "")  # the sampler's
                row += [g(med), interval_statement(lo, hi, side, G)]
            else:
                row += ["-", "no posterior: run idtool sample"]
            rows.append(row)
        for n, (e, what) in summary.derived.items():  # e.g. the sdof law's drive force
            ci = f"[{g(e.ci95[0])}, {g(e.ci95[1])}]"
            rows.append([n, what, e.unit, g(e.estimate), ci, "-", "derived from the fit"])
        sec["Estimates"] = table(
            ["parameter", "meaning", "unit", "fit", "fit 95%", "posterior median", "posterior 95%"],
            rows,
        )
        md += ["| parameter | fit | 95% | posterior 95% |", "|---|---|---|---|"]
        md += [f"| {r[0]} [{r[2]}] | {r[3]} | {r[4]} | {r[6]} |" for r in rows]

        cpath = correlation_figure(
            list(summary.correlation_names), summary.correlation, figs / "correlation.png"
        )
        sec["Correlations"] = img(cpath, "correlation matrix")

        # The measured traces against the fitted ones always; the posterior predictive
        # check beside them once there is a posterior.
        sec["Traces and posterior predictive check"] = (
            "<p>Measured block means (grey) against the fitted traces (red), with the 95% "
            "band of the load cell's noise around the fit.</p>"
            + img(folder / TRACES_PNG.name, "measured and fitted traces")
            + (
                img(folder / PPC_PNG.name, "posterior predictive check")
                if (folder / PPC_PNG.name).is_file()
                else "<p>No posterior predictive check yet (run idtool sample).</p>"
            )
        )
        sec["Residuals"] = img(folder / RESIDUALS_PNG.name, "residuals and autocorrelation")

        corner_src = (
            {n: np.asarray(post[n].values).ravel() for n in names}
            if post is not None
            else draws.values
        )
        units = {n: fit.estimates[n].unit for n in names}
        kpath = corner_figure(corner_src, names, units, figs / "corner.png")
        sec["Posterior: corner plot"] = f"<p>Draws: {html.escape(draws.note)}</p>" + img(
            kpath, "corner plot"
        )
        if post is not None:
            sampled = [str(v) for v in post.data_vars]
            chains = {n: np.asarray(post[n].values) for n in sampled}
            units |= {n: str(post[n].attrs.get("units", "")) for n in sampled}
            wpath = walker_figure(chains, sampled, units, figs / "walkers.png")
            diag = meta["diagnostics"]
            sec["Sampling: walkers and convergence"] = _convergence(diag) + img(wpath, "walkers")
            md += ["", f"Sampling converged: {diag.get('converged')}"]
        else:
            sec["Sampling: walkers and convergence"] = "<p>No posterior: run idtool sample.</p>"

        p1, p2 = friction_ratio_figures(draws, summary.traces, speed, figs)
        sec["Friction ratio against amplitude and load"] = (
            f"<p>Median and 95% bands ({html.escape(draws.note)}). Dark band: the mean "
            "friction ratio at that operating point (use it for design curves); light "
            "band: what the next single pull will give, pull-to-pull scatter added (use "
            "it for acceptance limits). Points: each trace's own friction ratio, fitted "
            "from that trace alone, with its 95% interval from its own noise (traces whose "
            "ON window ends before the force settles measure none).</p>"
            + _variability_table(summary.variability)
            + img(p1, "FR against amplitude")
            + img(p2, "FR against load")
        )
        loads = fit.model.data.normal_load_n
        grid = np.linspace(0.5 * loads.min(), 1.5 * loads.max(), 12)
        apath, _ = amplitude_map_figure(
            draws, tuple(targets), grid, speed, figs / "amplitude_map.png"
        )
        sec["Amplitude needed for a target reduction"] = (
            "<p>The amplitude needed against load (the answer's table gives it at the "
            "tested loads).</p>" + img(apath, "amplitude map")
        )

        sec["Held-out validation"] = validation_section(folder)
        sec["Model comparison"] = (
            f"<p>{html.escape(summary.choice)}</p>"
            + _choice_table("Coupling laws", "law", fit.coupling_laws)
            + _choice_table("Directions of vibration", "direction", fit.directions)
            + "<h3>Every candidate</h3><p>By the traces' likelihood, which chooses the "
            "actuator, offset and level models within each option.</p>"
            + table(
                ["model", "AIC", "BIC", "log L", "parameters"],
                [
                    [m.model, f"{m.aic:.1f}", f"{m.bic:.1f}", f"{m.loglik:.1f}", m.n_params]
                    for m in summary.model_comparison
                ],
            )
        )
        warnings = list(fit.warnings) + ([] if meta is None else meta.get("warnings", []))
        sec["Warnings"] = (
            "<ul>" + "".join(f"<li>{html.escape(w)}</li>" for w in warnings) + "</ul>"
            if warnings
            else "<p>none</p>"
        )
        if fit.notes:  # facts of the design, not doubts: below the warnings
            sec["Warnings"] += (
                "<h3>Notes</h3><ul>"
                + "".join(f"<li>{html.escape(n)}</li>" for n in fit.notes)
                + "</ul>"
            )
        record = {
            "dataset": prov.dataset,
            "fit command": prov.command,
            "fit seed": prov.seed,
            "versions": prov.versions,
            "idtool": prov.idtool_version,
            "sampling": None
            if meta is None
            else {k: meta.get(k) for k in ("seed", "noise", "timing")},
        }
        sec["Provenance"] = kv_table(record)
        sec["Sign-off"] = signoff()
        md += ["", f"Dataset sha256 {ds.sha256}; fit command `{prov.command}`"]

    title = f"idtool report: {fit.dataset.name}"
    extrapolation = first.extrapolation if asked else []
    banners = _banners(fit, meta, extrapolation) + validation_banner(folder)
    order = (SECTIONS[0], NEXT_PULLS, *SECTIONS[1:])
    document = page(title, _header(fit, meta, rid), banners, {n: sec[n] for n in order if n in sec})
    if nxt.csv is not None:
        write_text_atomic(folder / PLAN_CSV.name, nxt.csv)
    else:  # an older report's plan is no longer this report's
        (folder / PLAN_CSV.name).unlink(missing_ok=True)
    out = write_text_atomic(folder / REPORT_HTML.name, document)
    write_text_atomic(folder / REPORT_MD.name, "\n".join(md) + "\n")
    return out
