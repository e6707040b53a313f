"""Read a steady-state friction table (CSV or Parquet) and import it as a dataset of
kind ``levels`` (:mod:`idtool._data._levels`; docs/how-to/levels-table.md).

One row per measurement; headers name the column and its unit (``load (N)``,
``amplitude (um)``, ``amplitude (%)``, ``frequency (kHz)``, ``speed (mm/s)``,
``off (N)``), read case-insensitively; a header without a unit is in SI (a fraction for
the amplitude). Every problem is located by file, row and column, and says what to fix:

| column | header | units |
|---|---|---|
| normal load | ``load``, ``normal load``, ``normal force`` | N, kN, mN, ... |
| amplitude | ``amplitude``, ``vibration amplitude`` | fraction, %, m, mm, um, nm |
| frequency | ``frequency``, ``vibration frequency`` | Hz, kHz |
| sliding speed | ``speed``, ``sliding speed``, ``velocity`` | m/s, mm/s, cm/s, m/min |
| OFF, ON friction | ``off``, ``on`` (``friction off``, ``mu off``) | force, or none: coefficient |
| standard errors (optional) | ``off se``, ``on se`` | as OFF and ON |
| repeat id (optional) | ``repeat`` | text |
| measurement time (optional, every row) | ``time``, ``measured at``, ``clock`` | s, min, h, ... |
"""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any

import numpy as np

from idtool._atomic import atomic_output_dir
from idtool._data._import_columns import parse_numbers
from idtool._data._import_table import DaqTable, ReadOptions, read_daq
from idtool._data._import_units import QUANTITIES, Header, to_si
from idtool._data._levels import LevelsTable, levels_from_document
from idtool._data._paths import DATASET_FILE
from idtool._data._schema import LEVELS_SCHEMA, load_schema, schema_problems
from idtool._errors import IdtoolError, Problem

__all__ = ["COLUMNS", "import_levels", "read_levels_table"]

_EMPTY = "empty cell"
_AMPLITUDE = {**QUANTITIES["amplitude"], **QUANTITIES["displacement"]}
_FREQUENCY = {"hz": 1.0, "khz": 1e3, "mhz": 1e6}
# field -> (accepted header names, units {name: factor to SI} or None: per 'friction')
COLUMNS: dict[str, tuple[tuple[str, ...], dict[str, float] | None]] = {
    "normal_load_n": (("load", "normal load", "normal force", "normal"), QUANTITIES["force"]),
    "amplitude": (("amplitude", "vibration amplitude", "amp"), _AMPLITUDE),
    "vibration_frequency_hz": (("frequency", "vibration frequency", "freq", "f"), _FREQUENCY),
    "sliding_speed_m_s": (
        ("speed", "sliding speed", "velocity", "sliding velocity", "v"),
        QUANTITIES["speed"],
    ),
    "off": (("off", "friction off", "mu off", "f off", "off friction", "cof off"), None),
    "on": (("on", "friction on", "mu on", "f on", "on friction", "cof on"), None),
    "off_se": (("off se", "se off", "friction off se", "mu off se", "f off se"), None),
    "on_se": (("on se", "se on", "friction on se", "mu on se", "f on se"), None),
    "time_s": (
        ("time", "measured at", "time measured", "measurement time", "clock", "elapsed time"),
        {**QUANTITIES["time"], "h": 3600.0},
    ),
}
_OPTIONAL = ("off_se", "on_se")  # a column that may be absent, and empty in some rows
_OPTIONAL_COLUMNS = (*_OPTIONAL, "time_s")  # that may be absent (a time then in every row)
_REPEAT = ("repeat", "run", "rep", "trial")


def _norm(text: str) -> str:
    return " ".join(text.replace("_", " ").split()).casefold()


def _find(table: DaqTable, names: tuple[str, ...]) -> int | None:
    for j, h in enumerate(table.headers):
        if _norm(h.name) in names or _norm(h.text) in names:
            return j
    return None


