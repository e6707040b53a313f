"""The report's first section: the answer a qualification asks for.

1. The friction ratio FR and the reduction ``100 (1 - FR)`` % at every tested load x
   tested amplitude (the dataset's own values, crossed: a cell the design did not run
   is marked), with the 95% band of the mean curve and the 95% band of a next single
   pull (:func:`~idtool._predict._predict.predict_friction_ratio`); beside it what the
   traces themselves measured there (their own friction ratios, fitted trace by trace).
2. The commanded amplitude needed for each target reduction at the tested loads (and
   any loads asked for), with its band or why it is out of reach
   (:func:`~idtool._predict._predict.amplitude_for_reduction`).

Both come with their extrapolation notes (loads asked beyond the tested range, needed
amplitudes beyond the tested amplitudes), which the report raises as banners.
"""

from __future__ import annotations

import dataclasses
import html
import math
from collections.abc import Sequence

import numpy as np

from idtool._diagnostic import reworded
from idtool._fit._artefact import FitArtefact
from idtool._fit._summary import TraceFit
from idtool._predict._amplitude import AmplitudeFor
from idtool._predict._predict import Draws
from idtool._predict._tables import amplitude_table, predict_table
from idtool._report._page import table

__all__ = ["Answer", "answer"]


@dataclasses.dataclass(frozen=True)
class Answer:
    """The answer section: its HTML, its markdown lines and its extrapolation notes."""

    html: str
    markdown: list[str]
    extrapolation: list[str]


def _band(lo: float, hi: float, fmt: str) -> str:
    return f"[{lo:{fmt}}, {hi:{fmt}}]"


def _measured(traces: Sequence[TraceFit], load: float, amp: float, speed: float) -> tuple[int, str]:
    """Traces run at this operating point, and the mean of their own friction ratios
    (with the range over traces when several)."""
    own = [
        t.free_friction_ratio
        for t in traces
        if math.isclose(t.normal_load_n, load)
        and math.isclose(t.amplitude_fraction, amp)
        and math.isclose(t.pull_speed_m_s, speed)
    ]
    values = [v for v in own if v is not None]
    if not own:
        return 0, "not tested"
    if not values:
        return len(own), "-"
    text = f"{np.mean(values):.3f}"
    if len(values) > 1:
        text += f" ({min(values):.3f}-{max(values):.3f})"
    return len(own), text


def _amplitude_cell(a: AmplitudeFor, max_amplitude_um: float, tested: tuple[float, float]) -> str:
    """The needed amplitude as percent of the maximum [95%] and in micrometres, marked
    when it lies outside the tested amplitudes ``tested`` (fractions)."""
    med, lo, hi = a.amplitude
    rmed, rlo, rhi = a.max_reduction_percent
    if not a.reachable:
        return f"out of reach: full amplitude gives {rmed:.0f}% [{rlo:.0f}, {rhi:.0f}]"
    upper = f"{100 * hi:.0f}" if math.isfinite(hi) else "out of reach"
    text = f"{100 * med:.0f}% [{100 * lo:.0f}, {upper}] = {med * max_amplitude_um:.0f} um"
    if not math.isfinite(hi):
        text += f" (reachable in {100 * a.probability_reachable:.0f}%)"
    if not tested[0] <= med <= tested[1]:
        text += " (extrapolated)"
    return text


def answer(
    fit: FitArtefact,
    draws: Draws,
    targets: Sequence[float],
    loads_n: Sequence[float] = (),
) -> Answer:
    """The answer section for ``fit`` from prediction ``draws``: FR at the tested
    operating points and the amplitude for each of ``targets`` [% reduction] at the
    tested loads plus ``loads_n`` [N]."""
    data = fit.model.data
    loads = sorted(set(np.asarray(data.normal_load_n).tolist()))
    amps = sorted(a for a in set(np.asarray(data.amplitude_fraction).tolist()) if a > 0)
    speeds = sorted(set(np.asarray(data.pull_speed_m_s).tolist()))
    max_um = fit.dataset.rig.max_amplitude_m * 1e6
    notes: list[str] = []

    preds = predict_table(draws, data, loads, amps, speeds)
    rows, md = [], ["## Answer", ""]
    md += ["| load [N] | amplitude | FR median [95%] | reduction % [95%] | next pull FR 95% |"]
    md += ["|---|---|---|---|---|"]
    for p in preds:
        red, (rlo, rhi) = p.reduction_percent
        _, (nlo, nhi) = p.new_trace or (p.median, p.ci95)
        n_traces, measured = _measured(
            fit.summary.traces, p.normal_load_n, p.amplitude_fraction, p.pull_speed_m_s
        )
        amp = f"{100 * p.amplitude_fraction:.0f}% ({p.amplitude_fraction * max_um:.0f} um)"
        row: list[object] = [f"{p.normal_load_n:g}", amp]
        row += [f"{p.pull_speed_m_s * 1e3:g}"] if len(speeds) > 1 else []
        row += [
            n_traces,
            measured,
            f"{p.median:.3f} {_band(*p.ci95, '.3f')}",
            f"{red:.1f} {_band(rlo, rhi, '.1f')}",
            _band(nlo, nhi, ".3f"),
        ]
        rows.append(row)
        md.append(f"| {row[0]} | {amp} | {row[-3]} | {row[-2]} | {row[-1]} |")
    header = ["load [N]", "amplitude (of max)"]
    header += ["speed [mm/s]"] if len(speeds) > 1 else []
    header += [
        "traces",
        "measured FR (traces' own)",
        "FR median [95%]",
        "reduction % [95%]",
        "next pull FR [95%]",
    ]
    html_out = (
        "<p>Friction ratio FR = pull force with ultrasound / without, and the reduction "
        "100 (1 - FR) %, at the tested loads and amplitudes. <b>FR [95%]</b>: the mean "
        "over many pulls (use it for design curves); <b>next pull</b>: what one more pull "
        "will give (use it for acceptance limits).</p>" + table(header, rows)
    )

    amp_loads = sorted(set(loads) | {float(x) for x in loads_n})
    several = len(speeds) > 1
    header = ["load [N]"] + (["speed [mm/s]"] if several else [])
    header += [f"amplitude for {t:g}% reduction [95%]" for t in targets]
    cells: dict[tuple[float, float], list[str]] = {
        (n, s): [f"{n:g}" + ("" if loads[0] <= n <= loads[-1] else " (extrapolated)")]
        + ([f"{s * 1e3:g}"] if several else [])
        for n in amp_loads
        for s in speeds
    }
    for target in targets:
        amp_rows = amplitude_table(draws, data, target, amp_loads, speeds)
        named = (
            reworded(
                n,
                n.replace(
                    "needed amplitude fraction", f"amplitude fraction for {target:g}% reduction,"
                ),
            )
            for n in amp_rows.warnings
        )
        notes += [n for n in named if n not in notes]
        for a in amp_rows:
            cell = _amplitude_cell(a, max_um, (amps[0], amps[-1]))
            cells[(a.normal_load_n, a.pull_speed_m_s)].append(cell)
    md += ["", "| " + " | ".join(header) + " |", "|---" * len(header) + "|"]
    md += ["| " + " | ".join(c) + " |" for c in cells.values()]
    per_load = list(cells.values())
    html_out += (
        "<p>Commanded amplitude (percent of the horn's maximum, and in micrometres) "
        "needed for each target reduction of the mean friction ratio:</p>"
        + table(header, per_load)
        + f'<p class="note">From {html.escape(draws.note)}.</p>'
    )
    notes += [n for n in preds.warnings if n not in notes]
    return Answer(html_out, md, notes)
