""" "What to measure next" in the HTML report: the planner's (:mod:`idtool._plan`) next
pulls for a goal, when the fit does not meet it yet.

The goal's value now comes first (:func:`~idtool._plan._plan.goal_now`: the linearised
model once, no selection); only when it misses the target does the greedy selection run
(:func:`~idtool._plan._plan.plan_pulls`, as ``idtool plan`` and ``Fit.plan`` run it: the
same grid, draws and seed, so the printed ``idtool plan`` command gives the same pulls).
A met goal is one line under the answer, and so is a fit the planner cannot plan on
(no levels model, one coupling law for the laws goal, an error): the report renders
either way.
"""

from __future__ import annotations

import dataclasses
import html
import shlex
from pathlib import Path

import numpy as np

from idtool._errors import IdtoolError
from idtool._fit._artefact import FitArtefact
from idtool._fit._folder import PLAN_CSV
from idtool._plan._figure import plot_plan
from idtool._plan._options import GoalOptions, meets_target
from idtool._plan._plan import (
    N_CHECK_DRAWS,
    Plan,
    band_half_widths,
    goal_now,
    plan_pulls,
    pull_file_name,
)
from idtool._posterior._draws import fit_draws
from idtool._posterior._store import PosteriorDraws
from idtool._report._page import g, img, table

__all__ = ["NEXT_PULLS", "PLAN_PNG", "NextPulls", "next_pulls"]

NEXT_PULLS = "What to measure next"  # the section's title
PLAN_PNG = "plan.png"  # in figures/
PLAN_DRAWS = 2000  # Fit.plan's default: the same draws, the same check


@dataclasses.dataclass(frozen=True)
class NextPulls:
    """What the report shows of the plan.

    Attributes:
        section: the section's HTML, or None (goal met, or nothing planned).
        note: one line under the answer (goal met, or why nothing was planned), or "".
        markdown: report.md's lines.
        csv: ``plan.csv``'s text (the conditions table), or None.
    """

    section: str | None = None
    note: str = ""
    markdown: tuple[str, ...] = ()
    csv: str | None = None


def _note(text: str) -> NextPulls:
    return NextPulls(note=f'<p class="note">{html.escape(text)}</p>', markdown=(text,))


def next_pulls(
    fit: FitArtefact,
    fit_folder: Path,
    posterior: PosteriorDraws | None,
    options: GoalOptions,
    figures: Path,
) -> NextPulls:
    """The section for ``options``' goal on ``fit`` (read from ``fit_folder``, with its
    stored ``posterior`` or None); the figure is written into ``figures``."""
    words = options.words(list(fit.model.physical_names))
    try:
        now = goal_now(fit, options.goal, at=options.at)
    except IdtoolError as e:
        return _note(f"What to measure next: not planned for this fit: {e}.")
    except Exception as e:  # the report renders whatever the planner meets
        return _note(f"What to measure next: not planned: the planner failed ({_error(e)}).")
    if meets_target(options.goal, now, options.target):
        return _note(f"Goal met: {words} ({g(now)} now); no further pulls needed for it.")
    try:
        plan = plan_pulls(
            fit,
            fit_draws(fit, posterior, PLAN_DRAWS, 0),
            options.goal,
            options.n_pulls,
            at=options.at,
            half_width=options.half_width,
            rel=options.rel,
            weight=options.weight,
        )
        d = fit.model.data
        traces = np.stack([np.asarray(d.normal_load_n), np.asarray(d.amplitude_fraction)], axis=1)
        figure = plot_plan(plan, band_half_widths(fit, plan.candidates), traces, figures / PLAN_PNG)
    except Exception as e:
        return _note(f"What to measure next: not planned: the planner failed ({_error(e)}).")
    command = shlex.join(
        ["idtool", "plan", str(fit_folder), *options.plan_arguments(), "--out", _plans(fit_folder)]
    )
    sentence = _sentence(plan, words)
    rows = [
        [
            p.rank,
            f"{p.normal_load_n:.1f}",
            f"{p.amplitude_fraction:.3f}",
            g(p.pull_speed_m_s),
            g(p.on_time_s),
            pull_file_name(p),
            g(p.value_after),
        ]
        for p in plan.pulls
    ]
    header = ["rank", "load [N]", "amplitude [fraction]", "speed [m/s]", "ON [s]", "save as"]
    header.append(f"{plan.unit} after")
    csv = PLAN_CSV.name
    section = (
        f"<p>{html.escape(sentence)}</p>"
        + table(header, rows)
        + img(figure, "the planned pulls and the goal against the number of pulls")
        + f'<p>The conditions table: <a href="{csv}">{csv}</a>, beside this report '
        "(<code>idtool import --conditions</code> reads it; save each pull under its file "
        "name). Vary the plan (other goals, limits, more pulls) with:</p>"
        f"<pre>{html.escape(command)}</pre>"
        + '<p class="note">'
        + html.escape(_check(plan, posterior is not None))
        + "</p>"
    )
    markdown = (
        f"## {NEXT_PULLS}",
        "",
        sentence,
        "",
        "| rank | load [N] | amplitude | speed [m/s] | ON [s] |",
        "|---|---|---|---|---|",
        *(f"| {r[0]} | {r[1]} | {r[2]} | {r[3]} | {r[4]} |" for r in rows),
        "",
        f"Conditions table: {PLAN_CSV.name}; reproduce: `{command}`",
    )
    return NextPulls(section, "", markdown, plan.to_frame().to_csv(index=False))


def _error(e: Exception) -> str:
    return f"{type(e).__name__}: {e}" if str(e) else type(e).__name__


def _plans(fit_folder: Path) -> str:
    """``plans/NAME`` for the fit folder ``.../NAME``."""
    return f"plans/{Path(fit_folder).name}"


def _sentence(plan: Plan, words: str) -> str:
    """The goal, its value now, after the planned pulls and after a uniform grid of as
    many, and how many planned pulls reach the target."""
    n = len(plan.pulls)
    what, now = plan.unit, g(plan.values[0])
    worst = plan.details.get("relative_sd", {})
    if worst:  # the parameters goal: its value is the largest relative sd
        what = f"largest {plan.unit}"
        now += f" ({max(worst, key=lambda k: worst[k][0])})"
    reach = (
        f"the target is not reached within {n} pulls (plan more with --pulls)"
        if plan.pulls_to_target is None
        else f"the first {plan.pulls_to_target} of them reach the target"
    )
    return (
        f"Goal: {words}. Now the {what} is {now}; after the {n} planned pulls below it is "
        f"expected at {g(plan.values[-1])} (after a uniform grid of {n} pulls: "
        f"{g(plan.uniform[-1])}); {reach}."
    )


def _check(plan: Plan, sampled: bool) -> str:
    """The pseudo-Bayesian check and the approximations, for the note under the plan."""
    b = plan.bayesian
    where = "the posterior" if sampled else "the fit's covariance"
    return (
        f"Averaged over {N_CHECK_DRAWS} parameter draws from {where}, the model "
        f"re-linearised at each: planned {g(b['planned'][0])}, uniform grid "
        f"{g(b['uniform'][0])}. Approximations: " + "; ".join(plan.notes) + "."
    )
