""":func:`fit_levels`: Kt, mu and the coupling from a steady-state friction table, the
public entry point behind ``idtool fit`` on a dataset of kind ``levels``."""

from __future__ import annotations

import dataclasses
import math
import time
from pathlib import Path

import numpy as np

from idtool._data._design import speed_resolved_pairs
from idtool._data._levels import LevelsTable, load_levels
from idtool._fit._variability import MISFIT, MISSPECIFIED_SD
from idtool._lawfit._result import estimate_from_sides
from idtool._levels._choice import kept, label, options, rank, table_bic
from idtool._levels._estimate import SD_FLOOR, SD_NAMES, estimate, profile_sides
from idtool._levels._free import check_coupling
from idtool._levels._model import DEFAULT_LAW, LevelsModel, levels_model
from idtool._levels._result import LevelsFit
from idtool._model._names import BY_DESIGN, DEFAULT_DIRECTION

__all__ = ["fit_levels"]

_NULL_LOADING = 0.1  # a parameter this much in an uninformed direction is not pinned
# below this BIC weight the chosen model shares the evidence: said so (as the trace fit's
# comparable_warning: the others hold more than 5%)
COMPARABLE = 0.95
CANNOT_PIN = "the table cannot pin"


def fit_levels(
    table: LevelsTable | str | Path,
    *,
    law: str = DEFAULT_LAW,
    coupling: str = BY_DESIGN,
    direction: str = DEFAULT_DIRECTION,
    seed: int = 0,
) -> LevelsFit:
    """Fit Kt, mu and the coupling law to a steady-state friction table.

    The rows' log OFF levels give mu (``mu = F_off / N``, or the coefficient itself),
    their friction ratios ``FR = ON / OFF`` the contact stiffness and the coupling, both
    through the registered friction and coupling laws (:mod:`idtool._levels._model`).
    Pull-to-pull scatter and model discrepancy are estimated as in the trace fit's
    levels model, the table's standard errors taken as known measurement variance
    (:mod:`idtool._levels._estimate`). Each interval is Wald where the profile
    likelihood agrees, else the profile's, one-sided or "not identified" where the
    table does not bound the parameter; a warning names the parameters the table
    cannot pin apart.

    Args:
        table: a :class:`LevelsTable`, or the folder (or ``dataset.json``) of a
            dataset of kind ``levels`` (``idtool import-levels``).
        law: registered friction law (default Dahl, as :func:`idtool.fit`'s).
        coupling: registered coupling law, ``"auto"`` (every coupling law a table can
            take, ranked by BIC: :mod:`idtool._levels._choice`) or ``"by-design"``
            (default, as :func:`idtool.fit`'s): the power limit, and on a table that
            measured some load and amplitude at two or more speeds also the load-power
            law, BIC choosing (two speeds at one slip amplitude pin it and Kt whatever
            the law, so a law's wrong shape shows as misfit instead of moving Kt).
        direction: of the vibration (default along the sliding), or ``"auto"``: every
            direction, ranked by BIC (with ``coupling="auto"``: every pair).
        seed: of the multi-start.

    Returns:
        The :class:`LevelsFit`; after a model choice the best model's, with every
        model's BIC and weight (its ``ranking``) and the others whose weight reaches
        0.001 kept for its predictions (its ``alternates``).

    Raises:
        IdtoolError: an invalid dataset (located problems) or an unknown name.
    """
    if not isinstance(table, LevelsTable):
        table = load_levels(table)
    start = time.perf_counter()
    resolved = bool(
        speed_resolved_pairs(table.normal_load_n, table.amplitude_m, table.sliding_speed_m_s)
    )
    pairs = options(coupling, direction, speed_resolved=resolved)
    if len(pairs) == 1:
        return _checked(_fit_one(table, law, *pairs[0], seed, start), seed, start)
    fits = [_fit_one(table, law, c, d, seed, start) for c, d in pairs]
    varied = (("coupling", {c for c, _ in pairs}), ("direction", {d for _, d in pairs}))
    compared = [name for name, values in varied if len(values) > 1]
    ranking = rank(
        [
            (label(f.model.coupling, f.model.direction, compared),
             f"{f.model.law}/{f.model.coupling}/{f.model.direction}", *_criteria(f))
            for f in fits
        ]
    )  # fmt: skip
    by_key = {f"{f.model.law}/{f.model.coupling}/{f.model.direction}": f for f in fits}
    best = by_key[ranking[0].key]
    alternates = tuple(by_key[w.key] for w in kept(ranking)[1:])
    warnings = best.warnings
    if ranking[0].bic_weight < COMPARABLE:
        shown = [w for w in ranking[1:] if w.bic_weight >= 0.01]
        others = ", ".join(f"{w.name} {w.bic_weight:.2f}" for w in shown)
        warnings = (
            *warnings,
            f"the {' and '.join(compared)} options fit comparably (BIC weights: "
            f"{ranking[0].name} {ranking[0].bic_weight:.2f}, {others}): the estimates are "
            f"{ranking[0].name}'s, the bands average the models by weight",
        )
    o = best.optimum
    fr_sds = [
        o.sds[n] for n, on in zip(SD_NAMES, o.active, strict=True) if on and n != "scatter_mu"
    ]
    if not o.restricted and max(fr_sds, default=0.0) <= 2.0 * SD_FLOOR:
        # saturated: the sds by ML run to their floor where a model meets every row,
        # and -2 log L falls by ~14 per row with it: the weights reward the exact fit
        # (not so where the best model still misses a row: its discrepancy is large)
        warnings = (
            *warnings,
            f"the best model ({ranking[0].name}) leaves no residual degrees of freedom "
            "(its sds by ML, at or near their floor): its BIC weight says the others "
            "cannot meet the table, not that it predicts better, and its bands are "
            f"biased narrow; add conditions or repeats before choosing a {compared[0]} "
            "from this table",
        )
    best = dataclasses.replace(
        best, ranking=tuple(ranking), alternates=alternates, warnings=warnings
    )
    return _checked(best, seed, start)


