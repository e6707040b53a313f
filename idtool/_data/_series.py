"""A velocity-force series: the input of ``idtool fit-law`` (docs/how-to/fit-law.md).

One CSV (any dialect :mod:`idtool._data._import_table` reads) or Parquet file with a
header line and one row per sample:

| column | header (case-insensitive, unit optional) | units |
|---|---|---|
| time | ``time``, ``t`` | s, ms, us, min |
| slip velocity | ``velocity``, ``v``, ``slip velocity``, ``speed`` | m/s, mm/s, cm/s |
| or displacement | ``displacement``, ``x``, ``position``, ``slip`` | m, mm, um, nm |
| friction force | ``force``, ``f``, ``friction``, ``friction force`` | N, kN, mN, lbf |
| normal load (optional) | ``normal load``, ``load``, ``normal force`` | N, kN, ... |

Units are read from the headers as for DAQ exports (``force (mN)``, ``x [um]``,
``time_s``; :mod:`idtool._data._import_units`); a header without one is in SI. With both
a velocity and a displacement column, the velocity is used. Every problem is located
(file, row, column, line), as the importer's are.
"""

from __future__ import annotations

import dataclasses
import hashlib
from pathlib import Path

import numpy as np

from idtool._data._import_columns import parse_numbers
from idtool._data._import_table import DaqTable, ReadOptions, read_daq
from idtool._data._import_units import QUANTITIES, column_unit, to_si
from idtool._errors import IdtoolError, Problem

__all__ = ["COLUMNS", "MIN_SAMPLES", "Series", "read_series"]

MIN_SAMPLES = 20
# role -> (quantity, accepted header names)
COLUMNS: dict[str, tuple[str, tuple[str, ...]]] = {
    "time": ("time", ("time", "t")),
    "velocity": ("speed", ("velocity", "v", "slip velocity", "speed", "sliding velocity")),
    "displacement": ("displacement", ("displacement", "x", "position", "slip", "u")),
    "force": ("force", ("force", "f", "friction", "friction force")),
    "normal_load": ("force", ("normal load", "load", "normal force", "normal")),
}


@dataclasses.dataclass(frozen=True)
class Series:
    """A series of slip and friction force, in SI units.

    Attributes:
        time_s: sample times [s], increasing.
        force_n: measured friction force [N].
        velocity_m_s: slip velocity [m/s] (None when only the displacement was given).
        displacement_m: slip displacement [m] (None when only the velocity was given).
        normal_load_n: normal load [N] at every sample, or None.
        source: where it came from (a file name, or "simulated ...").
        sha256: hash of the file's bytes (or of the arrays, for a series made in Python).
    """

    time_s: np.ndarray
    force_n: np.ndarray
    velocity_m_s: np.ndarray | None = None
    displacement_m: np.ndarray | None = None
    normal_load_n: np.ndarray | None = None
    source: str = "(in memory)"
    sha256: str = ""

    def __post_init__(self):
        if self.velocity_m_s is None and self.displacement_m is None:
            raise IdtoolError("a series needs a velocity or a displacement")
        if not self.sha256:
            h = hashlib.sha256()
            for a in (self.time_s, self.force_n, self.velocity_m_s, self.displacement_m):
                if a is not None:
                    h.update(np.ascontiguousarray(a, float).tobytes())
            object.__setattr__(self, "sha256", h.hexdigest())
        problems = _checks(self)
        if problems:
            raise IdtoolError(f"{self.source}: not a usable series", problems)

    @property
    def n_samples(self) -> int:
        return int(self.time_s.size)

    @property
    def slip_input(self) -> str:
        """``"velocity"`` or ``"displacement"``: which column the model is driven by."""
        return "velocity" if self.velocity_m_s is not None else "displacement"

    def velocity(self) -> np.ndarray:
        """Slip velocity at the samples [m/s]: given, or the displacement's derivative
        (second-order differences, :func:`numpy.gradient`)."""
        if self.velocity_m_s is not None:
            return np.asarray(self.velocity_m_s, float)
        return np.gradient(np.asarray(self.displacement_m, float), self.time_s)

    def displacement(self) -> np.ndarray:
        """Slip displacement [m]: given, or the velocity's trapezoid integral from 0."""
        if self.displacement_m is not None:
            return np.asarray(self.displacement_m, float)
        v, t = self.velocity(), self.time_s
        return np.concatenate([[0.0], np.cumsum(0.5 * (v[1:] + v[:-1]) * np.diff(t))])


