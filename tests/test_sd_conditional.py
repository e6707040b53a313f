"""Draws from a fit's covariance given each draw's sds (:func:`idtool._predict._predict.
draws_from_covariance` with :class:`~idtool._fit._variability.ThetaGivenSds`).

Without a posterior the physical parameters are drawn, per draw ``k``, as ``theta_k ~
N(theta_hat, Sigma(s_k))``, ``Sigma(s) = (G^T C(s)^-1 G)^-1`` at the draw's own scatter
and discrepancy sds: an uncertain sd widens the parameters' spread with it. Checked: the
covariance at the REML sds is the fit's (by construction); it grows with the
discrepancy and the scatter; the band agrees with the planner's linear-Gaussian one
(:func:`idtool._plan._plan.band_half_widths`) on a small bench with 3% FR scatter, where
the shortcut (every draw at the REML sds' covariance) was half as wide; the example's
band (sds at zero, tight) is unchanged; a fit folder without the Jacobian draws as before
and says so.
"""

from __future__ import annotations

import itertools
import shutil
import warnings

import numpy as np
import pytest
from sample_helpers import small_params

import idtool
import idtool._plan._plan as plan_module
from idtool._fit._folder import FIT_STATE
from idtool._plan._linear import Points
from idtool._predict._predict import _conditional_steps, draws_from_covariance

SCATTER = {"friction_ratio_sd": 0.03, "friction_coefficient_sd": 0.007}  # the study's
POINTS = [(270.0, 0.5), (450.0, 0.6), (670.0, 0.7), (450.0, 0.5)]  # 450 N held out
SPEED = 0.025


@pytest.fixture(scope="module")
def example_fit(example_default_run):
    return idtool.Fit.from_run(
        idtool.load_dataset(idtool.example_dataset_path()), example_default_run
    )


@pytest.fixture(scope="module")
def scatter_fit():
    """The small design (8 traces, 4 operating points) with the study's 3% FR and 0.7%
    mu scatter, seed 3: the REML sds of the FR at zero, their 95% intervals up to 3.2%
    (scatter) and 6.5% (discrepancy), the colleague's case."""
    params = small_params()
    params["scatter"] = dict(SCATTER)
    dataset, _ = idtool.simulate_bench(params, seed=3)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # its misfit warnings are not checked here
        return idtool.fit(dataset, seed=0)


def _shortcut(fit: idtool.Fit, max_draws: int, seed: int):
    """The draws as they were before: every draw at the REML sds' covariance."""
    law = fit.artefact.chosen
    return draws_from_covariance(
        law.model, law.z, law.cov_z, max_draws, seed, law.sd_grids, law.conditioning
    )


def _half_widths(fit: idtool.Fit, draws=None, max_draws=4000, seed=1) -> np.ndarray:
    """The mean-FR band's half-width at :data:`POINTS`, Fit.predict's draws or ``draws``."""
    from idtool._predict._predict import predict_friction_ratio

    out = []
    for load, a in POINTS:
        if draws is None:
            p = fit.predict(load, a, SPEED, max_draws=max_draws, seed=seed)[0]
        else:
            p = predict_friction_ratio(draws, [load], [a], [SPEED])[0]
        out.append(0.5 * (p.ci95[1] - p.ci95[0]))
    return np.array(out)


def test_the_covariance_at_the_reml_sds_is_the_fits(example_fit):
    """Sigma(REML sds) from the stored Jacobian and blocks is the fit's cov_theta, which
    the fit wrote into cov_z's physical block; to round-off (the sds are stored as sds,
    squared back)."""
    law = example_fit.artefact.chosen
    k = law.model.n_physical
    v = example_fit.result.variability
    assert v is not None and law.theta_given_sds is not None
    at_reml = law.theta_given_sds.at({})
    np.testing.assert_allclose(at_reml, v.cov_theta, rtol=1e-10, atol=0.0)
    np.testing.assert_allclose(law.cov_z.leading(k), v.cov_theta, rtol=1e-10, atol=0.0)
    # every draw of the sds at the REML estimate (each grid's mass on one point): the
    # draws' internal-scale covariance is the fit's, to Monte Carlo error (a variance's
    # relative sd at 4000 draws is sqrt(2 / 4000) = 2.2%; 10% is 4.5 of them)
    sds = {name: np.full(4000, est) for name, (est, _, _) in v.sds.items()}
    eps = np.random.default_rng(0).standard_normal((4000, k))
    steps = _conditional_steps(law.theta_given_sds, sds, eps)
    np.testing.assert_allclose(np.var(steps, axis=0), np.diag(v.cov_theta), rtol=0.10)


