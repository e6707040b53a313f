"""Coverage on the benches whose levels move within their plateaus (issue 26, item 4): a
fading horn and a creeping friction level (idtool._simulate._departures.DRIFT_KINDS), on
the paper's matrix (24 traces), fitted with the defaults a new user gets
(``idtool.fit(dataset)``), which try the relaxing ON level and the creeping level when
the steady fit's plateaus drift.

One seed per kind, the study's first (``benchmarks/study_departures.py``: seed 100 k + 1
for the k-th kind), to keep the default run short (about a minute on one core); the
study runs more (``--kinds fading,creep --seeds 3``). Scored against the truth:

* the cold-horn friction ratio (the contact model's at the commanded amplitude, which
  the relaxing model's FR is) at 6 held-out operating points (360 and 560 N x 50, 60,
  70%) inside its 95% band: at least 11 of the 12 (the issue's 90%), and at least 5 of
  6 per kind. Before the level models: 0 of 6 on the creep bench (the drifting offset
  took up the creep and left every ON level low), and bands 0.1-0.5 wide around a
  wrong estimate on the fading bench;
* Kt and mu inside their 95% intervals;
* the level model chosen (relaxing on the fading bench, creeping on the creep bench), a
  drift warning on both, and the band at the paper's matrix at most 0.03 in FR (its
  half-width).
"""

from __future__ import annotations

import warnings

import numpy as np
import pytest

import idtool
from idtool._diagnostic import DRIFT_CODES, with_code
from idtool._simulate._departures import DEPARTURE_KINDS, DRIFT_KINDS, departure_params
from idtool._simulate._simulate import true_friction_ratio

pytestmark = pytest.mark.slow

HELD_OUT = ([360.0, 560.0], [0.5, 0.6, 0.7])
MATRIX = ([270.0, 450.0, 670.0], [0.5, 0.7])
LEVEL_MODEL = {"fading": "relaxing", "creep": "creeping"}


def _seed(kind: str) -> int:
    """The study's first seed of ``kind`` (benchmarks/study_departures.py)."""
    return 100 * (DEPARTURE_KINDS + DRIFT_KINDS).index(kind) + 1


def _score(kind: str) -> dict:
    seed = _seed(kind)
    params = departure_params(kind, seed)
    dataset, _ = idtool.simulate_bench(params, seed=seed)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the fit's own warnings are scored below
        fit = idtool.fit(dataset, seed=0)
    inside, truths = [], []
    for p in fit.predict(*HELD_OUT):
        truth = true_friction_ratio(params, p.normal_load_n, p.amplitude_fraction)
        truths.append(truth)
        inside.append(p.ci95[0] <= truth <= p.ci95[1])
    contact = params.contact
    truth = {"Kt": contact.contact_stiffness_n_m, "mu": contact.friction_coefficient}
    out = {
        "kind": kind,
        "inside": inside,
        "level": fit.model.level.name,
        "drift_warning": bool(with_code(fit.warnings, *DRIFT_CODES)),
        "half_width": float(np.mean([(p.ci95[1] - p.ci95[0]) / 2 for p in fit.predict(*MATRIX)])),
    }
    for name, value in truth.items():
        est = fit.estimates[name]
        out[name] = est.ci95[0] <= value <= est.ci95[1]
    print(
        f"{kind:7s} seed {seed}: held-out {sum(inside)}/6, half-width {out['half_width']:.4f}, "
        f"level {out['level']}, Kt {out['Kt']}, mu {out['mu']}"
    )
    return out


@pytest.fixture(scope="module")
def scores() -> list[dict]:
    return [_score(kind) for kind in DRIFT_KINDS]


def test_every_drift_kind_is_scored(scores):
    assert {s["kind"] for s in scores} == set(DRIFT_KINDS) == set(LEVEL_MODEL)


def test_held_out_friction_ratios_inside_their_bands(scores):
    inside = np.concatenate([s["inside"] for s in scores])
    assert inside.sum() >= 11, inside
    for s in scores:
        assert sum(s["inside"]) >= 5, s


def test_kt_and_mu_intervals_cover_the_truth(scores):
    for s in scores:
        assert s["Kt"] and s["mu"], s


def test_the_level_model_is_chosen_and_the_drift_reported(scores):
    for s in scores:
        assert s["level"] == LEVEL_MODEL[s["kind"]], s
        assert s["drift_warning"], s


def test_bands_stay_useful(scores):
    for s in scores:
        assert s["half_width"] <= 0.03, s
