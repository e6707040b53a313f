"""Warnings for legal values that look like the wrong unit (kN for N, ms for s, ...).

The bench (model notes §5) fixes the scales: loads of hundreds of N, pull speeds of a few
cm/s, a 20 kHz horn with an amplitude of tens of µm, pulls of about 12 s, and a pull force
``mu N`` with a friction coefficient between about 0.02 and 3. A value legal by the
schema but far off these scales is reported as a warning with the likely conversion.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import Any

import numpy as np

from idtool._errors import Problem

__all__ = ["force_warnings", "metadata_warnings", "time_warnings"]

MU_PLAUSIBLE = (0.02, 3.0)  # friction coefficients a seat-belt contact can have
LONGEST_PULL_S = 600.0  # a 12-inch pull at 25 mm/s lasts 12 s


def _number(value: object) -> float | None:
    ok = isinstance(value, int | float) and not isinstance(value, bool) and np.isfinite(value)
    return float(value) if ok else None  # type: ignore[arg-type]


def _checks() -> tuple[tuple[str, Callable[[float], bool], str], ...]:
    """(field, test on the value, message with ``{v}``) for each unit slip we recognise."""
    return (
        (
            "vibration_frequency_hz",
            lambda v: v < 1000.0,
            "{v:g} Hz is not ultrasonic: if it is in kHz, write {k:g} ({v:g} * 1000)",
        ),
        (
            "max_amplitude_m",
            lambda v: v > 1e-3,
            "a horn amplitude of {v:g} m is implausible: if it is in µm, write {u:g} "
            "({v:g} * 1e-6)",
        ),
        (
            "normal_load_n",
            lambda v: v < 5.0,
            "a normal load of {v:g} N is implausibly small for the bench: if it is in kN, "
            "write {k:g} ({v:g} * 1000)",
        ),
        (
            "pull_speed_m_s",
            lambda v: v > 1.0,
            "a pull speed of {v:g} m/s is implausible: if it is in mm/s, write {m:g} "
            "({v:g} / 1000)",
        ),
    )


def metadata_warnings(document: object, file: str) -> list[Problem]:
    """Unit warnings for the rig and trace fields of a parsed ``dataset.json``."""
    if not isinstance(document, Mapping):
        return []
    places: list[tuple[str, Mapping[str, Any]]] = []
    if isinstance(document.get("rig"), Mapping):
        places.append(("rig", document["rig"]))
    traces = document.get("traces")
    if isinstance(traces, list):
        places += [(f"traces[{i}]", t) for i, t in enumerate(traces) if isinstance(t, Mapping)]
    problems = []
    for where, entry in places:
        for field, looks_wrong, message in _checks():
            v = _number(entry.get(field))
            if v is not None and v > 0 and looks_wrong(v):
                text = message.format(v=v, k=v * 1000, u=v * 1e-6, m=v / 1000)
                problems.append(
                    Problem(text, file=file, column=f"{where}.{field}", severity="warning")
                )
    return problems


def force_warnings(
    force_n: np.ndarray, on: np.ndarray, normal_load_n: object, file: str, column: str
) -> list[Problem]:
    """Warn when the OFF force level cannot be ``mu N`` for any plausible mu.

    The OFF level is the 90th percentile of the samples with ultrasound OFF: robust to the
    start-up ramp (below it) and to noise.
    """
    load = _number(normal_load_n)
    off = force_n[~on]
    if load is None or load <= 0 or off.size < 10:
        return []
    level = float(np.percentile(off, 90))
    ratio = level / load
    lo, hi = MU_PLAUSIBLE
    if level <= 0:
        text = (
            f"the force with ultrasound OFF is negative (about {level:.3g}): the pull force "
            "should be positive; flip the sign of the column"
        )
    elif ratio < lo:
        text = (
            f"the force with ultrasound OFF (about {level:.3g}) is only {ratio:.2%} of the "
            f"normal load {load:g} N, below any plausible friction coefficient ({lo}-{hi}): "
            "if force_n is in kN, multiply it by 1000"
        )
    elif ratio > hi:
        text = (
            f"the force with ultrasound OFF (about {level:.3g}) is {ratio:.3g} times the "
            f"normal load {load:g} N, above any plausible friction coefficient ({lo}-{hi}): "
            "check that force_n is in N and normal_load_n in N"
        )
    else:
        return []
    return [Problem(text, file=file, column=column, severity="warning")]


def time_warnings(time_s: np.ndarray, file: str, column: str) -> list[Problem]:
    """Warn when a trace is far longer than a pull: time in ms rather than s."""
    span = float(time_s[-1] - time_s[0])
    if span <= LONGEST_PULL_S:
        return []
    text = (
        f"the trace spans {span:g} s but a pull lasts about 12 s: if time_s is in ms, "
        "divide it by 1000"
    )
    return [Problem(text, file=file, column=column, severity="warning")]
