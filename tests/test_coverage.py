"""Coverage of idtool's intervals on benches that depart from the fit's model (issue 10).

Recovering the truth from the fit's own simulator proves little, so every dataset here
has a departure the fit does not assume (idtool._simulate._departures): pull-to-pull
scatter, a lagging rate-limited actuator, 60 Hz mains at 2 kHz, offset drift, a coupling
law the fit does not ship, and all of them together; plus clean data, where the bands
must not widen. The study is 7 kinds x 3 seeds = 21 datasets on the paper's matrix (24
traces), each fitted with the defaults a new user gets (``idtool.fit(dataset)``), and
scored against the truth. Every dataset has its own seed (kind k of ``DEPARTURE_KINDS``
takes seeds 3k+1 to 3k+3; a kind added there is picked up): the seed draws the truth
and the noise, and kinds sharing seeds would share noise realisations, so one unlucky
realisation would count as several misses (seed 1's mu estimate sits
2.5 standard errors low on the clean, scatter and drift benches alike; on 11 clean seeds
the z-scores of mu have an rms of 1.1, so it is chance, counted three times).

* the mean friction ratio at 6 held-out operating points (360 and 560 N x 50, 60, 70%)
  inside its 95% band (``Prediction.ci95``): at least 90% of the 126 overall, and no
  kind below 15 of 18 (a kind that collapses is a defect even if the others carry the
  total; 15/18 is below the 95% rate by more than two binomial sds of 18 points);
* 50 simulated new pulls per held-out point (the truth times the bench's FR scatter)
  inside the ``new_trace`` band: at least 90%;
* Kt and mu inside their 95% intervals in at least 85% of the datasets (3 misses of 21);
  measured: Kt 19 of 21, mu 18 of 21 (under the truth-only coupling law Kt can be
  biased beyond its interval: the fit warns there that Kt rests on the coupling's
  shape, test below);
* on clean data the bands no more than 20% wider than the noise-only model's, and on
  every dataset a mean half-width at the paper's matrix of at most 0.03 in FR
  (measured: kind means 0.0009 to 0.0118, every dataset within 0.03);
* the bench models chosen right: the lag actuator on every bench that has one, the slope
  model on the benches whose actuator is the slope model and nothing blurs the switches,
  and the constant offset wherever the offset does not drift.

What runs where. ``make test`` (CI) fits one dataset per kind, the first of its three
seeds (3k+1), and checks what each dataset must show on its own: the last three points
(precision, useful bands, bench models) and the coupling flag below, each as one test
per kind. The rates (the first three points: held-out FR, new pulls, Kt and mu) are
properties of the 21-dataset study and run in ``make study``
(``IDTOOL_COVERAGE_SEEDS=3``), with their thresholds unchanged: on 7 datasets they
would not be tests. The points of one dataset share its fit, so its 6 held-out points
hit or miss together; even counted as independent, at the nominal 95% the chance of 5
or more misses of 42 (below 90%) is 6% (of 13 of the study's 126: 1%), of a kind below
5 of its 6 points 3% (21% that one of 7 kinds is; below 15 of 18: 1%), and at the
measured miss rates (Kt 2 of 21, mu 3 of 21) 2 misses of 7 (below 85%) come 14% and 26%
of the time. Thresholds that held at that size would be loosened beyond use, so CI
checks the per-dataset properties only.

The study's 21 fits take about 7 minutes on one core, CI's 7 about 2.5: marked slow,
still part of the default run.
"""

from __future__ import annotations

import functools
import os
import warnings

import numpy as np
import pytest

import idtool
from idtool._diagnostic import with_code
from idtool._simulate._departures import DEPARTURE_KINDS, departure_params
from idtool._simulate._simulate import true_friction_ratio

pytestmark = pytest.mark.slow

STUDY_SEEDS_PER_KIND = 3  # the study: kind k takes seeds 3k+1 to 3k+3
# CI runs the first seed of each kind; make study all three (module docstring)
SEEDS_PER_KIND = int(os.environ.get("IDTOOL_COVERAGE_SEEDS", "1"))
HELD_OUT = ([360.0, 560.0], [0.5, 0.6, 0.7])
MATRIX = ([270.0, 450.0, 670.0], [0.5, 0.7])
NEW_PULLS = 50


def seeds_of(kind: str) -> list[int]:
    """The seeds of ``kind`` that this run scores: the first ``SEEDS_PER_KIND`` of its
    three (a kind's seeds do not depend on how many run)."""
    k = DEPARTURE_KINDS.index(kind)
    return [STUDY_SEEDS_PER_KIND * k + s for s in range(1, SEEDS_PER_KIND + 1)]


