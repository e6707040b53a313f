"""Answers as tables: predictions of the friction ratio and amplitudes for a target
reduction, with where their draws came from and what to beware of (extrapolation).

Both :class:`idtool.Fit` and :class:`idtool.Posterior` answer through
:func:`predict_table` and :func:`amplitude_table`.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Iterator, Sequence
from typing import Any, Generic, TypeVar

import numpy as np

from idtool._data._blocks import FitData
from idtool._diagnostic import reworded
from idtool._errors import IdtoolError
from idtool._predict._amplitude import AmplitudeFor, amplitude_for_reduction
from idtool._predict._mixture import law_disagreement_notes
from idtool._predict._predict import (
    Draws,
    Prediction,
    extrapolation_notes,
    predict_friction_ratio,
)

__all__ = ["Amplitudes", "Predictions", "amplitude_table", "predict_table"]

R = TypeVar("R", Prediction, AmplitudeFor)


@dataclasses.dataclass(frozen=True)
class _Rows(Generic[R]):
    """Rows of answers, where their draws came from, and what to beware of."""

    rows: tuple[R, ...]
    source: str  # "posterior" or "fit covariance"
    note: str
    warnings: tuple[str, ...]

    def __iter__(self) -> Iterator[R]:
        return iter(self.rows)

    def __len__(self) -> int:
        return len(self.rows)

    def __getitem__(self, i: int) -> R:
        return self.rows[i]

    def to_dict(self) -> dict[str, Any]:
        return {
            "source": self.source,
            "note": self.note,
            "rows": [r.to_dict() for r in self.rows],
            "warnings": list(self.warnings),
        }

    def to_frame(self):
        """A pandas DataFrame, one row per answer: nested fields as ``a.b`` columns,
        each 95% interval as ``a.ci95.lo`` and ``a.ci95.hi``, out-of-reach values NaN."""
        import pandas as pd

        return pd.DataFrame([_flat(r.to_dict()) for r in self.rows])


def _flat(doc: dict[str, Any], prefix: str = "") -> dict[str, Any]:
    out: dict[str, Any] = {}
    for key, value in doc.items():
        name = prefix + key
        if isinstance(value, dict):
            out |= _flat(value, name + ".")
        elif isinstance(value, list) and len(value) == 2:
            out[name + ".lo"], out[name + ".hi"] = (np.nan if v is None else v for v in value)
        else:
            out[name] = np.nan if value is None else value
    return out


class Predictions(_Rows[Prediction]):
    """Friction ratio (median, 95% band) and reduction [%] at operating points."""


class Amplitudes(_Rows[AmplitudeFor]):
    """The amplitude fraction needed for a target reduction, per load and speed."""


def _numbers(name: str, x: float | Sequence[float], lo: float, hi: float) -> list[float]:
    values = [float(v) for v in np.atleast_1d(np.asarray(x, float))]
    for v in values:
        if not (lo < v <= hi) or not np.isfinite(v):
            raise IdtoolError(f"{name} = {v:g}: must lie in ({lo:g}, {hi:g}]")
    return values


def _speeds(data: FitData, speed_m_s) -> list[float]:
    if speed_m_s is not None:
        return _numbers("speed_m_s", speed_m_s, 0.0, np.inf)
    seen = sorted(set(np.asarray(data.pull_speed_m_s).tolist()))
    if len(seen) > 1:
        raise IdtoolError(f"the fit has several pull speeds ({seen}); give speed_m_s")
    return seen


def predict_table(
    draws: Draws,
    data: FitData,
    load_n: float | Sequence[float],
    amplitude: float | Sequence[float],
    speed_m_s: float | Sequence[float] | None = None,
) -> Predictions:
    """FR (median, 95% band) and reduction [%] over loads [N] x amplitude fractions x
    speeds [m/s] (default: the fitted speed), with extrapolation warnings."""
    loads = _numbers("load_n", load_n, 0.0, np.inf)
    amps = _numbers("amplitude", amplitude, 0.0, 1.0)
    speeds = _speeds(data, speed_m_s)
    rows = predict_friction_ratio(draws, loads, amps, speeds)
    notes = extrapolation_notes(data, loads, amps, speeds)
    notes += law_disagreement_notes(rows, draws.law_weights)
    return Predictions(tuple(rows), draws.source, draws.note, tuple(notes))


def amplitude_table(
    draws: Draws,
    data: FitData,
    reduction_percent: float,
    load_n: float | Sequence[float],
    speed_m_s: float | Sequence[float] | None = None,
) -> Amplitudes:
    """The amplitude fraction for ``reduction_percent`` at each load [N] x speed [m/s],
    with its 95% band or why it is out of reach; warns on extrapolation."""
    if not 0.0 < reduction_percent < 100.0:
        raise IdtoolError(f"reduction_percent = {reduction_percent:g}: give one in (0, 100)")
    loads = _numbers("load_n", load_n, 0.0, np.inf)
    speeds = _speeds(data, speed_m_s)
    rows = amplitude_for_reduction(draws, reduction_percent, loads, speeds)
    needed = [a.amplitude[0] for a in rows if a.reachable]
    notes = extrapolation_notes(data, loads, (), speeds)
    notes += [
        reworded(
            n,
            n.replace("amplitude fraction", "needed amplitude fraction"),
            quantity="needed amplitude fraction",
        )
        for n in extrapolation_notes(data, (), needed, ())
    ]
    return Amplitudes(tuple(rows), draws.source, draws.note, tuple(notes))