def _unit(
    header: Header, units: dict[str, float], file: str
) -> tuple[str | None, float | None, list[Problem]]:
    """The column's unit and its factor to SI (no unit: the first, SI one)."""
    lookup = {u.casefold(): (u, f) for u, f in units.items()}
    text = header.unit or header.unit_text
    if text is None:
        return next(iter(units)), 1.0, []
    key = text.casefold().replace("µ", "u").replace("μ", "u")
    if key in lookup:
        return lookup[key][0], lookup[key][1], []
    example = f"{header.name} ({next(iter(units))})"
    message = f"unknown unit '{text}': use one of {', '.join(units)} (e.g. '{example}')"
    return None, None, [Problem(message, file=file, row=0, column=header.text)]


def _friction_unit(
    header: Header, friction: str | None, file: str
) -> tuple[str | None, float | None, list[Problem]]:
    """OFF/ON columns: a force unit makes them forces [N]; none, a coefficient; the
    ``friction`` option must agree."""
    text = header.unit or header.unit_text
    key = (text or "").casefold()
    forces = {u.casefold(): f for u, f in QUANTITIES["force"].items()}

    def located(message: str) -> Problem:
        return Problem(message, file=file, row=0, column=header.text)

    if key in forces:
        if friction == "coefficient":
            message = (
                f"the header gives a force unit '{text}' but friction is 'coefficient': "
                "drop the unit or say --friction force"
            )
            return None, None, [located(message)]
        return "force", forces[key], []
    if key in ("", "-", "1", "mu", "cof", "coefficient"):
        if friction == "force":
            return "force", 1.0, []  # a force column without a unit: newtons
        if friction is None and key == "":
            message = (
                "no unit: say whether OFF and ON are forces (write the unit, e.g. "
                f"'{header.name} (N)') or coefficients (--friction coefficient)"
            )
            return None, None, [located(message)]
        return "coefficient", 1.0, []
    units = ", ".join(QUANTITIES["force"])
    message = f"unknown unit '{text}': a force unit ({units}) or none for a coefficient"
    return None, None, [located(message)]


def read_levels_table(
    path: str | os.PathLike[str],
    *,
    friction: str | None = None,
    max_amplitude_m: float | None = None,
    frequency_hz: float | None = None,
    options: ReadOptions | None = None,
) -> tuple[list[dict], str, list[Problem]]:
    """Read a table: its rows as ``levels_table.schema.json`` row documents (SI), what
    OFF and ON are (``"force"`` or ``"coefficient"``) and every problem, located.

    ``friction``: ``"force"`` or ``"coefficient"`` when the headers do not say (a
    header with a force unit says force).
    """
    path = Path(path)
    file = str(path)
    table, problems = read_daq(path, file, options or ReadOptions())
    if table is None:
        return [], "", problems
    listing = ", ".join(repr(h.text) for h in table.headers)
    values: dict[str, np.ndarray] = {}
    found: dict[str, int] = {}
    kinds = set()
    for field, (names, units) in COLUMNS.items():
        j = _find(table, names)
        if j is None:
            if field == "vibration_frequency_hz" and frequency_hz is not None:
                values[field] = np.full(table.n_rows, float(frequency_hz))
            elif field not in _OPTIONAL_COLUMNS:
                message = (
                    f"no {field.split('_')[0].replace('normal', 'normal load')} column: name "
                    f"one {names[0]!r} with its unit in the header; the columns are {listing}"
                )
                problems.append(Problem(message, file=file, row=0, column=names[0]))
            continue
        found[field] = j
        header = table.headers[j]
        if units is None:
            kind, factor, unit_problems = _friction_unit(header, friction, file)
            if kind is not None:
                kinds.add(kind)
            unit = kind
        else:
            unit, factor, unit_problems = _unit(header, units, file)
        numbers, decimals, bad = parse_numbers(table, j)
        if field in _OPTIONAL:
            bad = [p for p in bad if not p.message.startswith(_EMPTY)]
        problems += unit_problems + bad
        if factor is not None:
            si = to_si(numbers, factor, decimals)
            if field == "amplitude":
                field = "amplitude_fraction" if unit in QUANTITIES["amplitude"] else "amplitude_m"
            values[field] = si
    if len(kinds) > 1:
        problems.append(Problem("OFF and ON columns mix forces and coefficients: give one", file))
    kind = friction or (kinds.pop() if len(kinds) == 1 else "")
    repeat_j = _find(table, _REPEAT)
    repeats = [""] * table.n_rows
    column = table.columns[repeat_j] if repeat_j is not None else None
    if column is not None and not isinstance(column, str) and column.text is not None:
        repeats = [c.strip() for c in column.text]
    elif column is not None and not isinstance(column, str) and column.numbers is not None:
        repeats = [f"{x:g}" for x in column.numbers]
    if "amplitude_fraction" in values:
        if max_amplitude_m is None:
            message = "amplitudes are fractions of the rig's maximum: give it (--max-amplitude-um)"
            problems.append(Problem(message, file=file, row=0, column=header_of_amplitude(table)))
        else:
            values["amplitude_m"] = values["amplitude_fraction"] * max_amplitude_m
    rows = [_row(values, i, repeats[i]) for i in range(table.n_rows)]
    header_of = {f: table.headers[j].text for f, j in found.items()}
    header_of["amplitude_m"] = header_of["amplitude_fraction"] = header_of.get("amplitude", "")
    # the schema's checks on every row (ranges, required values), except where a
    # column is missing or a cell was already reported
    reported = {(p.row, p.column) for p in problems}
    row_schema = {"$ref": load_schema(LEVELS_SCHEMA)["$id"] + "#/$defs/row"}
    for i, row in enumerate(rows):
        for p in schema_problems(row, row_schema, file):
            column_name = header_of.get(p.column or "")
            if column_name and not {(i + 1, column_name), (0, column_name)} & reported:
                problems.append(Problem(p.message, file=file, row=i + 1, column=column_name))
    return rows, kind, problems


