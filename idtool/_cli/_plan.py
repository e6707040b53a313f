"""``idtool plan fits/NAME --goal band --at 670,0.7 --out plans/NAME``: the next pulls."""

from __future__ import annotations

import argparse
import math

from idtool._atomic import atomic_output_dir, refuse_existing
from idtool._errors import IdtoolError
from idtool._plan._options import GOAL_NAMES, GoalOptions

__all__ = ["add_goal_arguments", "goal_options", "register"]


def _range(option: str, text: str | None, hi_max: float = math.inf) -> tuple[float, float] | None:
    """``LOW:HIGH`` (or one value) -> (low, high), or a located error."""
    if text is None:
        return None
    parts = text.split(":")
    try:
        values = [float(p) for p in parts]
    except ValueError:
        raise IdtoolError(f"{option} {text!r}: give LOW:HIGH, e.g. {option} 200:700") from None
    if len(values) == 1:
        values = values * 2
    lo, hi = values[0], values[-1]
    if len(values) != 2 or not (math.isfinite(lo) and math.isfinite(hi) and 0 < lo <= hi <= hi_max):
        bound = "" if math.isinf(hi_max) else f" <= {hi_max:g}"
        raise IdtoolError(f"{option} {text!r}: give LOW:HIGH with 0 < LOW <= HIGH{bound}")
    return lo, hi


def _at(values: list[str] | None) -> list[tuple[float, float]] | None:
    """``--at 670,0.7`` (load [N], amplitude fraction; ``670N,0.7`` too) -> pairs."""
    if not values:
        return None
    out = []
    for text in values:
        parts = [p.strip().removesuffix("N").removesuffix("n") for p in text.split(",")]
        try:
            load, amp = (float(p) for p in parts)
        except ValueError:
            raise IdtoolError(
                f"--at {text!r}: give LOAD,AMPLITUDE (load [N], amplitude fraction), "
                "e.g. --at 670,0.7"
            ) from None
        if not (load > 0 and 0 < amp <= 1):
            raise IdtoolError(
                f"--at {text!r}: the load must be positive [N] and the amplitude a "
                "fraction in (0, 1]"
            )
        out.append((load, amp))
    return out


def _grid(text: str) -> tuple[int, int]:
    try:
        a, b = (int(p) for p in text.lower().split("x"))
    except ValueError:
        raise IdtoolError(f"--grid {text!r}: give LOADSxAMPLITUDES, e.g. 10x10") from None
    if a < 1 or b < 1:
        raise IdtoolError(f"--grid {text!r}: at least 1 level of each")
    return a, b


def goal_options(args: argparse.Namespace) -> GoalOptions:
    """The goal the options of :func:`add_goal_arguments` ask for, checked."""
    return GoalOptions(
        args.goal, args.pulls, tuple(_at(args.at) or ()), args.half_width, args.rel, args.weight
    )


def add_goal_arguments(p: argparse.ArgumentParser, default: str) -> None:
    """The goal's options (``--goal``, ``--at``, ``--half-width``, ``--rel``,
    ``--weight``, ``--pulls``): ``idtool plan``'s and ``idtool report``'s, one
    definition; ``default``: the command's default goal."""
    p.add_argument(
        "--goal",
        choices=GOAL_NAMES,
        default=default,
        help=f"band, laws or parameters (default {default})",
    )
    p.add_argument(
        "--at",
        action="append",
        metavar="LOAD,AMPLITUDE",
        help="band goal: operating point, e.g. 670,0.7 (repeatable)",
    )
    p.add_argument(
        "--half-width",
        type=float,
        default=0.01,
        help="band goal: target half-width of the 95%% FR band (default 0.01)",
    )
    p.add_argument(
        "--rel", type=float, default=0.05, help="parameters goal: target relative sd (default 0.05)"
    )
    p.add_argument(
        "--weight",
        type=float,
        default=0.95,
        help="laws goal: target weight of the true law (default 0.95)",
    )
    p.add_argument("--pulls", type=int, default=10, help="pulls to plan (default 10)")


def _run(args: argparse.Namespace) -> int:
    import numpy as np

    from idtool._levels._store import is_levels_fit

    if is_levels_fit(args.fit):
        return _run_levels(args)
    # the options are checked before the fit is read
    loads = _range("--loads", args.loads)
    amps = _range("--amplitudes", args.amplitudes, 1.0)
    goal = goal_options(args)
    grid = _grid(args.grid)
    refuse_existing(args.out, args.force)
    import idtool
    from idtool._plan._linear import Points
    from idtool._plan._plan import band_half_widths, plan_text, write_plan

    fit = idtool.load_fit(args.fit)
    plan = fit.plan(
        goal.goal,
        goal.n_pulls,
        at=goal.at or None,
        half_width=goal.half_width,
        next_pull=args.next_pull,
        rel=goal.rel,
        weight=goal.weight,
        loads_n=loads,
        amplitudes=amps,
        speeds_m_s=args.speeds,
        on_time_s=args.on_time,
        grid=grid,
        max_draws=args.draws,
        seed=args.seed,
    )
    c = plan.candidates
    band_map = band_half_widths(
        fit.artefact,
        Points(c.normal_load_n, c.amplitude_fraction, c.pull_speed_m_s),
        seed=args.seed,
    )
    d = fit.model.data
    traces = np.stack([np.asarray(d.normal_load_n), np.asarray(d.amplitude_fraction)], axis=1)
    with atomic_output_dir(args.out, force=args.force) as tmp:
        write_plan(plan, tmp, band_map, traces)
    print(plan_text(plan))
    print(
        f"wrote {args.out}/plan.csv (idtool import --conditions reads it), plan.txt, "
        "plan.json, plan.png"
    )
    return 0


