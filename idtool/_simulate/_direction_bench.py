"""Preset simulator parameters for each direction of vibration (issue 30, item 2).

:func:`direction_params` gives a small bench (2 loads x 4 amplitudes, one 2 s ON window
each: 8 traces) whose contact vibrates in the direction asked, on the example's physics
(Dahl contact, mu 0.3, Kt 1e9 N/m, the power-limited coupling): what
``tests/test_direction_auto.py`` and ``benchmarks/study_directions.py`` fit with
``direction="auto"`` to see whether BIC picks the simulated direction and whether Kt and
mu land in the winner's intervals. Several amplitudes per load, because the directions
differ in how the friction ratio falls with the slip amplitude (eqs. of
:mod:`idtool._model._direction_transverse` and :mod:`idtool._model._direction_normal`).
The normal direction needs a larger slip amplitude for the same reduction (gain 0.1
against 0.03: FR 0.45-0.64 over the matrix, against 0.13-0.48 along and 0.35-0.61
transverse); so each bench reduces friction by a measurable amount.
"""

from __future__ import annotations

import json
from typing import Any

from idtool._data._example import example_params_path
from idtool._model._directions import DIRECTIONS
from idtool._simulate._params import BenchParams

__all__ = ["DIRECTION_DESIGN", "DIRECTION_GAINS", "direction_params"]

# The coupling's small-signal gain per direction (module docstring).
DIRECTION_GAINS = {"along": 0.03, "transverse": 0.03, "normal": 0.1}
# The small matrix: 2 loads x 4 amplitudes, one ON window of 2 s, 2 s of sliding before
# and after it, 500 samples per second.
DIRECTION_DESIGN: dict[str, Any] = {
    "normal_loads_n": [270.0, 670.0],
    "amplitude_fractions": [0.3, 0.5, 0.7, 0.9],
    "on_durations_s": [2.0],
    "sliding_before_s": 2.0,
    "sliding_after_s": 2.0,
    "sample_rate_hz": 500.0,
}


def direction_params(direction: str) -> BenchParams:
    """The small bench of the module docstring with its contact vibrating in
    ``direction`` (a name of :data:`idtool.DIRECTIONS`)."""
    name = DIRECTIONS.get(direction).name
    p = json.loads(example_params_path().read_text())
    p["name"] = f"direction-{name}"
    p["description"] = f"the example's physics on 8 traces, vibration {name}"
    p["contact"]["direction"] = name
    p["coupling"]["gain"] = DIRECTION_GAINS.get(name, DIRECTION_GAINS["along"])
    p["experiments"].update(DIRECTION_DESIGN)
    return BenchParams.from_dict(p)
