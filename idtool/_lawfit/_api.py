""":func:`fit_law`: the public entry point of ``idtool fit-law``."""

from __future__ import annotations

import math
import time
from pathlib import Path

import numpy as np

from idtool._data._series import Series, read_series
from idtool._lawfit._problem import make_problem
from idtool._lawfit._profile import profile_intervals
from idtool._lawfit._result import SeriesFit, estimate_from_sides
from idtool._lawfit._solve import fit_lag, solve

__all__ = ["fit_law"]


def fit_law(
    series: Series | str | Path,
    law: str = "lugre",
    *,
    posterior: bool = False,
    seed: int = 0,
) -> SeriesFit:
    """Fit a friction law to a velocity-force series.

    The law's bristle state is integrated through the series
    (:mod:`idtool._model._series_force`: exact slip updates, model notes §4), the
    parameters found by Levenberg-Marquardt on the force residuals from a multi-start,
    the load cell's first-order lag tested for by a likelihood ratio and fitted where the
    series asks for it (:mod:`idtool._lawfit._lag`), and each physical parameter's 95%
    interval checked against its profile likelihood
    (:mod:`idtool._lawfit._profile`). A parameter the series cannot inform is stated so
    (one-sided, or not identified) instead of being given a huge standard error.

    Args:
        series: a :class:`idtool.Series`, or the path of a series file
            (CSV or Parquet; docs/how-to/fit-law.md).
        law: ``lugre``, ``dahl``, ``coulomb-viscous``, or any registered friction law
            (with ``-viscous`` for an extra viscous term).
        posterior: also sample the posterior with emcee (flat priors on the internal
            scale's log ranges).
        seed: of the sampler.

    Returns:
        The :class:`idtool.SeriesFit`.

    Raises:
        IdtoolError: an unreadable series (located problems) or an unknown law.
    """
    if not isinstance(series, Series):
        series = read_series(series)
    start = time.perf_counter()
    problem = make_problem(series, law)
    opt, lm = solve(problem)
    # the load cell's lag, kept where the likelihood ratio asks for it
    problem, opt, lagged_lm = fit_lag(problem, opt)
    lm = lagged_lm or lm
    n_phys = problem.n_physical
    sides = profile_intervals(lm, opt, n_phys)
    se_z = np.sqrt(np.diag(opt.cov_z))
    estimates, by_name = {}, {}
    for k in range(n_phys):
        p = problem.params[k]
        se = float(se_z[k]) if math.isfinite(se_z[k]) else math.inf
        estimates[p.name] = estimate_from_sides(p, float(opt.z[k]), se, *sides[k])
        by_name[p.name] = sides[k]
    # the model's force from the fit's own program run for no step (no program of its
    # own to trace and compile): the white residuals are (F_model - F) / force_scale
    force = np.asarray(problem.series.force_n) + lm.linearise(opt.z, 0.0)[0] * problem.force_scale_n
    fit = SeriesFit(
        problem,
        opt,
        estimates,
        by_name,
        force,
        time.perf_counter() - start,
        lag_check=opt.lag_check,
    )
    if posterior:
        from idtool._lawfit._posterior import sample_posterior

        fit = SeriesFit(**{**fit.__dict__, "posterior": sample_posterior(fit, seed=seed)})
    return fit
