"""The held-out validation in the HTML report: ``validation.json`` (written by ``idtool
validate-fit``) as a table, and a banner when the held-out traces miss their bands
more often than chance explains."""

from __future__ import annotations

import html
from pathlib import Path

from idtool._fit._folder import VALIDATION_JSON
from idtool._report._page import g, table

__all__ = ["validation_banner", "validation_section"]


def validation_banner(folder: Path) -> str:
    """A banner when held-out traces fall outside their 95% bands more often than
    chance explains: fewer inside than the 2.5% quantile of Binomial(n, 0.95)."""
    if not (folder / VALIDATION_JSON.name).is_file():
        return ""
    v = VALIDATION_JSON.read_json(folder)
    inside = [t["inside"] for t in v["traces"] if t["inside"] is not None]
    n, k = len(inside), sum(inside)
    # P(at most k inside | n, 0.95): a lower tail under 2.5% is more than bad luck
    from scipy.stats import binom

    if n == 0 or binom.cdf(k, n, 0.95) >= 0.025:
        return ""
    text = (
        f"Held-out validation: only {k} of {n} held-out traces lie inside their 95% "
        "bands (chance alone would do this less than 2.5% of the time): the bands are "
        "too narrow for this bench; see 'Held-out validation'."
    )
    return f'<p class="banner">{html.escape(text)}</p>'


def validation_section(folder: Path) -> str:
    """``validation.json`` (``idtool validate-fit``) as a table, or what to run."""
    if not (folder / VALIDATION_JSON.name).is_file():
        return (
            "<p>No held-out validation yet: fit some traces (idtool fit --traces) and run "
            "idtool validate-fit on the others, or on another session's dataset.</p>"
        )
    v = VALIDATION_JSON.read_json(folder)
    rows = []
    for t in v["traces"]:
        own = t["friction_ratio"]
        meas = t["measured_ci95"]
        rows.append(
            [
                t["id"],
                g(t["normal_load_n"]),
                f"{100 * t['amplitude_fraction']:.0f}%",
                f"{t['fit_percent']:.1f}",
                f"{t['rmse_n']:.3f}",
                "-" if own is None else f"{own:.3f} ({t['friction_ratio_se']:.3f})",
                "-" if meas is None else f"[{meas[0]:.3f}, {meas[1]:.3f}]",
                {None: "-", True: "yes", False: "NO"}[t["inside"]],
            ]
        )
    notes = "".join(f"<li>{html.escape(w)}</li>" for w in v.get("warnings", []))
    return (
        f"<p>{html.escape(v['summary'])}. Dataset {html.escape(v['dataset'])} (sha256 "
        f"<code>{v['dataset_sha256'][:12]}</code>); bands from {html.escape(v['draws'])}. "
        "Force fit %: 100 (1 - |y - y_hat| / |y - mean y|) with only the trace's own "
        "nuisances fitted; the band: a new pull's FR as this trace measures it (its own "
        "estimation error added).</p>"
        + table(
            [
                "trace",
                "load [N]",
                "amplitude",
                "force fit [%]",
                "RMSE [N]",
                "own FR (se)",
                "95% band as measured",
                "inside",
            ],
            rows,
        )
        + (f"<ul>{notes}</ul>" if notes else "")
    )
