"""``compare.html``: the comparison as one self-contained page (images embedded), with
the look and print rules of ``report.html`` (:mod:`idtool._report._page`): the fits and
their data first, banners, then the answer (which reduces friction more), the
amplitudes for the targets, the estimates, the overlaid curves, warnings, provenance.
"""

from __future__ import annotations

import html
from collections.abc import Sequence
from pathlib import Path

from idtool._report._answer import _amplitude_cell
from idtool._report._comparison import DECISIVE, ComparisonRecord, prob
from idtool._report._page import g, img, kv_table, page, table
from idtool._version import __version__

__all__ = ["DECISIVE", "SECTIONS", "compare_html", "prob"]

SECTIONS = (
    "Answer: which reduces friction more",
    "Amplitude needed for a target reduction",
    "Estimates",
    "Friction ratio against amplitude and load",
    "Warnings",
    "Provenance",
)


def _beyond(c: ComparisonRecord, name: str, value: float, text: str) -> str:
    """``text``, marked when ``value`` of ``name`` lies outside some fit's tested range."""
    outside = any(
        not min(f.tested(name)) * (1 - 1e-9) <= value <= max(f.tested(name)) * (1 + 1e-9)
        for f in c.fits
    )
    return text + (" (extrapolated)" if outside else "")


def _verdict(a: str, b: str, p: float) -> str:
    if p >= DECISIVE:
        return f"{a} reduces more"
    if p <= 1 - DECISIVE:
        return f"{b} reduces more"
    return "not resolved"


def _answer(c: ComparisonRecord) -> str:
    """Per pair, at each operating point: both FRs, the difference, the probability."""
    by_label = {f.label: f for f in c.fits}
    out = (
        "<p><b>P(A reduces friction more)</b> is the probability, under the two fits' "
        "posteriors, that A's mean friction ratio FR (pull force with ultrasound / "
        "without, over many pulls) at that load and amplitude is below B's. 0.5: the "
        "data cannot tell them apart; at least 0.95 (at most 0.05): A (B) reduces "
        "friction more. &plusmn;: its Monte-Carlo standard error. <b>Reduction A - B</b>: "
        "A's reduction 100 (1 - FR) % minus B's, in percentage points. <b>Single "
        "pulls</b>: how often one pull on A gives a lower FR than one pull on B "
        "(pull-to-pull scatter included).</p>"
    )
    for a, b, pts in c.pairs:
        fa, fb = by_label[a], by_label[b]
        max_um = fa.fit.dataset.rig.max_amplitude_m * 1e6
        rows = []
        for k, p in enumerate(pts):
            pa, pb = fa.predictions[k], fb.predictions[k]
            med, lo, hi = p.reduction_difference
            rows.append(
                [
                    _beyond(c, "normal_load_n", p.normal_load_n, g(p.normal_load_n)),
                    _beyond(
                        c,
                        "amplitude_fraction",
                        p.amplitude_fraction,
                        f"{p.amplitude_fraction:.0%} ({p.amplitude_fraction * max_um:.0f} um)",
                    ),
                    f"{pa.median:.3f} [{pa.ci95[0]:.3f}, {pa.ci95[1]:.3f}]",
                    f"{pb.median:.3f} [{pb.ci95[0]:.3f}, {pb.ci95[1]:.3f}]",
                    f"{med:+.1f} [{lo:+.1f}, {hi:+.1f}]",
                    prob(p.probability, p.standard_error).removeprefix("= "),
                    prob(p.probability_next_pull).removeprefix("= "),
                    _verdict(a, b, p.probability),
                ]
            )
        header = ["load [N]", "amplitude (of max)", f"FR {a} [95%]", f"FR {b} [95%]"]
        header += [f"reduction {a} - {b} [points, 95%]", f"P({a} reduces more)"]
        header += ["P, single pulls", "verdict"]
        out += f"<h3>{html.escape(a)} against {html.escape(b)}</h3>" + table(header, rows)
    return out


def _amplitudes(c: ComparisonRecord) -> str:
    rows = []
    n_loads = len(c.load_n)
    for t, target in enumerate(c.targets):
        for k, load in enumerate(c.load_n):
            row = [f"{target:g}%", _beyond(c, "normal_load_n", load, g(load))]
            for f in c.fits:
                amps = f.tested("amplitude_fraction")
                max_um = f.fit.dataset.rig.max_amplitude_m * 1e6
                a = f.amplitudes[t * n_loads + k]
                row.append(_amplitude_cell(a, max_um, (amps[0], amps[-1])))
            rows.append(row)
    header = ["target reduction", "load [N]"] + [f"{f.label}: amplitude [95%]" for f in c.fits]
    return (
        "<p>Commanded amplitude (percent of the horn's maximum [95%], and in micrometres) "
        "each fit needs for the target reduction of its mean friction ratio; "
        "'(extrapolated)' beyond its tested amplitudes.</p>" + table(header, rows)
    )


