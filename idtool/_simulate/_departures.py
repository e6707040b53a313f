"""Preset simulator parameters with the bench's departures from the fit's model.

:func:`departure_params` gives, for each kind of departure, parameters on the paper's
experiment matrix (the shipped example's: loads 270, 450 and 670 N, amplitudes 50% and
70%, ON times 0.5, 1, 2 and 2.5 s; 24 traces) with the departure switched on at a
moderate, realistic size:

* ``"clean"``: no departure (the simulated bench is the fit's model plus noise);
* ``"scatter"``: pull-to-pull scatter, FR log-sd 0.03 and mu log-sd 0.007;
* ``"actuator"``: a rate-limited first-order-lag actuator (time constant 0.15 s, rate
  limit 100 N/s, which governs the first part of every switching deeper than 15 N);
* ``"mains60"``: 60 Hz hum sampled at 2000 Hz;
* ``"drift"``: a linear load-cell offset drift, rate sd 0.05 N/s (about 0.6 N over a trace);
* ``"coupling"``: the truth-only coupling ``a = gain alpha A_max exp(-N / load_scale_n)``;
* ``"ceiling"``: the truth-only coupling ``a = gain A_max c tanh(alpha / c)``, its ceiling
  ``c = sqrt(ceiling_load_n / N)`` falling as ``N^-1/2`` through a tanh knee (another
  saturating shape than any the fit ships; :mod:`idtool._simulate._truth_coupling`);
* ``"fading"``: a horn whose slip amplitude fades by up to 20% within each ON window
  (time constant 1.5 s: 16% lost by the end of a 2.5 s window, so the ON level rises
  through it; :mod:`idtool._simulate._plateau_drift`);
* ``"creep"``: mu creeping by 0.2% of itself per second of sliding (1.5-2% over a trace,
  2-3 N at 670 N: eight times the offset drift's newtons per second at 450 N);
* ``"all"``: scatter, actuator, mains60, drift and coupling together (a paper-like bench:
  the paper's lab is on 60 Hz mains). Not the ceiling coupling (a bench has one coupling
  law), nor the fading horn nor the creeping level: the
  coverage studies run "all" as a bench the fit's model should still cover without the
  level models, and those two move the levels within their plateaus, which only the
  level models the fit tries when its plateaus drift represent
  (:mod:`idtool._model._level_model`; the fit warns of them too,
  :mod:`idtool._fit._plateau_drift`).

The true contact and coupling (mu, Kt, gain and load scale) are drawn from ``seed`` in
narrow ranges around the example's values (below), the same for every kind, so a coverage
study over seeds checks more than one truth and comparing kinds at one seed isolates the
departure. Simulate with :func:`idtool.simulate_bench`; the truth it returns has what a
coverage test scores against (:func:`idtool._simulate._simulate.true_friction_ratio` for
held-out operating points).
"""

from __future__ import annotations

import json
import math
from typing import Any

import numpy as np

from idtool._data._example import example_params_path
from idtool._errors import IdtoolError
from idtool._simulate._params import BenchParams

__all__ = [
    "ALL_KINDS",
    "DEPARTURE_KINDS",
    "DESIGNS",
    "DRIFT_KINDS",
    "SHAPE_KINDS",
    "departure_params",
    "with_departure",
]

# The departures the fit's model options cover (the coverage studies score these).
DEPARTURE_KINDS = ("clean", "scatter", "actuator", "mains60", "drift", "coupling", "all")
# Levels that move within their plateaus: the fit detects them and warns
# (idtool._fit._plateau_drift), then models them with the relaxing ON level and the
# creeping level (idtool._model._level_model); their coverage is scored apart
# (tests/test_coverage_fading.py), since the steady fit alone does not cover them.
DRIFT_KINDS = ("fading", "creep")
# What "all" turns on (module docstring).
ALL_KINDS = frozenset(DEPARTURE_KINDS) - {"clean", "all"}
# A coupling whose shape no shipped law has and which the fit's checks do not see: the
# power limit and the load-power law both fit its levels (the latter to within their
# noise) with Kt 0.3-8x off its truth, outside the interval, since Kt is read through the
# coupling's shape (idtool._fit._run.kt_through_coupling). Measured in the study (make
# study), not asserted by the coverage tests: no model option represents it yet.
SHAPE_KINDS = ("ceiling",)

