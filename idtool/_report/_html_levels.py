"""``report.html`` of a friction table's fit (kind: levels): the page builder of
:mod:`idtool._report._page` on what ``idtool fit`` and ``idtool sample`` left in the
folder: the predictions with their bands first (the posterior's once sampled, else the
fit's Wald bands), the fit's warnings as banners, then the estimates (fit and posterior
intervals), the table against the fit, the FR-against-speed figure when the table spans
speeds, the chain's convergence, provenance and sign-off."""

from __future__ import annotations

import html
import math
from pathlib import Path

import numpy as np

from idtool._atomic import atomic_output_dir, write_text_atomic
from idtool._lawfit._result import estimate_from_sides
from idtool._levels._estimate import SD_NAMES
from idtool._levels._result import FIGURE, FIT_JSON, POSTERIOR_NC, LevelsFit
from idtool._levels._store import load_levels_fit
from idtool._report._page import g, img, kv_table, now_utc, page, report_id, signoff, table
from idtool._version import __version__

__all__ = ["write_levels_report"]

REPORT_HTML, REPORT_MD = "report.html", "report.md"
PLAN_ROWS = 6  # rows the report's section proposes (idtool plan for more, or a band goal)
HEAD = [
    "rank", "load [N]", "amplitude [um]", "speed [mm/s]", "largest rel. sd after",
    "uniform choice",
]  # fmt: skip


def _bands(fit: LevelsFit) -> tuple[str, list[str]]:
    """FR at each of the table's conditions with its bands: HTML and markdown."""
    t = fit.table
    _, first = t.operating_points
    p = fit.predict(
        t.normal_load_n[first], t.sliding_speed_m_s[first], amplitude_m=t.amplitude_m[first],
        frequency_hz=t.vibration_frequency_hz[first],
    )  # fmt: skip
    rows, md = [], ["| load N | amplitude um | speed mm/s | FR | 95% new condition | 95% next |"]
    md.append("|---|---|---|---|---|---|")
    for i in range(first.size):
        mean = f"[{g(p.mean_band[0][i])}, {g(p.mean_band[1][i])}]" if p.pinned[i] else "not pinned"
        nxt = f"[{g(p.next_band[0][i])}, {g(p.next_band[1][i])}]" if p.pinned[i] else "not pinned"
        row = [
            g(p.load_n[i]), g(p.amplitude_m[i] * 1e6), g(p.speed_m_s[i] * 1e3),
            g(p.frequency_hz[i] / 1e3), g(p.fr[i]), mean, nxt,
            f"{100 * (1 - p.fr[i]):.1f}%",
        ]  # fmt: skip
        rows.append(row)
        md.append(f"| {row[0]} | {row[1]} | {row[2]} | {row[4]} | {mean} | {nxt} |")
    source = (
        "the posterior's draws (median; the discrepancy, and for the next measurement the "
        "scatter, drawn with each)"
        if fit.posterior is not None
        else "the fit's covariance (Wald, delta method on log FR) with the discrepancy and "
        "scatter sds; sample the posterior (idtool sample) for posterior bands"
    )
    head = [
        "load [N]", "amplitude [um]", "speed [mm/s]", "frequency [kHz]", "FR",
        "95% band, new condition", "95% band, next measurement", "reduction",
    ]  # fmt: skip
    out = (
        f"<p>Friction ratio ON/OFF at each condition of the table; bands from {source}.</p>"
        + table(head, rows)
    )
    return out, md


def _estimates(fit: LevelsFit) -> str:
    summary = fit.posterior.summary() if fit.posterior is not None else {}
    rows = []
    for name, e in fit.estimates.items():
        s = summary.get(name)
        post = f"{g(s['median'])} [{g(s['ci95'][0])}, {g(s['ci95'][1])}]" if s else "-"
        rows.append([name, e.unit, g(e.estimate), e.statement, post])
    for name in SD_NAMES:
        s = summary.get(name)
        post = f"{g(s['median'])} [{g(s['ci95'][0])}, {g(s['ci95'][1])}]" if s else "-"
        value = fit.optimum.sds[name]
        est = "not estimated" if value == 0 else g(value)
        how = "REML" if fit.optimum.restricted else "ML"
        d = fit.optimum.discrepancy
        if name == "discrepancy_fr" and d is not None:
            # the bands' sd: REML's estimate integrated over its likelihood
            how = f"[{g(d.ci95[0])}, {g(d.ci95[1])}] (REML estimate {g(d.reml)})"
        rows.append([name, "1 (relative sd)", est, how, post])
    head = ["parameter", "unit", "fit estimate", "fit 95% interval", "posterior median [95%]"]
    return table(head, rows)


