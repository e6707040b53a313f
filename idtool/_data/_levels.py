"""Steady-state friction tables, a dataset of kind ``levels``: load, check, write.

A tribometer study (pin-on-disc, reciprocating) publishes the mean friction with the
vibration OFF and ON at each condition, with repeats. Such a dataset is a folder holding
one ``dataset.json`` (``"kind": "levels"``, schema ``datasets_schema/levels_table.schema.json``)
whose ``rows`` are the measurements in SI units: normal load [N], vibration amplitude
[m] (and the commanded fraction, if the table gave one), vibration frequency [Hz],
sliding speed [m/s], OFF and ON friction (force [N] or coefficient [-], as ``friction``
says), optional standard errors of each, an optional repeat id and, optionally on every
row, when it was measured [s] (the fit then lets the horn's output drift over the
campaign: :mod:`idtool._levels._model`).
``idtool import-levels`` (:func:`idtool._data._levels_read.import_levels`) writes one
from a CSV table with units in its headers.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
from pathlib import Path
from typing import Any

import numpy as np

from idtool._data._paths import DATASET_FILE
from idtool._data._schema import LEVELS_SCHEMA, schema_problems
from idtool._errors import IdtoolError, Problem

__all__ = ["KIND", "LevelsTable", "is_levels_dataset", "levels_from_document", "load_levels"]

KIND = "levels"
_NUMBERS = (
    "normal_load_n",
    "amplitude_m",
    "vibration_frequency_hz",
    "sliding_speed_m_s",
    "off",
    "on",
)
_OPTIONAL = ("amplitude_fraction", "off_se", "on_se", "time_s")


@dataclasses.dataclass(frozen=True, eq=False)
class LevelsTable:
    """A steady-state friction table (module docstring), one array entry per row.

    Attributes:
        name, material: as in ``dataset.json``.
        friction: ``"force"`` (OFF and ON in N) or ``"coefficient"`` ([-]).
        normal_load_n: normal load [N].
        amplitude_m: vibration amplitude [m].
        amplitude_fraction: commanded fraction of the rig's maximum [-] (NaN: not given).
        vibration_frequency_hz: vibration frequency [Hz].
        sliding_speed_m_s: sliding speed [m/s].
        off, on: friction OFF and ON (N or -, as ``friction``).
        off_se, on_se: their standard errors (NaN: not given).
        repeat: repeat id per row ("" if none).
        time_s: when each row was measured [s], any origin (NaN on every row, or
            empty: not given; given on some rows only is an error).
        max_amplitude_m: the rig's amplitude at 100% command [m], or None.
        source: citation text ("" if none).
        path: the folder, or None for a table made in memory.
        sha256: SHA-256 of ``dataset.json``'s bytes (of the document, in memory).
    """

    name: str
    material: str
    friction: str
    normal_load_n: np.ndarray
    amplitude_m: np.ndarray
    amplitude_fraction: np.ndarray
    vibration_frequency_hz: np.ndarray
    sliding_speed_m_s: np.ndarray
    off: np.ndarray
    on: np.ndarray
    off_se: np.ndarray
    on_se: np.ndarray
    repeat: tuple[str, ...]
    time_s: np.ndarray = dataclasses.field(default_factory=lambda: np.empty(0))
    max_amplitude_m: float | None = None
    source: str = ""
    description: str = ""
    path: Path | None = None
    sha256: str = ""

    def __post_init__(self):
        n = np.size(self.off)
        if np.size(self.time_s) == 0:  # not given
            object.__setattr__(self, "time_s", np.full(n, np.nan))
        for name in (*_NUMBERS, *_OPTIONAL):
            value = np.asarray(getattr(self, name), float)
            if value.shape != (n,):
                raise IdtoolError(f"{name} has shape {value.shape}; off has ({n},)")
            object.__setattr__(self, name, value)
        if len(self.repeat) != n:
            raise IdtoolError(f"repeat has {len(self.repeat)} entries; off has {n}")
        if self.friction not in ("force", "coefficient"):
            raise IdtoolError(f"friction {self.friction!r}: say 'force' or 'coefficient'")
        given = np.isfinite(self.time_s)
        if given.any() and not given.all():
            raise IdtoolError(
                f"time_s is given on {int(given.sum())} of {n} rows: give every row's time or none"
            )

    @property
    def has_times(self) -> bool:
        """Every row's measurement time is given, and they are not all the same."""
        return bool(np.all(np.isfinite(self.time_s)) and np.ptp(self.time_s) > 0.0)

    @property
    def campaign_position(self) -> np.ndarray:
        """Each row's place in the campaign, ``(t - t_mid) / (t_last - t_first)`` in
        [-1/2, 1/2] with ``t_mid`` the campaign's middle (0 on every row without
        :attr:`has_times`): the horn drift's clock (:mod:`idtool._levels._model`)."""
        if not self.has_times:
            return np.zeros(self.n_rows)
        t = self.time_s
        return (t - 0.5 * (t.min() + t.max())) / np.ptp(t)

    @property
    def n_rows(self) -> int:
        return int(self.off.size)

    @property
    def friction_ratio(self) -> np.ndarray:
        """FR = ON / OFF per row [-]."""
        return self.on / self.off

    @property
    def reference_amplitude_m(self) -> float:
        """The amplitude [m] the coupling law's commanded fraction is taken of: the rig's
        maximum if given, else the table's largest amplitude."""
        return float(self.max_amplitude_m or np.max(self.amplitude_m))

    @property
    def alpha(self) -> np.ndarray:
        """Commanded amplitude fraction per row: ``amplitude_m / reference_amplitude_m``."""
        return self.amplitude_m / self.reference_amplitude_m

    @property
    def operating_points(self) -> tuple[np.ndarray, np.ndarray]:
        """``(index, first)``: each row's condition (load, amplitude, frequency, speed)
        number, and the first row of each condition."""
        keys = np.stack(
            [
                self.normal_load_n,
                self.amplitude_m,
                self.vibration_frequency_hz,
                self.sliding_speed_m_s,
            ]
        ).T
        _, first, index = np.unique(keys, axis=0, return_index=True, return_inverse=True)
        return np.ravel(index), first

    def to_document(self) -> dict[str, Any]:
        """The ``dataset.json`` document (schema ``levels_table.schema.json``)."""
        doc: dict[str, Any] = {
            "schema_version": "1",
            "kind": KIND,
            "name": self.name,
            "material": self.material,
        }
        if self.source:
            doc["source"] = self.source
        if self.description:
            doc["description"] = self.description
        doc["friction"] = self.friction
        if self.max_amplitude_m is not None:
            doc["max_amplitude_m"] = self.max_amplitude_m
        rows = []
        for i in range(self.n_rows):
            row: dict[str, Any] = {k: float(getattr(self, k)[i]) for k in _NUMBERS}
            for k in _OPTIONAL:
                if np.isfinite(getattr(self, k)[i]):
                    row[k] = float(getattr(self, k)[i])
            if self.repeat[i]:
                row["repeat"] = self.repeat[i]
            rows.append(row)
        doc["rows"] = rows
        return doc


