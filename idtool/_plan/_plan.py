"""``Fit.plan``: the next pulls for a goal, from the fit's linearised levels model.

The candidates are a grid of loads x amplitudes (x speeds) within the limits (default:
the range the dataset tested); the goals and their values are
:mod:`idtool._plan._goals`', the linear-Gaussian model :mod:`idtool._plan._linear`'s,
the batch :mod:`idtool._plan._select`'s greedy one, compared with a uniform grid of the
same size. Then the pseudo-Bayesian check: the plan's value averaged over draws of the
physical parameters (the posterior's when the fit has one, else Gaussian on the fit's
covariance), the model re-linearised at each (Chaloner & Verdinelli 1995, Statist. Sci.
10, §2.3: "local" designs against the expectation over the prior). Every random choice
(the sd draws, the parameter draws) takes ``seed``: same seed, same plan.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence

import numpy as np

from idtool._errors import IdtoolError
from idtool._fit._artefact import FitArtefact, LawFit
from idtool._plan._goals import GOALS, law_values, parameter_values
from idtool._plan._linear import LinearLaw, Points, linear_law
from idtool._plan._options import meets_target
from idtool._plan._select import goal_value, greedy, uniform_batch, value_after
from idtool._predict._predict import Draws

__all__ = [
    "Plan",
    "PlannedPull",
    "band_half_widths",
    "goal_now",
    "plan_pulls",
    "pull_file_name",
    "write_plan",
]

N_SD_DRAWS = 32  # draws of the sds the linearised model averages over
N_CHECK_DRAWS = 12  # parameter draws of the pseudo-Bayesian check


@dataclasses.dataclass(frozen=True)
class PlannedPull:
    """One proposed pull: its operating point, ON time [s], and the goal's expected
    value once it (and the pulls ranked before it) is added."""

    rank: int
    normal_load_n: float
    amplitude_fraction: float
    pull_speed_m_s: float
    on_time_s: float
    value_after: float


@dataclasses.dataclass(frozen=True)
class Plan:
    """The proposed next pulls for a goal (:func:`plan_pulls`).

    Attributes:
        goal: ``band``, ``laws`` or ``parameters``.
        unit: what the goal's value measures (``FR half-width``, ``relative sd``,
            ``expected weight of the true law``).
        target: the goal's target value (half-width [FR], relative sd, weight).
        pulls: the proposed pulls, ranked (:class:`PlannedPull`).
        values: the goal's expected value after 0, 1, ... N of them (linearised).
        uniform: the same for a uniform grid of each size 0..N (:func:`~idtool._plan.
            _select.uniform_batch`; re-chosen for each size).
        bayesian: the planned batch's value after all N averaged over parameter draws
            (mean, sd over the draws), the model re-linearised at each; and the
            uniform grid's.
        pulls_to_target: how many planned pulls reach the target (None: not within N).
        candidates: the candidate grid (loads [N], amplitudes, speeds [m/s]) and the
            goal's value after each single pull (the first step's ranking).
        at: the band goal's target operating points (load [N], amplitude, speed [m/s]).
        notes: the approximations taken and what the fit had.
    """

    goal: str
    unit: str
    target: float
    pulls: tuple[PlannedPull, ...]
    values: tuple[float, ...]
    uniform: tuple[float, ...]
    bayesian: dict[str, tuple[float, float]]
    pulls_to_target: int | None
    candidates: Points
    candidate_values: np.ndarray
    at: tuple[tuple[float, float, float], ...]
    notes: tuple[str, ...]
    grid_shape: tuple[int, int, int]
    details: dict = dataclasses.field(default_factory=dict)
    # the uniform grid of N pulls the plan is compared with (what idtool study --uniform
    # simulates), value_after: the grid of that size's value (re-chosen for each size)
    uniform_pulls: tuple[PlannedPull, ...] = ()

    @property
    def met(self) -> bool:
        """Whether the goal's value now already meets its target."""
        return meets_target(self.goal, self.values[0], self.target)

    def to_frame(self):
        """The conditions table (pandas): the columns ``idtool import --conditions``
        reads (file, load, amplitude, speed, notes) and the rank, ON time [s] and the
        goal's expected value after the pull."""
        import pandas as pd

        return pd.DataFrame([_row(p, self) for p in self.pulls])