def _shape(fit: LevelsFit) -> str:
    """The coupling law's shape against free slip amplitudes (idtool/_levels/_free.py):
    the test and each friction-law parameter's law-free interval beside the stated one."""
    c = fit.coupling_check
    assert c is not None
    verdict = "rejected at 5%: intervals widened" if c.rejected else "not rejected"
    rows = []
    for name, (lo, hi) in c.free.items():
        p = fit.model.params[fit.model.names.index(name)]
        free = estimate_from_sides(p, 0.0, math.inf, lo, hi).statement
        rows.append([name, free, fit.estimates[name].statement])
    return (
        f"<p>The {html.escape(c.coupling)} law against a free slip amplitude at each of the "
        f"table's {c.points} load-amplitude points ({c.resolved} measured at two or more "
        "speeds, where the speeds pin Kt without a coupling law): -2 log likelihood ratio "
        f"{c.statistic:.2f}, F on {c.dof} and {c.residual_dof} degrees of freedom, "
        f"p = {c.p_value:.3g}. Verdict: <b>{verdict}</b>.</p>"
        + table(["parameter", "law-free 95% interval", "stated 95% interval"], rows)
    )


def _data(fit: LevelsFit) -> str:
    t = fit.table
    fitted = fit.fitted_fr
    unit = "-" if t.friction == "coefficient" else "N"

    def se(x: float) -> str:
        return g(x) if np.isfinite(x) else "-"

    rows = [
        [
            str(i + 1),
            g(t.normal_load_n[i]),
            g(t.amplitude_m[i] * 1e6),
            g(t.vibration_frequency_hz[i] / 1e3),
            g(t.sliding_speed_m_s[i] * 1e3),
            g(t.off[i]),
            se(t.off_se[i]),
            g(t.on[i]),
            se(t.on_se[i]),
            t.repeat[i] or "-",
            g(t.friction_ratio[i]),
            g(fitted[i]),
        ]
        for i in range(t.n_rows)
    ]
    head = [
        "row", "load [N]", "amplitude [um]", "frequency [kHz]", "speed [mm/s]",
        f"OFF [{unit}]", "OFF se", f"ON [{unit}]", "ON se", "repeat", "FR", "FR fitted",
    ]  # fmt: skip
    return table(head, rows)


def _next_rows(fit: LevelsFit) -> str:
    """The parameters goal's plan (every physical parameter to a 5% relative sd):
    met, or the next rows with the goal's value after each beside a uniform choice."""
    plan = fit.plan("parameters", PLAN_ROWS)
    if plan.met:
        return (
            f"<p>Every physical parameter is within a {100 * plan.target:g}% relative sd "
            f"({100 * plan.values[0]:.2g}% at most): no row is needed for that goal. For a "
            "narrower band at stated conditions: idtool plan FITDIR --goal band --at "
            "LOAD,AMPLITUDE.</p>"
        )
    if plan.values[-1] > 0.99 * plan.values[0]:
        # e.g. one load and one amplitude: rows within the table's ranges repeat what it
        # has, and a parameter it does not inform stays so
        return (
            f"<p>Goal: every physical parameter within a {100 * plan.target:g}% relative "
            f"sd; now {100 * plan.values[0]:.3g}% at most. No row within the table's "
            "ranges of load, amplitude and speed improves that by 1% (the largest stays "
            f"{100 * plan.values[-1]:.3g}% after {PLAN_ROWS}): widen them, idtool plan "
            "FITDIR --goal parameters --loads LO:HI --amplitudes LO:HI (other loads and "
            "amplitudes inform the coupling law's shape; the plan says by how much).</p>"
        )
    rows = [
        [str(r.rank), g(r.normal_load_n), g(r.amplitude_m * 1e6), g(r.sliding_speed_m_s * 1e3),
         f"{100 * r.value_after:.3g}%", f"{100 * u:.3g}%"]
        for r, u in zip(plan.rows, plan.uniform[1:], strict=True)
    ]  # fmt: skip
    reach = (
        f"{plan.rows_to_target} of them reach it"
        if plan.rows_to_target is not None
        else f"{PLAN_ROWS} do not reach it"
    )
    return (
        f"<p>Goal: every physical parameter within a {100 * plan.target:g}% relative sd; "
        f"now {100 * plan.values[0]:.3g}% at most. The next {PLAN_ROWS} rows (the "
        f"linearised model, idtool plan FITDIR --goal parameters); {reach}.</p>"
        + table(HEAD, rows)
        + '<p class="note">'
        + html.escape("; ".join(plan.notes))
        + "</p>"
    )


def _models(fit: LevelsFit) -> str:
    """The model choice's ranking (``fit_levels(..., direction="auto")`` or
    ``coupling="auto"``): BIC, its excess over the best, weight, kept or not."""
    best = fit.ranking[0].bic
    kept = 1 + len(fit.alternates)
    rows = [
        [w.name, f"{w.bic:.2f}", f"{w.bic - best:.2f}", f"{w.bic_weight:.3f}",
         "estimates and bands" if i == 0 else ("bands" if i < kept else "-")]
        for i, w in enumerate(fit.ranking)
    ]  # fmt: skip
    return (
        "<p>Every model fitted, ranked by BIC; weights exp(-delta/2) (their posterior "
        "probabilities under equal prior odds). The estimates are the best model's; the "
        "bands average the models used for them by weight.</p>"
        + table(["model", "BIC", "delta", "weight", "used for"], rows)
    )


