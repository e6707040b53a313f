"""What a fit found: each parameter's :class:`Estimate` and the whole :class:`FitResult`
(``model`` and ``z`` reproduce every prediction); :func:`estimate_of` maps an internal
value and its standard error to the physical scale (delta method, interval through the
transform)."""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import numpy as np

from idtool._diagnostic import Diagnostic
from idtool._fit._cov import Covariance
from idtool._fit._level_design import discrepancy_conditioning
from idtool._fit._variability import Variability
from idtool._model._benchmodel import BenchModel
from idtool._model._params import Param

__all__ = [
    "WEAK_DECADES",
    "Z95",
    "Z_AT_BOUND",
    "Estimate",
    "FitResult",
    "estimate_of",
    "interval_statement",
    "one_sided",
    "uninformed",
    "weakly_identified",
]

Z95 = 1.959963984540054
# Internal scale: a bounded parameter beyond this sits at its bound (sigmoid > 0.999).
Z_AT_BOUND = 7.0
# A positive parameter whose 95% interval spans more decades than this, though the data
# bound it on both sides, is stated as weakly identified (issue 26): an interval of
# 100:1 and wider says the data fix the parameter's order of magnitude at best, and a
# reader who takes its midpoint (Kt's creep and Coulomb plateaus lie 2-4 decades apart,
# model notes section 4) would be misled. The fit's "uninformed" diagnostic warns at the
# same width.
WEAK_DECADES = 2.0


def weakly_identified(lo: float, hi: float, side: str) -> bool:
    """True when a 95% interval bounded by the data on both sides (``side`` is "") of a
    positive parameter spans more than :data:`WEAK_DECADES` decades."""
    return side == "" and lo > 0.0 and hi > lo and math.log10(hi / lo) > WEAK_DECADES


def uninformed(spec: Param, lo: float, hi: float) -> Diagnostic | None:
    """The "uninformed" warning for a physical log-scale parameter whose 95% interval
    ``[lo, hi]`` spans more than :data:`WEAK_DECADES` decades, else None."""
    if not (spec.physical and spec.kind == "log" and hi / max(lo, 1e-300) > 10**WEAK_DECADES):
        return None
    return Diagnostic(
        "uninformed",
        f"{spec.name}: its 95% interval spans more than a factor of 100 "
        f"({lo:.3g} to {hi:.3g} {spec.unit}); the data cannot inform it",
        parameter=spec.name,
        ci95=(lo, hi),
    )


def interval_statement(
    lo: float, hi: float, side: str, fmt: str | None = None, *, weak: bool | None = None
) -> str:
    """A 95% interval as a reader should take it (:attr:`Estimate.statement`): ``[lo,
    hi]``; ``> lo`` / ``< hi`` where the data bound the parameter on one side only (the
    other end is the parameter's range, not information); the range itself said as not
    identified; an interval over :data:`WEAK_DECADES` decades said as weakly identified,
    with its width. ``fmt`` formats the numbers (default: four significant digits for a
    one-sided bound, five for an interval); ``weak`` overrides the weak-identification
    rule (:func:`weakly_identified`) where the caller knows better (a scatter sd's
    interval reaching towards zero is its prior's spike)."""
    fmt = fmt or (".4g" if side else ".5g")
    weak = weakly_identified(lo, hi, side) if weak is None else weak
    if side == "lower":
        return f"> {lo:{fmt}} (95%; not bounded above)"
    if side == "upper":
        return f"< {hi:{fmt}} (95%; not bounded below)"
    if side == "neither":
        return f"[{lo:{fmt}}, {hi:{fmt}}] (95%; not identified: bounded by its range alone)"
    if weak:
        return (
            f"[{lo:{fmt}}, {hi:{fmt}}] (95%; weakly identified: spans "
            f"{math.log10(hi / lo):.1f} decades)"
        )
    return f"[{lo:{fmt}}, {hi:{fmt}}]"


@dataclasses.dataclass(frozen=True)
class Estimate:
    """A parameter's estimate, standard error and 95% interval, in its unit."""

    name: str
    unit: str
    estimate: float
    std_error: float
    ci95: tuple[float, float]
    at_bound: bool = False
    fixed: bool = False  # fixed (--fix, a parameter table, the rig): not estimated
    fixed_label: str = ""  # who fixed it, for reports ("fixed by the user", ...)
    # "lower" when the data bound it from below only (its interval runs to the top of
    # its range: reported as "> ci95[0]"), "upper" from above only ("< ci95[1]"),
    # "neither" when the interval runs to both ends of its range (not identified),
    # "" when the data bound it on both sides
    one_sided: str = ""

    @property
    def weakly_identified(self) -> bool:
        """Bounded by the data on both sides, but over :data:`WEAK_DECADES` decades."""
        return weakly_identified(*self.ci95, self.one_sided)

    @property
    def statement(self) -> str:
        """The interval as a reader should take it (:func:`interval_statement`)."""
        return interval_statement(*self.ci95, self.one_sided)