def _row(p: PlannedPull, plan: Plan) -> dict:
    return {
        "file": pull_file_name(p),
        "load [N]": round(p.normal_load_n, 3),
        "amplitude [fraction]": round(p.amplitude_fraction, 4),
        "speed [m/s]": round(p.pull_speed_m_s, 6),
        "notes": f"rank {p.rank}; ON {p.on_time_s:g} s; expected {plan.goal} {p.value_after:.4g}",
    }


def pull_file_name(p: PlannedPull) -> str:
    """The file name the operator saves the pull under: the planned row's ``file``."""
    return (
        f"plan{p.rank:03d}_N{p.normal_load_n:.0f}_A{100 * p.amplitude_fraction:.0f}"
        f"_T{p.on_time_s:g}.csv"
    )


# The laws goal's default candidate amplitudes (fractions of the rig's maximum): the
# horn's commanded range rather than the tested one (:func:`plan_pulls`).
LAWS_AMPLITUDES = (0.1, 1.0)


def amplitude_limits(
    goal: str, given: tuple[float, float] | None, tested: np.ndarray
) -> tuple[float, float]:
    """The candidates' amplitude limits (fractions): ``given``, else the ``tested``
    range, or for the laws goal :data:`LAWS_AMPLITUDES`."""
    if given is None and goal == "laws":
        # the coupling laws part at the amplitudes a bench leaves untested (the power
        # limit's knee at small ones), and every commanded fraction is one the horn can
        # give: a simulated scatter bench (benchmarks/study_plan.py) planned 0.80 within
        # the tested 0.5-0.7, 0.998 within 0.1-1
        given = LAWS_AMPLITUDES
    return _limits(given, tested, "--amplitudes")


def _limits(given: tuple[float, float] | None, seen: np.ndarray, name: str) -> tuple[float, float]:
    lo, hi = (float(np.min(seen)), float(np.max(seen))) if given is None else given
    if not (math.isfinite(lo) and math.isfinite(hi) and 0.0 < lo <= hi):
        raise IdtoolError(f"{name} {lo:g}:{hi:g}: give LOW:HIGH with 0 < LOW <= HIGH")
    return lo, hi


def _on_time(law: LawFit, on_time_s: float | None) -> float:
    """The planned ON time [s]: given, else the most common of the measured traces'."""
    if on_time_s is not None:
        return float(on_time_s)
    d = law.model.data
    assert law.levels is not None
    meas = law.levels[0].measured
    length = (np.asarray(d.on_end_s) - np.asarray(d.on_start_s))[meas]
    values, counts = np.unique(np.round(length, 2), return_counts=True)
    return float(values[np.argmax(counts)])


def _laws(fit: FitArtefact, goal: str) -> list[tuple[str, float, LawFit]]:
    """(name, weight, LawFit) of the coupling laws the plan uses: every law the fit kept
    (weights renormalised over them), or only the chosen one for ``parameters``."""
    chosen = fit.chosen
    out = [(fit.chosen_label, fit.chosen_weight, chosen)]
    if goal != "parameters":
        out += [(name, w, law) for name, (w, law) in fit.alternates.items()]
    total = sum(w for _, w, _ in out)
    return [(n, w / total, law) for n, w, law in out]