def _checked(fit: LevelsFit, seed: int, start: float) -> LevelsFit:
    """``fit`` with its coupling law's shape checked against free slip amplitudes
    (:mod:`idtool._levels._free`); where the table rejects the shape, the friction
    law's parameters' intervals widened to hold their law-free ones, and said so."""
    check = check_coupling(fit.model, fit.optimum, seed)
    if check is None:
        return dataclasses.replace(fit, seconds=time.perf_counter() - start)
    test = (
        f"-2 log likelihood ratio {check.statistic:.1f}, F on {check.dof} and "
        f"{check.residual_dof} degrees of freedom, p = {check.p_value:.2g}"
    )
    if not check.rejected:
        note = (
            f"the {check.coupling} law's shape was checked against a free slip amplitude at "
            f"each of the {check.points} load-amplitude points ({check.resolved} at two or "
            f"more speeds): not rejected ({test})"
        )
        return dataclasses.replace(
            fit, coupling_check=check, notes=(*fit.notes, note),
            seconds=time.perf_counter() - start,
        )  # fmt: skip
    estimates, sides, widened = dict(fit.estimates), dict(fit.sides), []
    names = fit.model.names
    for name, (flo, fhi) in check.free.items():
        lo, hi = fit.sides[name]
        new_lo = flo if flo.z < lo.z else lo
        new_hi = fhi if fhi.z > hi.z else hi
        if (new_lo, new_hi) == (lo, hi):
            continue
        j = names.index(name)
        p = fit.model.params[j]
        sides[name] = (new_lo, new_hi)
        estimates[name] = estimate_from_sides(
            p, float(fit.optimum.theta[j]), math.inf, new_lo, new_hi
        )
        widened.append(name)
    check = dataclasses.replace(
        check, widened=tuple(widened), law_sides={n: fit.sides[n] for n in widened}
    )
    said = "; ".join(f"{n} {estimates[n].statement}" for n in widened) or "none needed widening"
    warning = (
        f"the table rejects the {check.coupling} law's shape against a free slip amplitude "
        f"at each of its {check.points} load-amplitude points ({test}): Kt and the friction "
        "law are read through a coupling the data do not follow; their intervals now hold "
        f"what the speeds say without a coupling law ({said}); the bands stay the law's, "
        "its discrepancy carrying the misfit"
    )
    widened_fit = dataclasses.replace(fit, estimates=estimates, sides=sides, coupling_check=check)
    # the unpinned-parameters warning restated with the intervals as now stated
    fresh = [w for w in _diagnose(widened_fit)[0] if w.startswith(CANNOT_PIN)]
    kept = [w for w in fit.warnings if not w.startswith(CANNOT_PIN)]
    return dataclasses.replace(
        widened_fit, warnings=(*fresh, *kept, warning), seconds=time.perf_counter() - start
    )


