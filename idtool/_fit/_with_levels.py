"""A fit's result under the levels model (:mod:`idtool._fit._variability`): its physical
parameters, covariance and per-trace friction ratios from the levels model, the sds in
:attr:`FitResult.variability`. Apart from :mod:`idtool._fit._variability` because a
:class:`FitResult` holds a :class:`~idtool._fit._variability.Variability`: the record
below the result, what makes one from the other above it."""

from __future__ import annotations

import dataclasses

import numpy as np

from idtool._diagnostic import Diagnostic
from idtool._fit._free_levels import free_levels, model_log_levels
from idtool._fit._level_design import level_design
from idtool._fit._level_profile import check_level_intervals
from idtool._fit._reml import GRID, evaluate, fit_sds
from idtool._fit._result import FitResult, estimate_of
from idtool._fit._variability import NoMeasuredLevels, estimate_variability

__all__ = ["compile_variability", "with_variability"]


def compile_variability(result: FitResult) -> None:
    """Compile the levels model's programs for ``result``'s traces (their shapes: how
    many ON levels are measured), for :func:`estimate_variability` to find compiled;
    run in :class:`~idtool._fit._prefetch.CompileAhead`'s thread."""
    free = free_levels(result.model, result.z, result.noise_state)
    assert free.cov_parts is not None  # a fresh free_levels'
    design = level_design(result.model, free.measured)
    m, k = free.off_n.size, result.model.n_physical
    r2, g2 = np.zeros((m, 2)), np.zeros((m, 2, k))
    args = dataclasses.replace(free.cov_parts, disc=design.disc_root).arrays
    fit_sds.compile_ahead(np.zeros(3), np.zeros(3), r2, g2, *args)
    evaluate.compile_ahead(np.zeros((GRID, 3)), r2, g2, *args, True)
    evaluate.compile_ahead(np.zeros((1, 3)), r2, g2, *args, False)  # at_sds: one row


def with_variability(result: FitResult) -> FitResult:
    """``result`` under the levels model (module docstring): the physical parameters,
    their covariance and the per-trace friction ratios from stage 2, their intervals
    checked against its profile likelihood (:mod:`idtool._fit._level_profile`), the sds
    and the lack-of-fit test in :attr:`FitResult.variability`, its warnings added. The bench
    parameters and nuisances stay the fit's."""
    model = result.model
    k, m = model.n_physical, model.data.n_traces
    try:
        v = estimate_variability(model, result.z, result.noise_state)
    except (np.linalg.LinAlgError, NoMeasuredLevels) as err:
        why = str(err) or "their covariance is singular"
        note = (
            f"scatter and discrepancy not estimated: the traces' own levels ({why}); "
            "the intervals are the noise-only model's and may be too narrow"
        )
        return dataclasses.replace(
            result, warnings=[*result.warnings, Diagnostic("levels_not_estimated", note)]
        )
    z = result.z.copy()
    z[:k] = v.theta
    cov = result.cov_z.with_leading(k, v.cov_theta)
    se_z = np.sqrt(np.diag(v.cov_theta))
    estimates = dict(result.estimates)
    physical = {spec.name for spec in model.shared_params[:k]}
    for i, spec in enumerate(model.shared_params[:k]):
        estimates[spec.name] = estimate_of(spec, z[i], se_z[i])
    # the Wald intervals checked against the levels model's profile likelihood
    estimates, profiled = check_level_intervals(model, result.noise_state, v, z, se_z, estimates)
    g, jac = model_log_levels(model, z, result.noise_state)
    fr = np.exp(g[m:])
    # the delta method's variance as a sum of squares over the covariance's eigenvectors:
    # never negative, where the quadratic form j C j' came out -3.7e-4 by round-off when
    # one direction of C is unidentified (eigenvalues 1.5e-5 to 2.1e12 on two loads with
    # short ON windows, tests/test_fit.py) and failed the fit under warnings as errors
    w, u = np.linalg.eigh(v.cov_theta)
    fr_se = fr * np.sqrt(np.sum((jac[m:] @ u) ** 2 * np.maximum(w, 0.0), axis=1))
    return dataclasses.replace(
        result,
        z=z,
        cov_z=cov,
        estimates=estimates,
        friction_ratio=fr,
        friction_ratio_se=fr_se,
        warnings=[*_kept(result.warnings, physical), *v.warnings, *profiled],
        notes=[*result.notes, *v.notes],
        variability=v,
    )


def _kept(warnings: list, physical: set[str]) -> list:
    """The noise-only fit's ``warnings`` that still hold under the levels model: not its
    ``profile_interval`` warnings on the physical parameters, whose intervals the levels
    model replaces (each said its profile interval was "reported instead"; the levels
    model's own check, :mod:`idtool._fit._level_profile`, warns where its interval is
    widened)."""
    return [
        w
        for w in warnings
        if not (
            getattr(w, "code", None) == "profile_interval" and w.values.get("parameter") in physical
        )
    ]