def _checked_laws(fit: FitArtefact, goal: str) -> list[tuple[str, float, LawFit]]:
    """:func:`_laws`, once the fit is checked to support ``goal``."""
    if goal not in GOALS:
        raise IdtoolError(f"goal {goal!r}: choose one of {', '.join(GOALS)}")
    if fit.chosen.levels is None:
        raise IdtoolError(
            "the fit has no levels model (fitted with variability off, or its scatter and "
            "discrepancy could not be estimated: see the fit's warnings)"
        )
    laws_used = _laws(fit, goal)
    if goal == "laws" and len(laws_used) < 2:
        raise IdtoolError(
            "--goal laws needs a fit that kept several coupling laws: fit with "
            "--coupling auto (the fit kept one)"
        )
    return laws_used


def _targets(
    fit: FitArtefact, goal: str, at: Sequence[tuple[float, float]] | None, unused: Points
) -> Points:
    """The band goal's target operating points (at the fit's median speed); ``unused``
    for the other goals (it keeps the shapes)."""
    if goal != "band":
        return unused
    if not at:
        raise IdtoolError("--goal band needs --at LOAD,AMPLITUDE (e.g. --at 670,0.7)")
    speed0 = float(np.median(np.asarray(fit.chosen.model.data.pull_speed_m_s)))
    return Points(
        np.array([float(n) for n, _ in at]),
        np.array([float(a) for _, a in at]),
        np.full(len(at), speed0),
    )


def goal_now(
    fit: FitArtefact,
    goal: str = "parameters",
    *,
    at: Sequence[tuple[float, float]] | None = None,
    next_pull: bool = False,
    seed: int = 0,
) -> float:
    """The goal's value today (:func:`plan_pulls`' ``values[0]``, the same sd draws and
    model) without planning: the linearised model with one candidate pull instead of the
    grid, and no greedy selection. What the report checks before it plans."""
    laws_used = _checked_laws(fit, goal)
    d = fit.chosen.model.data
    one = Points(
        np.asarray(d.normal_load_n, float)[:1],
        np.asarray(d.amplitude_fraction, float)[:1],
        np.asarray(d.pull_speed_m_s, float)[:1],
    )
    targets = _targets(fit, goal, at, one)
    n_sd = 1 if goal == "laws" else N_SD_DRAWS
    linear = [
        linear_law(
            name,
            w,
            law,
            one,
            targets,
            n_sd,
            seed,
            sds=_estimated_sds(law) if goal == "laws" else None,
        )
        for name, w, law in laws_used
    ]
    return goal_value(goal, linear, next_pull, [])


