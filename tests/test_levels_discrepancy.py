"""A table's discrepancy sd integrated over its likelihood (idtool/_levels/_discrepancy.py):
the grid against quadrature on a one-way random-effects likelihood, and on a table whose
horn gain drifts, where REML puts the discrepancy at its floor, the bands that now hold
a new condition's FR (they missed all three before)."""

from __future__ import annotations

import json
import math
from pathlib import Path

import jsonschema
import numpy as np
import pytest
import scipy.integrate
import scipy.optimize
import scipy.stats

import idtool
from idtool._levels._discrepancy import discrepancy_posterior
from idtool._simulate._table import TABLE_TRUTH, table_friction_ratio
from tests.test_levels_table import table_csv

SCHEMA = Path(__file__).parents[1] / "datasets_schema" / "levels_fit.schema.json"


def _one_way(means: np.ndarray, noise_sd: float):
    """-log REML likelihood of tau for condition means ~ N(0, tau^2 + noise_sd^2), known
    centre (closed form), and its REML maximiser."""
    ss, c = float(np.sum(means**2)), means.size

    def nll(tau: float) -> float:
        v = tau**2 + noise_sd**2
        return 0.5 * (c * math.log(v) + ss / v)

    return nll, math.sqrt(max(ss / c - noise_sd**2, 0.0))


@pytest.mark.parametrize("tau_true", [0.0, 0.02, 0.08])
def test_the_grid_integrates_the_likelihood_times_the_half_normal_prior(tau_true):
    """E[tau^2] and the 97.5% point on the grid against adaptive quadrature of the same
    density: to 1% (161 points over where the likelihood lives; the trapezoid's error
    is second order in the spacing, ~1e-4 here)."""
    rng = np.random.default_rng(3)
    noise = 0.03
    means = rng.normal(0.0, math.hypot(tau_true, noise), 18)
    nll, reml = _one_way(means, noise)
    post = discrepancy_posterior(nll, reml)

    base = nll(reml)

    def density(t):
        return math.exp(-(nll(t) - base) - 0.5 * (t / 0.1) ** 2)

    top = float(post.grid[-1])
    z = scipy.integrate.quad(density, 0.0, top, limit=200)[0]
    m2 = scipy.integrate.quad(lambda t: t * t * density(t), 0.0, top, limit=200)[0] / z
    assert post.band_sd == pytest.approx(math.sqrt(m2), rel=0.01)
    hi = scipy.optimize.brentq(
        lambda x: scipy.integrate.quad(density, 0.0, x, limit=200)[0] / z - 0.975, 0.0, top
    )
    assert post.ci95[1] == pytest.approx(hi, rel=0.02)
    # beyond the grid's top nothing is left: the likelihood has fallen by e^-12 there
    assert nll(top) - min(nll(float(t)) for t in post.grid) >= 12.0 or top >= 2.0
    # the band's sd is at least REML's where REML leaves the floor (the likelihood leans
    # right of its mode), and positive where it sits at zero
    assert post.band_sd > 0.5 * reml and post.band_sd > 0.0


def test_a_drifting_gain_table_gets_bands_that_hold_a_new_condition(tmp_path):
    """Simulated table (3 loads x 3 amplitudes x 2 speeds x 3 repeats, a 2% discrepancy
    per condition under 3% scatter) whose horn gain falls 15% over the campaign, rows in
    a random order: the drift adds ~3% scatter, and REML puts the discrepancy at its
    0.1% floor (seed 1; as on 4 of 8 seeds). The bands read at REML's estimate missed
    the true FR (with a new condition's 2% discrepancy) at the third held-out condition
    (z 2.6); integrated over its likelihood the discrepancy's 95% interval holds the 2%
    and the mean bands hold all three (over 8 seeds in benchmarks/study_benches.py: 23
    of 24 against 19). The report and fit.json state it, and a loaded fit gives the
    same bands."""
    seed = 1
    table = idtool.simulate_table(seed, departure="gain-drift")
    # the fit as a lab makes it: imported, fitted, saved; the loaded fit the same
    data = tmp_path / "data"
    idtool.import_levels(table_csv(table, tmp_path / "t.csv"), data, material="m",
                         friction="force")  # fmt: skip
    fit = idtool.fit_levels(data, coupling="power-limited", seed=seed)
    d = fit.optimum.discrepancy
    assert d is not None and d.reml <= 2e-3  # at REML's floor: the case
    assert d.ci95[0] <= 0.02 <= d.ci95[1]
    assert fit.optimum.sds["discrepancy_fr"] == d.band_sd >= 0.01
    out = fit.save(tmp_path / "fit")
    back = idtool.load_levels_fit(out)
    rng = np.random.default_rng(10_000 + seed)
    for load, amp, speed in ((35.0, 3e-6, 0.05), (70.0, 5e-6, 0.03), (70.0, 3e-6, 0.05)):
        truth = table_friction_ratio(
            load, amp, speed, truth=TABLE_TRUTH, departure="gain-drift"
        ) * math.exp(rng.normal(0.0, 0.02))
        p = fit.predict(load, speed, amplitude_m=amp)
        assert p.mean_band[0] <= truth <= p.mean_band[1], (load, amp, speed, truth, p.mean_band)
        q = back.predict(load, speed, amplitude_m=amp)
        np.testing.assert_allclose(np.ravel(q.mean_band), np.ravel(p.mean_band), rtol=1e-12)
    assert "REML 0.10%" in fit.report() and back.report() == fit.report()
    doc = json.loads((out / "fit.json").read_text())
    jsonschema.validate(doc, json.loads(SCHEMA.read_text()))
    assert doc["sds"]["discrepancy"]["band_sd"] == d.band_sd
    assert doc["sds"]["discrepancy_fr"] == d.band_sd
    assert doc["sds"]["discrepancy"]["reml"] == d.reml
    # BIC's likelihood stays the maximum, at REML's sds: above the one at the band's sd
    y, c = fit.optimum.y, fit.optimum.cov
    r = y - np.asarray(fit.model.log_levels(fit.optimum.theta))
    at_band = float(scipy.stats.multivariate_normal(np.zeros(y.size), c).logpdf(r))
    assert doc["log_likelihood"] == fit.optimum.loglik > at_band