# Pull-to-pull scatter: log-normal sd of the per-trace FR and mu multipliers [-].
SCATTER = {"friction_ratio_sd": 0.03, "friction_coefficient_sd": 0.007}
# The lag actuator: 0.15 s time constant; its 100 N/s rate limit (the example's slope)
# governs the first part of any switching deeper than 100 N/s * 0.15 s = 15 N, i.e. most
# of every ON dip (40 to 120 N deep) and the whole start-up but its last 15 N.
LAG_ACTUATOR = {"model": "lag", "time_constant_s": 0.15, "rate_limit_n_s": 100.0}
MAINS_60_HZ = 60.0  # [Hz], North American mains
SAMPLE_RATE_2K_HZ = 2000.0  # [Hz]
OFFSET_DRIFT_SD_N_S = 0.05  # [N/s]: a 12 s trace drifts by about 0.6 N, the white-noise sd
# The fading horn: a transducer warming over a window loses a tenth to a third of its
# amplitude within seconds; 20% at 1.5 s is the middle of that.
HORN_FADING = {"fade_fraction": 0.2, "fade_time_constant_s": 1.5}
LEVEL_CREEP_PER_S = 0.002  # [1/s]: mu rises 0.2% of itself per second of sliding
# The truth-only coupling, calibrated to the example's power-limited one: the same slip
# amplitude at 270 and 670 N for 50% amplitude (so FR about 0.15 and 0.41 there, the
# paper's reductions), but without the power limit (70% now gives clearly more reduction).
TRUTH_ONLY_COUPLING = {"law": "load_exponential", "gain": 0.032, "load_scale_n": 600.0}
# The truth-only saturating coupling, calibrated to the example's power-limited one at
# 450 N (slip amplitudes 0.63 and 0.65 um at 50 and 70%, against 0.62 and 0.66): 11%
# less at 270 N and 19% more at 670 N, where its ceiling falls more slowly with the load.
CEILING_COUPLING = {"law": "tanh_ceiling", "gain": 0.03, "ceiling_load_n": 30.0}

# The experiment matrices the presets run on (overrides of the example's "experiments").
# "paper": the example's (3 loads x 2 amplitudes x ON 0.5/1/2/2.5 s at 25 mm/s). The
# fit reads Kt there only through the coupling law's shape (idtool._fit._run,
# kt_through_coupling). "two-speed": the same 24 traces as 3 x 2 x ON 1/2.5 s at half
# and twice the paper's speed: two velocity ratios at one slip amplitude give that
# amplitude and Kt at each load and amplitude whatever the coupling law (VR 0.16 and 0.63
# at the example's 0.63 um, 450 N; both below 1, where FR depends on VR and Lambda).
DESIGNS: dict[str, dict[str, Any]] = {
    "paper": {},
    "two-speed": {"on_durations_s": [1.0, 2.5], "pull_speed_m_s": [0.0125, 0.05]},
}

# Half-widths of the seeded truth's log-uniform ranges around the example's values: mu
# 0.27-0.33, Kt 0.67e9-1.5e9 N/m, gain +-10%, load scales +-20%. Narrow enough that Lambda
# stays in 1-30 (Kt identifiable) and FR in 0.1-0.9 at every operating point of the matrix.
TRUTH_LOG_HALF_WIDTH = {
    "friction_coefficient": 0.1,
    "contact_stiffness_n_m": 0.4,
    "gain": 0.1,
    "load_scale": 0.2,
}
# Salt of the truth's random stream, so it is not simulate_bench's stream of the same seed.
_TRUTH_STREAM = 0x7472757468  # "truth"