def levels_from_document(
    doc: Any, file: str, path: Path | None = None, sha256: str = ""
) -> LevelsTable:
    """A :class:`LevelsTable` from a parsed ``dataset.json`` of kind ``levels``.

    Raises:
        IdtoolError: every way it breaks the schema, located by field path.
    """
    problems = schema_problems(doc, LEVELS_SCHEMA, file)
    if problems:
        raise IdtoolError(f"{file}: not a valid levels dataset", problems)
    rows = doc["rows"]
    timed = ["time_s" in r for r in rows]
    if any(timed) and not all(timed):
        message = (
            f"time_s is given on {sum(timed)} of {len(rows)} rows: give every row's "
            "measurement time, or none"
        )
        first = timed.index(False)
        where = f"rows[{first}].time_s"
        raise IdtoolError(
            f"{file}: not a valid levels dataset", [Problem(message, file, None, where)]
        )

    def column(key: str) -> np.ndarray:
        return np.array([float(r.get(key, np.nan)) for r in rows])

    if not sha256:
        sha256 = hashlib.sha256(json.dumps(doc, sort_keys=True).encode()).hexdigest()
    arrays = {k: column(k) for k in (*_NUMBERS, *_OPTIONAL)}
    return LevelsTable(
        name=doc["name"],
        material=doc["material"],
        friction=doc["friction"],
        repeat=tuple(str(r.get("repeat", "")) for r in rows),
        max_amplitude_m=doc.get("max_amplitude_m"),
        source=doc.get("source", ""),
        description=doc.get("description", ""),
        path=path,
        sha256=sha256,
        **arrays,
    )


def _document(path: Path) -> tuple[Path, Any, bytes]:
    file = path / DATASET_FILE if path.is_dir() else path
    try:
        data = file.read_bytes()
    except OSError as err:
        raise IdtoolError(f"cannot read {file}: {err.strerror or err}") from None
    try:
        return file, json.loads(data), data
    except json.JSONDecodeError as err:
        problem = Problem(f"not valid JSON: {err.msg} (line {err.lineno})", file=str(file))
        raise IdtoolError(f"{file}: cannot read it", [problem]) from None


def is_levels_dataset(path: str | Path) -> bool:
    """True when ``path`` (a folder or its ``dataset.json``) holds a dataset of kind
    ``levels``; False for anything else, unreadable files included (the trace loader
    then says what is wrong)."""
    try:
        _, doc, _ = _document(Path(path))
    except IdtoolError:
        return False
    return isinstance(doc, dict) and doc.get("kind") == KIND


def load_levels(path: str | Path) -> LevelsTable:
    """Load a levels dataset: a folder holding ``dataset.json`` of kind ``levels``, or
    that file.

    Raises:
        IdtoolError: unreadable, or every problem found, located by field path.
    """
    file, doc, data = _document(Path(path))
    return levels_from_document(doc, str(file), file.parent, hashlib.sha256(data).hexdigest())