def plan_pulls(
    fit: FitArtefact,
    draws: Draws,
    goal: str = "band",
    n_pulls: int = 10,
    *,
    at: Sequence[tuple[float, float]] | None = None,
    half_width: float = 0.01,
    next_pull: bool = False,
    rel: float = 0.05,
    weight: float = 0.95,
    loads_n: tuple[float, float] | None = None,
    amplitudes: tuple[float, float] | None = None,
    speeds_m_s: Sequence[float] | None = None,
    on_time_s: float | None = None,
    grid: tuple[int, int] = (10, 10),
    seed: int = 0,
) -> Plan:
    """The next ``n_pulls`` pulls for ``goal`` (module docstring) on ``fit``, with
    ``draws`` of its physical parameters for the pseudo-Bayesian check.

    Args:
        goal: ``band`` (half-width ``half_width`` [FR] of the mean FR's band, or of the
            next pull's with ``next_pull``, at the operating points ``at``: (load [N],
            amplitude fraction) pairs at the fit's speed), ``laws`` (each law's
            expected weight if true at least ``weight``) or ``parameters`` (every
            physical parameter's relative sd at most ``rel``).
        loads_n, amplitudes: (low, high) limits of the candidates (default: the
            dataset's tested range; for ``laws`` the amplitudes
            :data:`LAWS_AMPLITUDES`, the horn's commanded range); ``speeds_m_s`` the
            candidate speeds (default the fit's); ``grid``: levels of load and of
            amplitude.
        on_time_s: the pulls' ON time [s] (default: the measured traces' most common).
    """
    if n_pulls < 1:
        raise IdtoolError(f"{n_pulls} pulls: plan at least 1")
    laws_used = _checked_laws(fit, goal)
    chosen = fit.chosen
    data = chosen.model.data
    lo_n, hi_n = _limits(loads_n, np.asarray(data.normal_load_n), "--loads")
    lo_a, hi_a = amplitude_limits(goal, amplitudes, np.asarray(data.amplitude_fraction))
    if hi_a > 1.0:
        raise IdtoolError(f"--amplitudes {lo_a:g}:{hi_a:g}: amplitudes are fractions in (0, 1]")
    speeds = np.unique(np.asarray(data.pull_speed_m_s)) if speeds_m_s is None else speeds_m_s
    speeds = np.asarray(speeds, float)
    if np.any(speeds <= 0.0):
        raise IdtoolError("--speeds: give positive speeds [m/s]")
    n_l, n_a = (1 if lo_n == hi_n else grid[0]), (1 if lo_a == hi_a else grid[1])
    loads = np.linspace(lo_n, hi_n, n_l)
    amps = np.linspace(lo_a, hi_a, n_a)
    mesh = np.array([(n, a, s) for n in loads for a in amps for s in speeds], float)
    cands = Points(mesh[:, 0], mesh[:, 1], mesh[:, 2])
    targets = _targets(fit, goal, at, Points(loads[:1], amps[:1], speeds[:1]))
    on_s = _on_time(chosen, on_time_s)
    n_sd = 1 if goal == "laws" else N_SD_DRAWS
    linear = [
        linear_law(
            name,
            w,
            law,
            cands,
            targets,
            n_sd,
            seed,
            on_s,
            sds=_estimated_sds(law) if goal == "laws" else None,
        )
        for name, w, law in laws_used
    ]
    batch, values, first = greedy(goal, linear, n_pulls, next_pull)
    uniform = [values[0]]
    for n in range(1, n_pulls + 1):
        uniform.append(value_after(goal, linear, _uniform(n, n_l, n_a, speeds.size), next_pull)[-1])
    target = {"band": half_width, "parameters": rel, "laws": weight}[goal]
    reach = next((i for i, v in enumerate(values) if meets_target(goal, v, target)), None)
    pulls = tuple(
        PlannedPull(
            i + 1, float(mesh[c, 0]), float(mesh[c, 1]), float(mesh[c, 2]), on_s, values[i + 1]
        )
        for i, c in enumerate(batch)
    )
    bayes = _bayesian(
        goal,
        laws_used,
        linear,
        cands,
        targets,
        draws,
        batch,
        _uniform(n_pulls, n_l, n_a, speeds.size),
        next_pull,
        on_s,
        seed,
    )
    details = _details(goal, linear, batch)
    uniform_pulls = tuple(
        PlannedPull(
            i + 1, float(mesh[c, 0]), float(mesh[c, 1]), float(mesh[c, 2]), on_s, uniform[-1]
        )
        for i, c in enumerate(_uniform(n_pulls, n_l, n_a, speeds.size))
    )
    notes = (
        "linearised levels model (universal kriging) about the fit's estimate; the sds "
        f"drawn {n_sd} times from the fit's grids",
        f"a new pull's level noise: the measured traces' median (2, 2) block (ON {on_s:g} s), "
        "moved to the pull by the ratios of its OFF and ON levels (the load cell's noise is "
        "absolute); the shared bench parameters' part left out",
    )
    return Plan(
        goal=goal,
        unit={
            "band": "FR half-width",
            "parameters": "relative sd",
            "laws": "expected weight of the true law",
        }[goal],
        target=float(target),
        pulls=pulls,
        values=tuple(values),
        uniform=tuple(uniform),
        bayesian=bayes,
        pulls_to_target=reach,
        candidates=cands,
        candidate_values=first,
        at=tuple(
            zip(
                targets.normal_load_n,
                targets.amplitude_fraction,
                targets.pull_speed_m_s,
                strict=True,
            )
        )
        if goal == "band"
        else (),
        notes=notes,
        grid_shape=(n_l, n_a, speeds.size),
        details=details,
        uniform_pulls=uniform_pulls,
    )