def header_of_amplitude(table: DaqTable) -> str:
    j = _find(table, COLUMNS["amplitude"][0])
    return table.headers[j].text if j is not None else "amplitude"


def _row(values: dict[str, np.ndarray], i: int, repeat: str) -> dict[str, Any]:
    row: dict[str, Any] = {k: float(v[i]) for k, v in values.items() if np.isfinite(v[i])}
    if repeat:
        row["repeat"] = repeat
    return row


def import_levels(
    table: str | os.PathLike[str],
    out: str | os.PathLike[str],
    *,
    name: str | None = None,
    material: str,
    source: str = "",
    description: str = "",
    friction: str | None = None,
    max_amplitude_m: float | None = None,
    frequency_hz: float | None = None,
    force: bool = False,
) -> LevelsTable:
    """Import a steady-state friction table (CSV or Parquet, module docstring) as a
    dataset of kind ``levels`` in the folder ``out``: written to a temporary folder,
    validated, then renamed into place; an existing ``out`` is replaced only with
    ``force``.

    Args:
        table: the table file.
        out: the dataset folder to create.
        name: the dataset's name (default: ``out``'s folder name).
        material: the two surfaces in contact (free text).
        source: citation text: where the numbers come from.
        description: free text.
        friction: ``"force"`` or ``"coefficient"``, when the OFF/ON headers carry no unit.
        max_amplitude_m: the rig's amplitude at 100% command [m]: needed when the table
            gives amplitudes as fractions or percent.
        frequency_hz: the vibration frequency [Hz] of every row, for a table without a
            frequency column.
        force: replace an existing ``out``.

    Returns:
        The imported :class:`~idtool._data._levels.LevelsTable`.

    Raises:
        IdtoolError: every problem in the table, each with its file, row and column.
    """
    if friction not in (None, "force", "coefficient"):
        raise IdtoolError(f"friction {friction!r}: say 'force' or 'coefficient'")
    rows, kind, problems = read_levels_table(
        table, friction=friction, max_amplitude_m=max_amplitude_m, frequency_hz=frequency_hz
    )
    file = str(table)
    if problems:
        raise IdtoolError(f"{file}: cannot import the table", problems)
    doc: dict = {"schema_version": "1", "kind": "levels"}
    doc["name"] = name or Path(out).resolve().name
    doc["material"] = material
    if source:
        doc["source"] = source
    if description:
        doc["description"] = description
    doc["friction"] = kind
    if max_amplitude_m is not None:
        doc["max_amplitude_m"] = float(max_amplitude_m)
    doc["rows"] = rows
    with atomic_output_dir(out, force=force) as tmp:
        (tmp / DATASET_FILE).write_text(json.dumps(doc, indent=1) + "\n")
        levels_from_document(doc, str(Path(out) / DATASET_FILE))  # checked before the rename
    from idtool._data._levels import load_levels

    return load_levels(Path(out))