def _convergence(fit: LevelsFit) -> str:
    post = fit.posterior
    if post is None:
        return "<p>Not sampled: the intervals are the fit's (run idtool sample FITDIR).</p>"
    d = post.diagnostics
    rows = [
        [n, g(v["tau"]), g(v["ess_bulk"]), f"{v['rhat']:.3f}"]
        for n, v in d.get("parameters", {}).items()
    ]
    verdict = "converged" if post.converged else "NOT converged"
    return (
        f"<p>{html.escape(post.describe())}; burn-in {d.get('burn_in')}, {post.n_draws} draws "
        f"kept; rule: {html.escape(str(d.get('rule', '')))}. Verdict: <b>{verdict}</b>.</p>"
        + table(["parameter", "tau [steps]", "bulk ESS", "R-hat"], rows)
    )


def write_levels_report(fit_folder: str | Path) -> Path:
    """Write ``report.html``, ``report.md`` and ``figures/`` into a table fit's folder
    (module docstring); returns the path of ``report.html``."""
    folder = Path(fit_folder)
    fit = load_levels_fit(folder)
    t = fit.table
    parts = [(folder / FIT_JSON).read_bytes()]
    if (folder / POSTERIOR_NC).is_file():
        parts.append((folder / POSTERIOR_NC).read_bytes())
    rid = report_id(*parts, b"levels")
    answer, md_answer = _bands(fit)
    sec: dict[str, str] = {"Answer": f'<div class="answer">{answer}</div>'}
    with atomic_output_dir(folder / "figures", force=True) as figs:
        if fit.spans_speeds:
            fit.plot_speed(figs / FIGURE)
            sec["Answer"] += (
                "<h3>Friction ratio against sliding speed</h3>"
                + img(figs / FIGURE, "FR against sliding speed with 95% bands")
                + '<p class="note">Curve: the model; dark band: FR at a new condition; '
                "light: the next measurement; points: the table's rows with 1.96 standard "
                "errors. Also figures/fr_vs_speed.png.</p>"
            )
        else:
            sec["Answer"] += '<p class="note">The table has one speed: no curve against speed.</p>'
    if fit.ranking:
        sec["Models compared"] = _models(fit)
    sec["What to measure next"] = _next_rows(fit)
    sec["Estimates"] = _estimates(fit)
    if fit.coupling_check is not None:
        sec["Coupling law's shape"] = _shape(fit)
    sec["Data"] = _data(fit)
    if fit.notes:
        sec["Notes"] = "<ul>" + "".join(f"<li>{html.escape(n)}</li>" for n in fit.notes) + "</ul>"
    sec["Convergence"] = _convergence(fit)
    m = fit.model
    doc = fit.to_json()
    sec["Provenance"] = kv_table(
        {
            "dataset": doc["dataset"],
            "model": doc["model"],
            "fit seed": fit.seed,
            "fit seconds": fit.seconds,
            "sampling": None
            if fit.posterior is None
            else {"seed": fit.posterior.seed, "timing": fit.posterior.timing},
            "idtool": __version__,
        }
    )
    sec["Sign-off"] = signoff()
    banners = "".join(
        f'<div class="banner">{html.escape(w)}</div>'
        for w in (
            *fit.warnings,
            *(
                ["the posterior chain did NOT converge: continue it (idtool sample --resume)"]
                if fit.posterior is not None and not fit.posterior.converged
                else []
            ),
        )
    )
    posterior = "none (bands from the fit's covariance)"
    if fit.posterior is not None:
        posterior = fit.posterior.describe()
    header = table(
        None,
        [
            ["material", t.material],
            ["dataset", f"{t.name}: friction table, {t.n_rows} rows; sha256 {t.sha256}"],
            ["source", t.source or "-"],
            [
                "model",
                f"{m.law} friction, {m.coupling} coupling, vibration {m.direction}"
                + (
                    f" (best of {len(fit.ranking)} by BIC; bands over {1 + len(fit.alternates)})"
                    if fit.ranking
                    else ""
                )
                + (
                    "; the horn's output drifting linearly over the rows' times (horn_drift),"
                    " every estimate and band at the campaign's middle"
                    if m.spec.drift
                    else ""
                ),
            ],
            ["posterior", posterior],
            ["report", f"{rid}, {now_utc()}, idtool {__version__}"],
        ],
        cls="meta",
    )
    title = f"idtool report: {t.name} (friction table)"
    document = page(title, header, banners, sec)
    md = [f"# {title}", "", f"Report {rid}", "", *md_answer, "", *(f"- {w}" for w in fit.warnings)]
    out = write_text_atomic(folder / REPORT_HTML, document)
    write_text_atomic(folder / REPORT_MD, "\n".join(md) + "\n")
    return out