def _run_levels(args: argparse.Namespace) -> int:
    """``idtool plan`` on a friction table's fit: the next rows
    (:meth:`idtool.LevelsFit.plan`); the targets ``--at LOAD,AMPLITUDE`` (amplitude as a
    fraction of the table's reference amplitude) at each of ``--speeds`` (default the
    table's speeds)."""
    import json

    from idtool._levels._store import load_levels_fit

    if args.goal == "laws":
        raise IdtoolError(
            f"{args.fit} is the fit of a friction table: --goal laws plans pulls of bench "
            "traces; on a table use --goal band or parameters (and compare the coupling "
            "laws with idtool fit --coupling auto)"
        )
    for flag, given in (("--next-pull", args.next_pull), ("--on-time", args.on_time)):
        if given:
            raise IdtoolError(f"{flag} applies to bench traces, not to a friction table")
    loads = _range("--loads", args.loads)
    amps = _range("--amplitudes", args.amplitudes)
    goal = goal_options(args)
    grid = max(_grid(args.grid))
    refuse_existing(args.out, args.force)
    fit = load_levels_fit(args.fit)
    t = fit.table
    ref = t.reference_amplitude_m
    speeds = sorted(set(args.speeds)) if args.speeds else sorted(set(t.sliding_speed_m_s))
    at = [(n, a * ref, v) for n, a in goal.at for v in speeds] or None
    plan = fit.plan(
        goal.goal,
        goal.n_pulls,
        at=at,
        half_width=goal.half_width,
        rel=goal.rel,
        loads_n=loads,
        amplitudes_m=None if amps is None else (amps[0] * ref, amps[1] * ref),
        speeds_m_s=(min(speeds), max(speeds)) if args.speeds else None,
        grid=grid,
    )
    text = plan.report()
    doc = {
        "kind": "levels",
        "goal": plan.goal,
        "unit": plan.unit,
        "target": plan.target,
        "values": list(plan.values),
        "uniform": list(plan.uniform),
        "rows_to_target": plan.rows_to_target,
        "at": [list(x) for x in plan.at],
        "rows": [vars(r) for r in plan.rows],
        "notes": list(plan.notes),
        "fit": str(args.fit),
    }
    with atomic_output_dir(args.out, force=args.force) as tmp:
        (tmp / "plan.csv").write_text(plan.to_csv(t.friction))
        (tmp / "plan.txt").write_text(text + "\n")
        (tmp / "plan.json").write_text(json.dumps(doc, indent=1) + "\n")
    print(text)
    print(
        f"wrote {args.out}/plan.csv (fill in OFF and ON; idtool import-levels reads it), "
        "plan.txt, plan.json"
    )
    return 0


def register(sub: argparse._SubParsersAction) -> None:
    from idtool._cli._args import number_list

    p = sub.add_parser(
        "plan",
        help="the next pulls for a goal: a narrower band, the coupling laws told apart, "
        "or the parameters to a precision",
        description="Propose the next pulls from a fit's linearised levels model (its "
        "covariance, scatter and discrepancy; checked over the posterior if sampled): "
        "ranked, each with the goal's expected value after it, beside a uniform grid of "
        "the same size. Writes plan.csv (the conditions table 'idtool import "
        "--conditions' reads), plan.txt, plan.json and plan.png into --out.",
    )
    p.add_argument("fit", help="fit folder, e.g. fits/NAME")
    p.add_argument("--out", required=True, help="output folder, e.g. plans/NAME")
    add_goal_arguments(p, "band")
    p.add_argument(
        "--next-pull",
        action="store_true",
        help="band goal: the next pull's band (scatter added), not the mean FR's",
    )
    p.add_argument("--loads", help="load limits LOW:HIGH [N] (default: the tested range)")
    p.add_argument(
        "--amplitudes",
        help="amplitude limits LOW:HIGH (default: the tested range; --goal laws: 0.1:1)",
    )
    p.add_argument("--speeds", type=number_list, help="pull speeds [m/s] (default: the fit's)")
    p.add_argument("--on-time", type=float, help="ON time [s] (default: the most common)")
    p.add_argument("--grid", default="10x10", help="candidate levels LOADSxAMPLITUDES (10x10)")
    p.add_argument("--draws", type=int, default=2000, help="draws for the check (default 2000)")
    p.add_argument("--seed", type=int, default=0, help="seed of every random choice")
    p.add_argument("--force", action="store_true", help="replace --out if it exists")
    p.set_defaults(func=_run)