@functools.cache
def _score(kind: str, seed: int) -> dict:
    params = departure_params(kind, seed)
    dataset, _ = idtool.simulate_bench(params, seed=seed)
    with warnings.catch_warnings():
        # the fit's own warnings (lack of fit, correlations) are part of its report
        warnings.simplefilter("ignore")
        fit = idtool.fit(dataset, seed=0)
        plain = idtool.fit(dataset, seed=0, variability=False) if kind == "clean" else None
    scatter = params.scatter.friction_ratio_sd if params.scatter is not None else 0.0
    rng = np.random.default_rng([seed, 7])
    inside, new_inside = [], []
    for p in fit.predict(*HELD_OUT):
        truth = true_friction_ratio(params, p.normal_load_n, p.amplitude_fraction)
        inside.append(p.ci95[0] <= truth <= p.ci95[1])
        pulls = np.minimum(truth * np.exp(rng.normal(0.0, scatter, NEW_PULLS)), 1.0)
        lo, hi = p.new_trace[1] if p.new_trace is not None else p.ci95
        new_inside.append(float(np.mean((pulls >= lo) & (pulls <= hi))))

    def half_width(f) -> float:
        return float(np.mean([(p.ci95[1] - p.ci95[0]) / 2 for p in f.predict(*MATRIX)]))

    contact = params.contact
    out = {
        "kind": kind,
        "inside": inside,
        "new_inside": new_inside,
        "Kt": fit.estimates["Kt"].ci95[0]
        <= contact.contact_stiffness_n_m
        <= fit.estimates["Kt"].ci95[1],
        "mu": fit.estimates["mu"].ci95[0]
        <= contact.friction_coefficient
        <= fit.estimates["mu"].ci95[1],
        "half_width": half_width(fit),
        "actuator": fit.model.actuator.name,
        "offset": fit.model.offset.name,
        "misspecified": bool(with_code(fit.warnings, "misfit_operating_points")),
    }
    if plain is not None:
        out["half_width_noise_only"] = half_width(plain)
    return out


# the per-dataset checks: one test per kind, each scoring its own kind's datasets (so
# the kinds' fits can run on different xdist workers, see tests/conftest.py)
each_kind = pytest.mark.parametrize("kind", DEPARTURE_KINDS)
# the rates: the whole study's datasets (module docstring)
study_only = pytest.mark.skipif(
    SEEDS_PER_KIND < STUDY_SEEDS_PER_KIND,
    reason="a rate over the study's 3 seeds per kind: make study (IDTOOL_COVERAGE_SEEDS=3)",
)


def scores_of(kind: str) -> list[dict]:
    return [_score(kind, seed) for seed in seeds_of(kind)]


@pytest.fixture(scope="module")
def scores() -> list[dict]:
    out = [s for kind in DEPARTURE_KINDS for s in scores_of(kind)]
    for kind in DEPARTURE_KINDS:  # the table the closing note quotes (pytest -s)
        rows = [s for s in out if s["kind"] == kind]
        inside = sum(sum(s["inside"]) for s in rows)
        print(
            f"{kind:9s} held-out {inside}/{6 * len(rows)}  new pulls "
            f"{100 * np.mean([np.mean(s['new_inside']) for s in rows]):.0f}%  Kt "
            f"{sum(s['Kt'] for s in rows)}/{len(rows)}  mu {sum(s['mu'] for s in rows)}/"
            f"{len(rows)}  half-width {np.mean([s['half_width'] for s in rows]):.4f}  "
            f"actuator {','.join(s['actuator'] for s in rows)}  "
            f"offset {','.join(s['offset'] for s in rows)}"
        )
    return out


@study_only
def test_enough_datasets_of_every_kind(scores):
    assert len(scores) >= 20
    assert {s["kind"] for s in scores} == set(DEPARTURE_KINDS)


@study_only
def test_mean_friction_ratio_bands_cover_held_out_points(scores):
    inside = np.concatenate([s["inside"] for s in scores])
    assert inside.mean() >= 0.90, inside.mean()
    for kind in DEPARTURE_KINDS:
        hits = sum(sum(s["inside"]) for s in scores if s["kind"] == kind)
        assert hits >= 15, (kind, hits)


@study_only
def test_new_trace_bands_hold_new_pulls(scores):
    rate = np.mean([np.mean(s["new_inside"]) for s in scores])
    assert rate >= 0.90, rate


@study_only
def test_kt_interval_covers_the_truth(scores):
    rate = np.mean([s["Kt"] for s in scores])
    assert rate >= 0.85, rate


@study_only
def test_mu_interval_covers_the_truth(scores):
    rate = np.mean([s["mu"] for s in scores])
    assert rate >= 0.85, rate


@each_kind
def test_clean_data_keeps_its_precision(kind):
    for s in scores_of(kind):
        if "half_width_noise_only" in s:
            assert s["half_width"] <= 1.2 * s["half_width_noise_only"], s


@each_kind
def test_bands_stay_useful(kind):
    for s in scores_of(kind):
        assert s["half_width"] <= 0.03, s


@each_kind
def test_the_lag_actuator_is_found_where_there_is_one(kind):
    # lag on every bench that has one; the slope model on the clean benches, whose
    # actuator is the slope model exactly. (On a scattered bench the nested lag model
    # may win: per-pull FR scatter leaves misfit at the switches that a time constant
    # absorbs; seed 5 does, with its bands and Kt still covering.)
    for s in scores_of(kind):
        if s["kind"] in ("actuator", "all"):
            assert s["actuator"] == "lag", s
        if s["kind"] in ("clean", "mains60", "drift"):
            assert s["actuator"] == "slope", s


@each_kind
def test_clean_benches_keep_the_constant_offset(kind):
    for s in scores_of(kind):
        if s["kind"] in ("clean", "actuator", "mains60", "coupling", "scatter"):
            assert s["offset"] == "constant", s


@each_kind
def test_a_coupling_of_another_shape_is_flagged(kind):
    """Where Kt misses its interval (the truth-only coupling), the report says that Kt
    rests on the coupling law's shape: the discrepancy's interval starts above 3% there
    (0.04-0.08) and nowhere else (at most 0.016)."""
    for s in scores_of(kind):
        assert s["misspecified"] == (s["kind"] in ("coupling", "all")), s