def departure_params(kind: str, seed: int, design: str = "paper") -> BenchParams:
    """Simulator parameters with the departure ``kind`` (one of :data:`DEPARTURE_KINDS`,
    :data:`DRIFT_KINDS` or :data:`SHAPE_KINDS`) on the experiment matrix ``design`` (one
    of :data:`DESIGNS`: ``"paper"``, the example's 24 traces at one pull speed, or
    ``"two-speed"``, 24 traces at two).

    ``seed`` (an integer >= 0) draws the true mu, Kt, coupling gain and load scale
    (module docstring); simulate with ``idtool.simulate_bench(params, seed)``.

    Raises:
        IdtoolError: an unknown ``kind`` or ``design``, or a bad ``seed``.
    """
    if kind not in DEPARTURE_KINDS + DRIFT_KINDS + SHAPE_KINDS:
        kinds = ", ".join(DEPARTURE_KINDS + DRIFT_KINDS + SHAPE_KINDS)
        raise IdtoolError(f"departure kind {kind!r}: use one of {kinds}")
    if design not in DESIGNS:
        raise IdtoolError(f"design {design!r}: use one of {', '.join(DESIGNS)}")
    if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
        raise IdtoolError(f"seed {seed!r}: give an integer >= 0")
    p: dict[str, Any] = json.loads(example_params_path().read_text())
    p["experiments"] |= DESIGNS[design]
    truth = _truth_factors(seed)
    p["contact"]["friction_coefficient"] *= truth["friction_coefficient"]
    p["contact"]["contact_stiffness_n_m"] *= truth["contact_stiffness_n_m"]
    with_departure(p, kind, truth)
    p["name"] = f"departures-{kind}-seed{seed}"
    p["description"] = (
        f"Simulated bench with departure '{kind}' from the fit's model "
        f"(idtool._simulate._departures, seed {seed}); the truth is in true_parameters.json."
    )
    return BenchParams.from_dict(p, f"departure preset {kind!r}")


def with_departure(p: dict[str, Any], kind: str, truth: dict[str, float] | None = None) -> None:
    """Switch the departure ``kind`` on in the simulator document ``p`` (in place), at
    the presets' sizes (module docstring); ``truth``: the seeded multipliers of the
    coupling's gain and load scale (default 1: the coupling as ``p`` has it, or the
    truth-only law's calibrated constants). ``"clean"`` changes nothing but the seeded
    coupling. The simulation study applies it to a truth drawn from a fit
    (:mod:`idtool._study`).

    Raises:
        IdtoolError: an unknown ``kind``.
    """
    if kind not in DEPARTURE_KINDS + DRIFT_KINDS + SHAPE_KINDS:
        kinds = ", ".join(DEPARTURE_KINDS + DRIFT_KINDS + SHAPE_KINDS)
        raise IdtoolError(f"departure kind {kind!r}: use one of {kinds}")
    truth = truth or {"load_scale": 1.0, "gain": 1.0}
    on = {kind} if kind != "all" else set(ALL_KINDS)
    if "coupling" in on:
        p["coupling"] = dict(TRUTH_ONLY_COUPLING)
        p["coupling"]["load_scale_n"] *= truth["load_scale"]
    elif kind == "ceiling":
        p["coupling"] = dict(CEILING_COUPLING)
        p["coupling"]["ceiling_load_n"] *= truth["load_scale"]
    elif "power_load_n" in p["coupling"]:
        p["coupling"]["power_load_n"] *= truth["load_scale"]
    if "gain" in p["coupling"]:
        p["coupling"]["gain"] *= truth["gain"]
    if "scatter" in on:
        p["scatter"] = dict(SCATTER)
    if "actuator" in on:
        p["actuator"] = {"pull_start_s": p["actuator"]["pull_start_s"], **LAG_ACTUATOR}
    if "mains60" in on:
        p["load_cell"]["mains_frequency_hz"] = MAINS_60_HZ
        p["experiments"]["sample_rate_hz"] = SAMPLE_RATE_2K_HZ
    if "drift" in on:
        p["load_cell"]["offset_drift_sd_n_s"] = OFFSET_DRIFT_SD_N_S
    if "fading" in on:
        p["horn_fading"] = dict(HORN_FADING)
    if "creep" in on:
        p["contact"]["level_creep_per_s"] = LEVEL_CREEP_PER_S


def _truth_factors(seed: int) -> dict[str, float]:
    """Seeded log-uniform multipliers of the example's mu, Kt, coupling gain and load scale
    (the power limit's P, or the truth-only law's load scale)."""
    rng = np.random.default_rng([seed, _TRUTH_STREAM])
    w = TRUTH_LOG_HALF_WIDTH
    return {k: math.exp(rng.uniform(-w[k], w[k])) for k in w}  # fixed order: w's keys
