"""Pulls at two speeds pin Kt whatever the coupling law (issue 26, item 3).

FR depends on ``VR = v / (a w)`` and ``Lambda = Kt a / (mu N)`` alone (notes §4), and
the slip amplitude ``a`` is not measured: at one pull speed Kt is read through the
coupling law's shape. Two speeds at one load and amplitude give two friction ratios at
one ``a``: the simulator's two-speed design, the fit's detection of it and its default
coupling choice there.
"""

from __future__ import annotations

import copy
import json
import math
import warnings

import numpy as np
import pytest

import idtool
from idtool import BenchParams
from idtool._data._design import speed_resolved_pairs
from idtool._data._example import example_params_path
from idtool._errors import IdtoolError
from idtool._fit._run import kt_through_coupling
from idtool._simulate._departures import departure_params

SPEEDS = (0.0125, 0.05)


@pytest.fixture(scope="module")
def two_speed_ceiling():
    """A bench whose coupling has a shape no shipped law has (the ceiling departure),
    pulled at 12.5 and 50 mm/s."""
    params = departure_params("ceiling", 801, "two-speed")
    dataset, truth = idtool.simulate_bench(params, seed=801)
    return params, dataset, truth


def test_two_speed_design_pulls_every_point_at_both_speeds(two_speed_ceiling):
    params, dataset, truth = two_speed_ceiling
    assert params.experiments.pull_speeds_m_s == SPEEDS
    speeds = sorted({t.pull_speed_m_s for t in dataset.traces})
    assert speeds == list(SPEEDS)
    assert len(dataset.traces) == 24
    assert all(t.id.endswith(("_V12.5", "_V50")) for t in dataset.traces)
    by_pair: dict[tuple[float, float], list] = {}
    for op in truth.operating_points:
        by_pair.setdefault((op.normal_load_n, op.amplitude_fraction), []).append(op)
    assert len(by_pair) == 6
    w = 2.0 * math.pi * params.rig.vibration_frequency_hz
    for slow, fast in by_pair.values():
        # a kinematic coupling does not depend on the speed: one slip amplitude, and the
        # velocity ratio in proportion to the speed
        assert slow.slip_amplitude_m == fast.slip_amplitude_m
        assert slow.velocity_ratio == pytest.approx(SPEEDS[0] / (slow.slip_amplitude_m * w))
        assert fast.velocity_ratio / slow.velocity_ratio == pytest.approx(4.0, rel=1e-12)
        # FR rises with VR (notes §3: FR is 1 for VR >= 1)
        assert slow.friction_ratio < fast.friction_ratio <= 1.0
    # each trace records its own speed
    for trace in truth.traces:
        assert trace.pull_speed_m_s == float(trace.id.rsplit("_V", 1)[1]) / 1000.0


def test_several_speeds_round_trip_and_are_checked():
    document = json.loads(example_params_path().read_text())
    document["experiments"]["pull_speed_m_s"] = list(SPEEDS)
    params = BenchParams.from_dict(copy.deepcopy(document))
    assert params.experiments.pull_speeds_m_s == SPEEDS
    assert params.to_dict() == document
    # one speed stays a number, as before
    single = BenchParams.from_dict(json.loads(example_params_path().read_text()))
    assert single.experiments.pull_speeds_m_s == (0.025,)
    for bad in ([], [0.025, -0.01], [0.025, 0.025]):
        document["experiments"]["pull_speed_m_s"] = bad
        with pytest.raises(IdtoolError, match="invalid simulator parameters") as err:
            BenchParams.from_dict(document)
        assert "pull_speed_m_s" in str(err.value.problems)
    with pytest.raises(IdtoolError, match="design 'three-speed'"):
        departure_params("clean", 1, "three-speed")


def test_speed_resolved_pairs():
    loads = np.array([270.0, 270.0, 450.0, 450.0, 670.0, 670.0])
    alphas = np.array([0.5, 0.5, 0.5, 0.7, 0.0, 0.0])
    speeds = np.array([0.0125, 0.05, 0.025, 0.025, 0.0125, 0.05])
    # 450 N has two amplitudes at one speed each; 670 N has no ultrasound
    assert speed_resolved_pairs(loads, alphas, speeds) == [(270.0, 0.5)]
    assert speed_resolved_pairs(loads, alphas, np.full(6, 0.025)) == []


def test_the_notes_say_what_kt_rests_on():
    one = kt_through_coupling("power-limited")
    assert one.startswith("Kt is read through the power-limited coupling law")
    assert "two speeds" in one
    two = kt_through_coupling("load-power", [(270.0, 0.5), (450.0, 0.7)])
    assert two.startswith(
        "Kt is pinned by pulls at two or more speeds (270 N at 50%, 450 N at 70%)"
    )


def test_default_fit_of_a_two_speed_bench_holds_kt_under_a_foreign_coupling(two_speed_ceiling):
    """At one speed every shipped law misses this bench's Kt outside its interval (the
    load-power law 1.5-3.1x, the power limit 8x or at its bound; docs/model.md). At two,
    the default fit tries the power limit and the load-power law, BIC keeps the latter,
    and its 95% interval holds the truth (0.94-0.99x truth on seeds 801-803 and 901)."""
    params, dataset, _ = two_speed_ceiling
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the misfit and correlation warnings are expected
        fit = idtool.fit(dataset, seed=0)
    assert set(fit.coupling_laws) == {"power-limited", "load-power"}
    assert fit.model.coupling.name == "load-power"
    kt = fit.estimates["Kt"]
    truth = params.contact.contact_stiffness_n_m
    assert kt.ci95[0] <= truth <= kt.ci95[1]
    # an interval, not a statement over decades: the speeds pin Kt
    assert math.log10(kt.ci95[1] / kt.ci95[0]) < 0.3
    assert any(n.startswith("Kt is pinned by pulls at two or more speeds") for n in fit.notes)
    # the operating points keep their speeds: FR at the slow one below the fast one's
    slow, fast = fit.predict(450.0, 0.5, list(SPEEDS))
    assert slow.median < fast.median