def _interval(ci: Sequence[float]) -> str:
    return f"{g(ci[0])}, {g(ci[1])}"


def _estimates(c: ComparisonRecord) -> str:
    est = {f.label: f.estimates() for f in c.fits}
    names = list(dict.fromkeys(n for e in est.values() for n in e))  # fixed ones too
    rows = []
    for name in names:
        have = [e[name] for e in est.values() if name in e]
        row = [name, have[0]["unit"]]
        for f in c.fits:
            e = est[f.label].get(name)  # None: this fit's model has no such parameter
            if e is None:
                row.append("-")
            elif e["source"] == "fixed":
                row.append(f"{g(e['estimate'])} ({e['fixed_by']})")
            else:
                row.append(f"{g(e['estimate'])} [{_interval(e['ci95'])}]")
        rows.append(row)
    source = ["intervals from", ""] + [
        "posterior (median)" if f.has_posterior else "fit (no posterior)" for f in c.fits
    ]
    return table(["parameter", "unit"] + [f"{f.label} [95%]" for f in c.fits], [*rows, source])


def _header(c: ComparisonRecord) -> str:
    rows = []
    for f in c.fits:
        ds, m = f.fit.dataset, f.fit.model
        if not f.has_posterior:
            post = "none: Gaussian draws on the fit's covariance"
        else:
            post = f"{f.draws.n} draws, " + ("converged" if f.converged else "NOT converged")
        loads = ", ".join(g(v) for v in f.tested("normal_load_n"))
        amps = ", ".join(f"{v:.0%}" for v in f.tested("amplitude_fraction"))
        rows.append(
            [
                f.label,
                ds.material,
                f"{ds.name}: {len(ds.traces)} traces",
                f"{m.law.name}, {m.coupling.name} coupling",
                post,
                f"{loads} N x {amps}",
            ]
        )
    fits = table(["fit", "material", "dataset", "model", "posterior", "tested"], rows)
    sha = "<br>".join(
        f"{html.escape(f.label)}: {html.escape(str(f.fit.folder or '(in memory)'))}; dataset "
        f"sha256 <code>{f.fit.dataset.sha256}</code>"
        for f in c.fits
    )
    points = (
        f"loads {', '.join(g(v) for v in c.load_n)} N x amplitudes "
        f"{', '.join(f'{v:.0%}' for v in c.amplitude)} at {c.speed_m_s:g} m/s"
    )
    meta = [
        ["compared", f"{c.id}, {c.created_utc}, idtool {__version__}"],
        ["operating points", points],
        ["reference", f"{c.fits[0].label}: every probability is its own against another fit"],
    ]
    return fits + f'<p class="note">{sha}</p>' + table(None, meta, cls="meta")


def compare_html(c: ComparisonRecord, figures: Sequence[Path]) -> str:
    """The page of ``c`` with the figures ``figures`` (FR against amplitude, load; none:
    the section says they were left out)."""
    prov = {f.label: f.fit.artefact.summary.provenance for f in c.fits}
    sec = {
        SECTIONS[0]: f'<div class="answer">{_answer(c)}</div>',
        SECTIONS[1]: _amplitudes(c),
        SECTIONS[2]: _estimates(c),
        SECTIONS[3]: (
            (
                "<p>Each fit's mean friction ratio, median and 95% band (the model's "
                "discrepancy between operating points included); the bands widen away "
                "from each fit's tested range (bars above FR = 1).</p>"
                + img(figures[0], "FR against amplitude, fits overlaid")
                + img(figures[1], "FR against load, fits overlaid")
            )
            if figures
            else '<p class="note">Not drawn: compared with --no-figures.</p>'
        ),
        SECTIONS[4]: (
            "<ul>" + "".join(f"<li>{html.escape(w)}</li>" for w in c.warnings) + "</ul>"
            if c.warnings
            else "<p>none</p>"
        ),
        SECTIONS[5]: kv_table(
            {
                **{
                    f.label: {
                        "fit command": prov[f.label].command,
                        "fit created": prov[f.label].created_utc,
                        "draws": f.draws.note,
                    }
                    for f in c.fits
                },
                "compare": {"seed": c.seed, "draws per fit": [f.draws.n for f in c.fits]},
            }
        ),
    }
    banners = "".join(f'<p class="banner">{html.escape(b)}</p>' for b in c.banners)
    names = " vs ".join(f.label for f in c.fits)
    return page(f"idtool compare: {names}", _header(c), banners, sec)