def _uniform(n: int, n_l: int, n_a: int, n_s: int) -> list[int]:
    """The uniform grid of ``n`` pulls as candidate indices (at the first speed)."""
    return [c * n_s for c in uniform_batch(n_l, n_a, n)]


def _estimated_sds(law: LawFit) -> np.ndarray:
    """The fit's sd estimates as one sd draw (1, 3)."""
    assert law.levels is not None
    sds = law.levels[1]
    names = ("scatter_mu", "scatter_fr", "discrepancy_fr")
    return np.array([[sds.get(n, (0.0,))[0] for n in names]])


def _details(goal: str, linear: list[LinearLaw], batch: list[int]) -> dict:
    """What the report shows beyond the value: per parameter its relative sd now and
    after the plan; per law its expected weight if true."""
    if goal == "parameters":
        law = linear[0]
        names = law.model.physical_names
        work = law.copy()
        now = parameter_values(work, after=False)[1][0]
        for c in batch:
            work.add(c)
        after = parameter_values(work, after=False)[1][0]
        return {
            "relative_sd": {
                n: (float(a), float(b)) for n, a, b in zip(names, now, after, strict=True)
            }
        }
    if goal == "laws":
        after = law_values(linear, batch)
        return {
            "weight_if_true": {
                law.name: (law.weight, float(a)) for law, a in zip(linear, after, strict=True)
            }
        }
    return {}


def _bayesian(
    goal, laws_used, linear, cands, targets, draws, batch, uniform, next_pull, on_s, seed
):
    """The planned and the uniform batch's value after all their pulls, averaged over
    :data:`N_CHECK_DRAWS` draws of the chosen law's physical parameters (the model
    re-linearised at each; the other laws at their estimates): (mean, sd)."""
    k = laws_used[0][2].model.n_physical
    params = laws_used[0][2].model.shared_params[:k]
    n = draws.n
    idx = np.random.default_rng([seed, 11]).choice(n, size=min(N_CHECK_DRAWS, n), replace=False)
    out: dict[str, list[float]] = {"planned": [], "uniform": []}
    for i in idx:
        theta = np.array([p.internal(float(draws.values[p.name][i])) for p in params])
        name, w, law = laws_used[0]
        sds = linear[0].sds
        first = linear_law(
            name, w, law, cands, targets, sds.shape[0], seed, on_s, theta=theta, sds=sds
        )
        work = [first, *linear[1:]]
        out["planned"].append(value_after(goal, work, batch, next_pull)[-1])
        out["uniform"].append(value_after(goal, work, uniform, next_pull)[-1])
    return {key: (float(np.mean(v)), float(np.std(v))) for key, v in out.items()}


def band_half_widths(
    fit: FitArtefact, points: Points, next_pull: bool = False, seed: int = 0
) -> np.ndarray:
    """Today's 95% band half-width [FR] at ``points`` on the linearised model (eq. P3 of
    :mod:`idtool._plan._linear`, the mixture B1 of :mod:`idtool._plan._band` over the
    coupling laws the fit kept and the sd draws): what :meth:`Fit.predict`'s band is
    checked against (tests/test_plan.py)."""
    from idtool._plan._goals import band_values

    laws = _laws(fit, "band")
    linear = [
        linear_law(
            name,
            w,
            law,
            Points(
                points.normal_load_n[:1], points.amplitude_fraction[:1], points.pull_speed_m_s[:1]
            ),
            points,
            N_SD_DRAWS,
            seed,
        )
        for name, w, law in laws
    ]
    out = np.empty(len(points))
    for t in range(len(points)):
        one = [
            dataclasses.replace(
                law,
                target_rows=law.target_rows[t : t + 1],
                target_log_fr=law.target_log_fr[t : t + 1],
            )
            for law in linear
        ]
        out[t] = band_values(one, next_pull, after=False)[0]
    return out