@dataclasses.dataclass(frozen=True)
class FitResult:
    """Everything one fit found; ``model`` and ``z`` reproduce every prediction."""

    model: BenchModel
    z: np.ndarray
    # the covariance of z, in the arrowhead's blocks (idtool._fit._cov; (p, p) only
    # for the dense reference path)
    cov_z: Covariance
    # the noise model's correlation state (AbstractNoise.state_params; AR(1): [phi])
    noise_state: np.ndarray
    sigma_n: float
    rss: float
    loglik: float
    estimates: dict[str, Estimate]
    correlation: np.ndarray  # the shared parameters' (s, s), in z's order
    friction_ratio: np.ndarray
    friction_ratio_se: np.ndarray
    optima: list[dict]
    warnings: list[str]
    lm_steps: int
    jacobian_evaluations: int  # linearisations: residuals plus one JVP per colour
    # the levels model's scatter and discrepancy (issue 10), when it is on
    variability: Variability | None = None
    # what the data let the fit measure, for the report (not doubts: those are warnings)
    notes: list[str] = dataclasses.field(default_factory=list)
    # the levels' trends within their plateaus by kind ("ON", "OFF"), when diagnosed
    # (:mod:`idtool._fit._plateau_drift`)
    plateau_drift: dict[str, Any] | None = None

    @property
    def phi(self) -> float:
        """The AR(1) coefficient: the state's ``phi`` (0 for a model without one), as
        ``fit.json``'s ``noise.phi`` has always recorded it."""
        return self.model.noise.state_by_name(self.noise_state).get("phi", 0.0)

    @property
    def sd_grids(self) -> dict[str, tuple[np.ndarray, np.ndarray]]:
        """The scatter and discrepancy sds' posterior grids (REML likelihood times the
        spike-and-slab prior; empty when off)."""
        return dict(self.variability.grids) if self.variability is not None else {}

    @property
    def levels(self):
        """(free levels, sds) of the levels model, or None when it is off."""
        if self.variability is None:
            return None
        return self.variability.free, dict(self.variability.sds)

    @property
    def conditioning(self):
        """What predictions condition the discrepancy on (the traces' own friction
        ratios, :mod:`idtool._fit._discrepancy`), or None when the levels model is off."""
        levels = self.levels
        return None if levels is None else discrepancy_conditioning(self.model, levels[0])

    @property
    def n_data(self) -> int:
        return self.model.data.n_blocks

    @property
    def n_params(self) -> int:
        return int(self.z.size) + len(self.model.noise.params)  # + sigma (and the state)

    @property
    def aic(self) -> float:
        return 2 * self.n_params - 2 * self.loglik

    @property
    def bic(self) -> float:
        return self.n_params * math.log(self.n_data) - 2 * self.loglik


def estimate_of(spec: Param, z: float, se_z: float) -> Estimate:
    """A parameter's estimate from its internal value ``z`` and standard error there:
    the error mapped by the transform's slope (delta method), the 95% interval through
    the transform itself (so it respects the bounds)."""
    value = float(spec.value(float(z)))
    se = abs(float(spec.slope(z))) * float(se_z)
    if spec.bounded:
        z_lo, z_hi = float(z - Z95 * se_z), float(z + Z95 * se_z)
        lo, hi = float(spec.value(z_lo)), float(spec.value(z_hi))
        at_bound = abs(z) > Z_AT_BOUND
        side = one_sided(z_lo, z_hi)
    else:
        lo, hi, at_bound, side = value - Z95 * se, value + Z95 * se, False, ""
    return Estimate(spec.name, spec.unit, value, se, (lo, hi), at_bound, one_sided=side)


def one_sided(z_lo: float, z_hi: float) -> str:
    """Which side alone the data bound, from the interval's ends on the internal scale:
    an end at or beyond :data:`Z_AT_BOUND` is the parameter's range, not an end the data
    set (:attr:`Estimate.one_sided`)."""
    open_lo, open_hi = z_lo <= -Z_AT_BOUND, z_hi >= Z_AT_BOUND
    if open_lo and open_hi:
        return "neither"
    if open_hi and not open_lo:
        return "lower"
    if open_lo and not open_hi:
        return "upper"
    return ""