def _criteria(fit: LevelsFit) -> tuple[float, float]:
    """BIC and AIC of ``fit`` (:func:`idtool._levels._choice.table_bic`)."""
    o = fit.optimum
    return table_bic(o.loglik, len(fit.model.params) + sum(o.active), o.y.size)


def _fit_one(table, law, coupling, direction, seed, start) -> LevelsFit:
    """One model's fit (:func:`fit_levels`' stages)."""
    model = levels_model(table, law, coupling, direction)
    opt = estimate(model, seed=seed)
    estimates, sides, ends = {}, {}, {}
    se_z = np.sqrt(np.maximum(np.diag(opt.cov_theta), 0.0))
    for j, p in enumerate(model.params):
        lo, hi, ends[p.name] = profile_sides(model, opt, j)
        sides[p.name] = (lo, hi)
        se = float(se_z[j]) if lo.method == hi.method == "wald" else math.inf
        estimates[p.name] = estimate_from_sides(p, float(opt.theta[j]), se, lo, hi)
    fit = LevelsFit(model, opt, estimates, sides, ends, (), (), 0.0)
    warnings, notes = _diagnose(fit)
    seconds = time.perf_counter() - start
    return LevelsFit(model, opt, estimates, sides, ends, warnings, notes, seconds, seed)


def _diagnose(fit: LevelsFit) -> tuple[tuple[str, ...], tuple[str, ...]]:
    model: LevelsModel = fit.model
    t, o = model.table, fit.optimum
    warnings, notes = [], []
    names = model.names
    in_null = {
        names[j]
        for j in range(len(names))
        if o.null.shape[1] and np.max(np.abs(o.null[j])) > _NULL_LOADING
    }
    loose = [
        n for n, e in fit.estimates.items() if n in in_null or e.one_sided or e.weakly_identified
    ]
    if loose:
        points = {(n, a) for n, a in zip(t.normal_load_n, t.amplitude_m, strict=True)}
        speeds = np.unique(t.sliding_speed_m_s).size
        coupling_names = {p.name for p in model.spec.coupling.fit_params}
        n_coupling = len(coupling_names)
        listed = "; ".join(f"{n} {fit.estimates[n].statement}" for n in loose)
        text = (
            f"{CANNOT_PIN} {', '.join(loose)}: {t.operating_points[1].size} "
            f"condition(s), {len(points)} load-amplitude point(s) at {speeds} speed(s), "
            f"for {len(names)} parameters ({listed})"
        )
        if len(points) <= n_coupling and coupling_names & set(loose):
            text += (
                f"; {len(points)} load-amplitude point(s) cannot pin a {n_coupling}-"
                f"parameter coupling law ({model.coupling}): add loads or amplitudes, or "
                "fit --coupling constant"
            )
        warnings.append(text)
    # REML's estimate, not the bands' sd: the misfit the table shows, not its doubt
    disc = o.sds["discrepancy_fr"] if o.discrepancy is None else o.discrepancy.reml
    if disc > MISSPECIFIED_SD:
        warnings.append(
            f"{MISFIT} the conditions by {100 * disc:.0f}% in friction ratio "
            "(discrepancy sd): the bands carry it, but the estimates are read through "
            "the model's shape; compare another direction or coupling law"
        )
    fitted = fit.fitted_fr
    flat = (fitted > 0.99) & (t.friction_ratio < 0.95)
    for i in np.flatnonzero(flat):
        warnings.append(
            f"{MISFIT} row {i + 1}: no reduction in the model (the sliding outruns the "
            f"vibration, velocity ratio >= 1) where the table has FR "
            f"{t.friction_ratio[i]:.3f} at {t.sliding_speed_m_s[i] * 1e3:.4g} mm/s"
        )
    if not o.active[1]:
        notes.append(
            "one row per condition: pull-to-pull scatter and model discrepancy cannot be "
            "told apart; discrepancy_fr is their sum"
        )
    if not np.any(np.isfinite(t.off_se) | np.isfinite(t.on_se)):
        notes.append("no standard errors given: the measurement variance is in the sds")
    if not o.restricted:
        notes.append(
            "the sds by maximum likelihood (no residual degrees of freedom for REML): biased low"
        )
    return tuple(warnings), tuple(notes)