@pytest.mark.parametrize("name", ["discrepancy_fr", "scatter_fr"])
def test_the_covariance_grows_with_the_sds(example_fit, name):
    """Sigma(s) grows in the Loewner order as the discrepancy (or the scatter) grows:
    more variance in C, less information G^T C^-1 G."""
    tg = example_fit.artefact.chosen.theta_given_sds
    covs = [tg.at({name: s}) for s in (0.0, 0.01, 0.03, 0.1)]
    for small, big in itertools.pairwise(covs):
        gap = np.linalg.eigvalsh(big - small)
        assert gap.min() >= -1e-9 * np.abs(gap).max()
        assert np.all(np.diag(big) >= np.diag(small) * (1.0 - 1e-10))
    # and by far at 10%, for the parameters the friction ratio informs (mu, read off the
    # OFF levels, hardly moves with the FR's sds)
    assert np.max(np.diag(covs[-1]) / np.diag(covs[0])) > 2.0


def test_the_band_agrees_with_the_planners_under_scatter(scatter_fit, monkeypatch):
    """On the small bench with 3% scatter the planner's linear-Gaussian band and
    Fit.predict's agree; the shortcut's was much narrower.

    The planner's band is a mixture over draws of the sds (eq. B1 of
    :mod:`idtool._plan._band`), its quantiles set by the slab's tail: at its default 32
    draws it moved by up to 2.8x over seeds here, at 1000 by 10-20% (measured), so it is
    run at 1000. What stays is the linearisation: the planner is linear in theta where
    the tail's sds (up to 15%) spread theta widely, and it leaves out the shift of the
    discrepancy's kriging mean with the sds; measured, planner / predict 0.81-1.08 at
    these points (seed 3), 0.79-1.31 on seed 4, against predict's own Monte Carlo error
    of ~2% at 4000 draws. Hence: every point within a factor 1.35, and the geometric
    mean of the ratios within 15% of 1. The shortcut's ratios were 1.2-2.2 (geometric
    mean ~1.7), which fails both."""
    monkeypatch.setattr(plan_module, "N_SD_DRAWS", 1000)
    pts = Points(
        np.array([p[0] for p in POINTS]), np.array([p[1] for p in POINTS]), np.full(4, SPEED)
    )
    lin = plan_module.band_half_widths(scatter_fit.artefact, pts)
    ratio = lin / _half_widths(scatter_fit)
    assert np.all((ratio > 1 / 1.35) & (ratio < 1.35)), ratio
    assert abs(np.exp(np.mean(np.log(ratio))) - 1.0) < 0.15, ratio
    before = lin / _half_widths(scatter_fit, _shortcut(scatter_fit, 4000, 1))
    assert np.exp(np.mean(np.log(before))) > 1.35, before  # the defect this fixes


def test_the_examples_band_is_unchanged(example_fit):
    """The example's sds sit at zero with tight intervals: Sigma(s) hardly moves over
    their draws, and the band is the shortcut's to Monte Carlo error (the percentile
    band's sd at 4000 draws is ~2% of its half-width, tests/test_plan.py; 6% is three)."""
    now = _half_widths(example_fit)
    before = _half_widths(example_fit, _shortcut(example_fit, 4000, 1))
    np.testing.assert_allclose(now, before, rtol=0.06)


def test_a_folder_without_the_jacobian_draws_as_before(example_fit, tmp_path):
    """A fit folder of version 2 (fit_state.npz without ``levels_jacobian``) loads, and
    draws every draw at the REML sds' covariance, as idtool did then, and says so; same
    seed, same draws."""
    example_fit.save(tmp_path / "fit")
    old = shutil.copytree(tmp_path / "fit", tmp_path / "old")
    with np.load(old / FIT_STATE.name) as npz:
        arrays = {k: npz[k] for k in npz.files if k != "levels_jacobian"}
    np.savez(old / FIT_STATE.name, **arrays)
    back = idtool.load_fit(old)
    assert back.artefact.chosen.theta_given_sds is None
    d = back.draws(300, 2)
    assert "at the REML sds for every draw" in d.note
    ref = _shortcut(example_fit, 300, 2)
    for name, x in ref.values.items():
        np.testing.assert_array_equal(d.values[name], x)
    new = idtool.load_fit(tmp_path / "fit").draws(300, 2)
    assert "given each draw's sds" in new.note
    same = example_fit.draws(300, 2)
    for name, x in same.values.items():
        np.testing.assert_array_equal(new.values[name], x)