def plan_text(plan: Plan) -> str:
    """The plan for a person: the pulls, the goal's value now and after, the uniform
    grid's, the pseudo-Bayesian check, and (goal unmet) what to measure next."""
    lines = [f"goal: {plan.goal} ({plan.unit}); target {plan.target:g}"]
    if plan.at:
        lines.append(
            "at: " + "; ".join(f"{n:g} N, amplitude {a:g}, {s:g} m/s" for n, a, s in plan.at)
        )
    lines.append(f"now: {plan.values[0]:.4g}" + (" (met)" if plan.met else " (unmet)"))
    lines.append(
        f"after the {len(plan.pulls)} planned pulls: {plan.values[-1]:.4g}; "
        f"a uniform grid of {len(plan.pulls)}: {plan.uniform[-1]:.4g}"
    )
    b = plan.bayesian
    lines.append(
        f"averaged over {N_CHECK_DRAWS} parameter draws (re-linearised): planned "
        f"{b['planned'][0]:.4g} (sd {b['planned'][1]:.2g}), uniform {b['uniform'][0]:.4g} "
        f"(sd {b['uniform'][1]:.2g})"
    )
    if plan.pulls_to_target is None:
        lines.append(f"the target is not reached within {len(plan.pulls)} pulls: plan more")
    else:
        lines.append(f"pulls to reach the target: {plan.pulls_to_target}")
    for name, (now, after) in plan.details.get("relative_sd", {}).items():
        lines.append(f"  {name}: relative sd {now:.3g} -> {after:.3g}")
    for name, (now, after) in plan.details.get("weight_if_true", {}).items():
        lines.append(f"  {name}: weight if true {now:.3g} -> {after:.3g}")
    if not plan.met:
        lines.append("what to measure next (ranked):")
    lines.append(
        f"{'rank':>4s} {'load [N]':>9s} {'amplitude':>9s} {'speed':>8s} {'ON [s]':>6s}  after"
    )
    for p in plan.pulls:
        lines.append(
            f"{p.rank:4d} {p.normal_load_n:9.1f} {p.amplitude_fraction:9.3f} "
            f"{p.pull_speed_m_s:8.4g} {p.on_time_s:6.3g}  {p.value_after:.4g}"
        )
    lines += [f"note: {n}" for n in plan.notes]
    return "\n".join(lines)


def write_plan(plan: Plan, folder, band_map: np.ndarray, traces: np.ndarray) -> None:
    """Write ``plan.csv`` (the conditions table ``idtool import --conditions`` reads),
    ``plan.txt``, ``plan.json`` and ``plan.png`` into ``folder`` (an existing folder: the
    caller's temporary one, :func:`~idtool._atomic.atomic_output_dir`)."""
    import json
    from pathlib import Path

    from idtool._plan._figure import plot_plan

    folder = Path(folder)
    plan.to_frame().to_csv(folder / "plan.csv", index=False)
    (folder / "plan.txt").write_text(plan_text(plan) + "\n")
    doc = {
        "goal": plan.goal,
        "unit": plan.unit,
        "target": plan.target,
        "values": list(plan.values),
        "uniform": list(plan.uniform),
        "bayesian": {k: list(v) for k, v in plan.bayesian.items()},
        "pulls_to_target": plan.pulls_to_target,
        "pulls": [dataclasses.asdict(p) for p in plan.pulls],
        "uniform_pulls": [dataclasses.asdict(p) for p in plan.uniform_pulls],
        "at": [list(a) for a in plan.at],
        "details": plan.details,
        "notes": list(plan.notes),
    }
    (folder / "plan.json").write_text(json.dumps(doc, indent=1) + "\n")
    plot_plan(plan, band_map, traces, folder / "plan.png")
