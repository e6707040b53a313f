"""A planning goal as options: checked, its target, whether a value meets it, and the
``idtool plan`` options that ask for it. Light (no JAX): the command line checks them
before it reads a fit, and the report (:mod:`idtool._report._html_plan`) records them in
its id and prints the command that reproduces its plan.
"""

from __future__ import annotations

import dataclasses
import math

from idtool._errors import IdtoolError

__all__ = ["GOAL_NAMES", "GoalOptions", "meets_target"]

GOAL_NAMES = ("band", "laws", "parameters")


def meets_target(goal: str, value: float, target: float) -> bool:
    """Whether ``value`` of ``goal`` meets ``target`` (the laws goal's weight: at least;
    a half-width or a relative sd: at most)."""
    return value >= target if goal == "laws" else value <= target


@dataclasses.dataclass(frozen=True)
class GoalOptions:
    """A goal and the number of pulls to plan for it (:func:`~idtool._plan._plan.
    plan_pulls`' options of the same names)."""

    goal: str = "parameters"
    n_pulls: int = 10
    at: tuple[tuple[float, float], ...] = ()
    half_width: float = 0.01
    rel: float = 0.05
    weight: float = 0.95

    def __post_init__(self) -> None:
        if self.goal not in GOAL_NAMES:
            raise IdtoolError(f"goal {self.goal!r}: choose one of {', '.join(GOAL_NAMES)}")
        if self.goal == "band" and not self.at:
            raise IdtoolError("--goal band needs --at LOAD,AMPLITUDE (e.g. --at 670,0.7)")
        if self.n_pulls < 1:
            raise IdtoolError(f"--pulls {self.n_pulls}: plan at least 1")
        if not 0 < self.half_width < 1:
            raise IdtoolError(f"--half-width {self.half_width:g}: give an FR half-width in (0, 1)")
        if not (math.isfinite(self.rel) and self.rel > 0):
            raise IdtoolError(f"--rel {self.rel:g}: give a positive relative sd, e.g. 0.05")
        if not 0 < self.weight < 1:
            raise IdtoolError(f"--weight {self.weight:g}: give a weight in (0, 1)")
        for load, amp in self.at:
            if not (load > 0 and 0 < amp <= 1):
                raise IdtoolError(
                    f"at {load:g},{amp:g}: the load must be positive [N] and the amplitude a "
                    "fraction in (0, 1]"
                )

    @property
    def target(self) -> float:
        """The goal's target: the half-width [FR], the relative sd or the weight."""
        return {"band": self.half_width, "parameters": self.rel, "laws": self.weight}[self.goal]

    def as_dict(self) -> dict:
        """The options that matter to the goal, canonically (for a report's id)."""
        out: dict = {"goal": self.goal, "pulls": self.n_pulls, "target": self.target}
        if self.goal == "band":
            out["at"] = [list(a) for a in self.at]
        return out

    def plan_arguments(self) -> list[str]:
        """The ``idtool plan`` options that ask for this goal."""
        out = ["--goal", self.goal]
        for n, a in self.at if self.goal == "band" else ():
            out += ["--at", f"{n:g},{a:g}"]
        option = {"band": "--half-width", "parameters": "--rel", "laws": "--weight"}[self.goal]
        return [*out, option, f"{self.target:g}", "--pulls", str(self.n_pulls)]

    def words(self, physical: tuple[str, ...] | list[str] = ()) -> str:
        """The goal in words."""
        if self.goal == "parameters":
            names = f" ({', '.join(physical)})" if physical else ""
            return f"every physical parameter{names} to a relative sd of at most {self.rel:g}"
        if self.goal == "band":
            where = "; ".join(f"{n:g} N, amplitude {a:g}" for n, a in self.at)
            return (
                f"the mean FR's 95% band at {where} to a half-width of at most {self.half_width:g}"
            )
        return (
            f"the coupling laws told apart: the true law's expected weight at least {self.weight:g}"
        )