def _checks(s: Series) -> list[Problem]:
    out = []
    arrays = {"time": s.time_s, "force": s.force_n, "velocity": s.velocity_m_s}
    arrays |= {"displacement": s.displacement_m, "normal load": s.normal_load_n}
    n = np.size(s.time_s)
    for name, a in arrays.items():
        if a is not None and np.shape(a) != (n,):
            out.append(Problem(f"{name} has shape {np.shape(a)}, time has ({n},)", s.source))
    if out:
        return out
    if n < MIN_SAMPLES:
        out.append(Problem(f"{n} samples: give at least {MIN_SAMPLES}", s.source))
    steps = np.diff(s.time_s)
    if np.any(steps <= 0):
        i = int(np.argmax(steps <= 0)) + 1
        message = "time does not increase here: sort the rows, or delete the repeated one"
        out.append(Problem(message, s.source, row=i + 1, column="time"))
    if s.normal_load_n is not None and np.any(s.normal_load_n <= 0):
        i = int(np.argmax(s.normal_load_n <= 0))
        message = "the normal load must be positive [N]"
        out.append(Problem(message, s.source, row=i + 1, column="normal load"))
    return out


def _find(table: DaqTable, role: str) -> int | None:
    names = COLUMNS[role][1]
    for j, h in enumerate(table.headers):
        if " ".join(h.name.split()).casefold() in names:
            return j
    return None


def read_series(path: str | Path, options: ReadOptions | None = None) -> Series:
    """Read a series file (module docstring).

    Raises:
        IdtoolError: every problem found, each with the file, row and column.
    """
    path = Path(path)
    file = str(path)
    table, problems = read_daq(path, file, options or ReadOptions())
    if table is None:
        raise IdtoolError(f"{file}: cannot read the series", problems)
    found = {role: _find(table, role) for role in COLUMNS}
    listing = ", ".join(repr(h.text) for h in table.headers)
    for role in ("time", "force"):
        if found[role] is None:
            problems.append(_missing(file, role, listing))
    if found["velocity"] is None and found["displacement"] is None:
        problems.append(_missing(file, "velocity", listing, " (or a displacement column)"))
    values: dict[str, np.ndarray] = {}
    for role, j in found.items():
        if j is None:
            continue
        quantity = COLUMNS[role][0]
        unit, _, unit_problems = column_unit(table.headers[j], None, quantity, role, file)
        numbers, decimals, bad = parse_numbers(table, j)
        problems += unit_problems + bad
        if unit is not None and not bad:
            values[role] = to_si(numbers, QUANTITIES[quantity][unit], decimals)
    if problems:
        raise IdtoolError(f"{file}: cannot read the series", problems)
    digest = hashlib.sha256(path.read_bytes()).hexdigest()
    return Series(
        time_s=values["time"],
        force_n=values["force"],
        velocity_m_s=values.get("velocity"),
        displacement_m=values.get("displacement"),
        normal_load_n=values.get("normal_load"),
        source=file,
        sha256=digest,
    )


def _missing(file: str, role: str, listing: str, extra: str = "") -> Problem:
    quantity, names = COLUMNS[role]
    units = ", ".join(QUANTITIES[quantity])
    return Problem(
        f"no {role} column{extra}: name one {names[0]!r} with its unit in the header "
        f"(e.g. '{names[0]} [{next(iter(QUANTITIES[quantity]))}]'; units {units}); "
        f"the columns are {listing}",
        file=file,
        row=0,
        column=names[0],
    )
