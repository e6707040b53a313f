"""Operating conditions of imported files: normal load [N], amplitude [-], speed [m/s].

Three sources: a conditions table (CSV or Parquet: a ``file`` column and ``load``,
``amplitude``, ``speed`` columns, their units in the headers, in the cells or given as
options), named groups of a regular expression searched in each file's name
(``N(?P<load_n>\\d+)_A(?P<amplitude_percent>\\d+)``), and one value for every file.
Each file must get each quantity from exactly one source; anything else is an error
naming the file, and the table's row and column.
"""

from __future__ import annotations

import dataclasses
import re
from collections.abc import Mapping, Sequence
from pathlib import Path, PurePosixPath

from idtool._data._import_table import DaqTable, ReadOptions, read_daq
from idtool._data._import_units import (
    QUANTITIES,
    Header,
    canonical_unit,
    column_unit,
    parse_header,
    scalar_to_si,
    split_value,
)
from idtool._data._schema import closest_name
from idtool._errors import Problem

__all__ = ["QUANTITY_NAMES", "ConditionSources", "Conditions", "conditions_for"]

# quantity -> (unit table of _import_units, option giving one value, option giving the unit)
QUANTITY_NAMES = {
    "load": ("force", "--load", "--load-unit"),
    "amplitude": ("amplitude", "--amplitude", "--amplitude-unit"),
    "speed": ("speed", "--speed", "--speed-unit"),
}
_ROLES = {
    "file": ("file", "filename", "file name", "trace", "trace file", "path"),
    "load": ("load", "normal load", "normal force"),
    "amplitude": ("amplitude", "ampl", "amp", "horn amplitude"),
    "speed": ("speed", "pull speed", "velocity", "pull velocity"),
    "notes": ("notes", "note", "comment", "comments"),
}
_GROUPS = "load_n, load_kn, amplitude_percent, amplitude_fraction, speed_m_s, speed_mm_s"


@dataclasses.dataclass(frozen=True)
class Conditions:
    """One file's operating point (SI) and optional notes from the table."""

    normal_load_n: float
    amplitude_fraction: float
    pull_speed_m_s: float
    notes: str | None = None


@dataclasses.dataclass(frozen=True)
class ConditionSources:
    """Where the conditions come from: a table, a file-name ``pattern``, ``values``
    for every file (quantity -> SI value), and the ``units`` (quantity -> unit) of table
    columns and pattern groups that name none."""

    table: Path | None = None
    pattern: str | None = None
    values: Mapping[str, float] = dataclasses.field(default_factory=dict)
    units: Mapping[str, str | None] = dataclasses.field(default_factory=dict)


@dataclasses.dataclass(frozen=True)
class _Value:
    si: float
    source: str  # for messages: "conditions.csv row 3", "--pattern", "--load"
    file: str
    row: int | None = None
    column: str | None = None

    def problem(self, message: str) -> Problem:
        return Problem(message, file=self.file, row=self.row, column=self.column)


def _role(header: Header) -> str | None:
    name = " ".join(header.name.replace("_", " ").split()).casefold()
    return next((role for role, names in _ROLES.items() if name in names), None)


def _unit(
    header: Header, quantity: str, file: str, units: Mapping[str, str | None]
) -> tuple[str | None, str, list[Problem]]:
    kind, _, unit_option = QUANTITY_NAMES[quantity]
    return column_unit(header, units.get(quantity), kind, unit_option, file)


def _cell_value(
    cell: str, quantity: str, unit: str, from_header: bool
) -> tuple[float | None, str | None]:
    """A cell in SI, or why not: a number with an optional unit of its own."""
    parts = split_value(cell)
    if parts is None:
        return None, f"{cell.strip()!r} is not a number" if cell.strip() else "empty cell"
    value, unit_text, decimals = parts
    kind = QUANTITY_NAMES[quantity][0]
    if unit_text:
        own = canonical_unit(unit_text)
        if own not in QUANTITIES[kind]:
            return None, f"'{unit_text}' is not a {quantity} unit ({', '.join(QUANTITIES[kind])})"
        if from_header and own != unit:
            return None, f"the cell says '{unit_text}' but the header says '{unit}'"
        unit = own
    return scalar_to_si(value, QUANTITIES[kind][unit], decimals), None


class _Collect:
    """The values found per file and quantity, and the problems."""

    def __init__(self, n_files: int):
        self.values: list[dict[str, list[_Value]]] = [{} for _ in range(n_files)]
        self.notes: list[str | None] = [None] * n_files
        self.failed: set[int] = set()  # files without a table row or pattern match (reported)
        self.broken: set[str] = set()  # quantities whose column or group is (reported)
        self.problems: list[Problem] = []

    def add(self, index: int, quantity: str, value: _Value) -> None:
        self.values[index].setdefault(quantity, []).append(value)


def _match_file(cell: str, names: Sequence[str]) -> int | None:
    """The imported file a table's ``file`` cell names: by file name, with or without
    its suffix (a folder in the cell is ignored)."""
    wanted = PurePosixPath(cell.strip().replace("\\", "/")).name
    for i, name in enumerate(names):
        if wanted in (Path(name).name, Path(name).stem):
            return i
    return None


def _read_table(sources: ConditionSources, names: Sequence[str], out: _Collect) -> None:
    assert sources.table is not None
    label = str(sources.table)
    table, problems = read_daq(sources.table, label, ReadOptions())
    out.problems += problems
    if table is None:
        return
    roles: dict[str, int] = {}
    for j, header in enumerate(table.headers):
        role = _role(header)
        if role is None:
            message = (
                f"column '{header.text}' is not file, load, amplitude, speed or notes: ignored"
            )
            out.problems.append(
                Problem(message, file=label, row=0, column=header.text, severity="warning")
            )
        elif role in roles:
            first = table.headers[roles[role]].text
            message = f"'{header.text}' and '{first}' both give the {role}: keep one of them"
            out.problems.append(Problem(message, file=label, row=0, column=header.text))
        else:
            roles[role] = j
    if "file" not in roles:
        message = "the conditions table needs a 'file' column naming each imported file"
        out.problems.append(Problem(message, file=label, row=0, column="file"))
        return
    units = {}
    for quantity in QUANTITY_NAMES:
        if quantity in roles:
            header = table.headers[roles[quantity]]
            unit, how, found = _unit(header, quantity, label, sources.units)
            out.problems += found
            if unit is None:
                out.broken.add(quantity)
            else:
                units[quantity] = (roles[quantity], unit, how == "from the header")
    _table_rows(table, roles, units, names, out)


def _text(table: DaqTable, j: int, i: int) -> str:
    """Cell ``i`` of column ``j`` as text ("" if empty or unreadable)."""
    column = table.columns[j]
    if isinstance(column, str):
        return ""
    if column.numbers is not None:  # a Parquet table
        empty = column.null is not None and column.null[i]
        return "" if empty else repr(float(column.numbers[i]))
    return "" if column.text is None else column.text[i].strip()


def _table_rows(
    table: DaqTable,
    roles: dict[str, int],
    units: dict[str, tuple[int, str, bool]],
    names: Sequence[str],
    out: _Collect,
) -> None:
    label, file_column = table.file, table.headers[roles["file"]].text
    seen: dict[int, int] = {}
    for i in range(table.n_rows):
        cell = _text(table, roles["file"], i)
        index = _match_file(cell, names) if cell else None
        if index is None:
            guess = closest_name(cell, [Path(n).name for n in names]) if cell else None
            hint = f" (did you mean '{guess}'?)" if guess else ""
            what = f"'{cell}' is not one of the imported files{hint}" if cell else "empty cell"
            message = f"{what}: give the file name of each imported file, or delete the row"
            out.problems.append(Problem(message, file=label, row=i + 1, column=file_column))
            continue
        if index in seen:
            message = f"'{names[index]}' already has row {seen[index] + 1}: keep one row per file"
            out.problems.append(Problem(message, file=label, row=i + 1, column=file_column))
            continue
        seen[index] = i
        for quantity, (j, unit, from_header) in units.items():
            column = table.headers[j].text
            value, why = _cell_value(_text(table, j, i), quantity, unit, from_header)
            if value is None:
                out.problems.append(Problem(f"{why}", file=label, row=i + 1, column=column))
            else:
                out.add(
                    index, quantity, _Value(value, f"{label} row {i + 1}", label, i + 1, column)
                )
        if "notes" in roles and _text(table, roles["notes"], i):
            out.notes[index] = _text(table, roles["notes"], i)
    for index, name in enumerate(names):
        if index not in seen:
            message = f"no row for the imported file '{name}': add one"
            out.problems.append(Problem(message, file=label, column=file_column))
            out.failed.add(index)


def _from_pattern(sources: ConditionSources, names: Sequence[str], out: _Collect) -> None:
    assert sources.pattern is not None
    try:
        regex = re.compile(sources.pattern)
    except re.error as err:
        out.problems.append(Problem(f"--pattern is not a regular expression: {err}"))
        return
    groups: dict[str, tuple[str, str | None]] = {}
    for group in regex.groupindex:
        header = parse_header(group)
        quantity = _role(header)
        if quantity not in QUANTITY_NAMES:
            message = f"--pattern: unknown group name '{group}': use {_GROUPS}"
            out.problems.append(Problem(message))
            continue
        unit, _, found = _unit(header, quantity, "--pattern", sources.units)
        out.problems += [Problem(f"--pattern group '{group}': {p.message}") for p in found]
        if unit is None:
            out.broken.add(quantity)
        groups[group] = (quantity, unit)
    if not groups:
        message = f"--pattern has no named group: name them (?P<load_n>...); use {_GROUPS}"
        out.problems.append(Problem(message))
        return
    for index, name in enumerate(names):
        match = regex.search(Path(name).stem)
        if match is None:
            message = (
                f"the file name does not match --pattern '{sources.pattern}' (searched in "
                f"'{Path(name).stem}')"
            )
            out.problems.append(Problem(message, file=name))
            out.failed.add(index)
            continue
        for group, (quantity, unit) in groups.items():
            text = match.group(group)
            if text is None or unit is None:
                continue  # reported as missing, or the unit was refused above
            value, why = _cell_value(text, quantity, unit, False)
            where = f"--pattern group '{group}'"
            if value is None:
                out.problems.append(Problem(f"{where}: {why}", file=name))
            else:
                out.add(index, quantity, _Value(value, where, name, column=group))


def _check(quantity: str, value: _Value) -> Problem | None:
    """An out-of-range value, located where it came from."""
    if quantity == "amplitude" and not 0.0 <= value.si <= 1.0:
        hint = ""
        if 1.0 < value.si <= 100.0:
            hint = "; it looks like a percentage: write it with %, or give --amplitude-unit %"
        return value.problem(f"amplitude {value.si:g} is not a fraction in [0, 1]{hint}")
    if quantity != "amplitude" and value.si <= 0.0:
        return value.problem(f"the {quantity} must be positive, not {value.si:g}")
    return None


def conditions_for(
    names: Sequence[str], sources: ConditionSources
) -> tuple[list[Conditions] | None, list[Problem]]:
    """The conditions of each imported file (``names``: their paths as the user gave
    them); None with the problems if any file lacks a quantity or gets one twice."""
    out = _Collect(len(names))
    if sources.table is not None:
        _read_table(sources, names, out)
    if sources.pattern is not None:
        _from_pattern(sources, names, out)
    for quantity, si in sources.values.items():
        option = QUANTITY_NAMES[quantity][1]
        for index, name in enumerate(names):
            out.add(index, quantity, _Value(si, option, name))
    result = []
    for index, name in enumerate(names):
        got: dict[str, float] = {}
        for quantity, (_, option, _) in QUANTITY_NAMES.items():
            found = out.values[index].get(quantity, [])
            if not found and (index in out.failed or quantity in out.broken):
                continue  # the missing row, the mismatch or the bad column is reported
            if not found:
                message = (
                    f"no {quantity} for this file: give it in the conditions table, in a "
                    f"--pattern group, or with {option}"
                )
                out.problems.append(Problem(message, file=name))
            elif len(found) > 1:
                both = " and ".join(v.source for v in found)
                message = f"the {quantity} comes from both {both}: give it once"
                out.problems.append(Problem(message, file=name))
            elif (problem := _check(quantity, found[0])) is not None:
                out.problems.append(problem)
            else:
                got[quantity] = found[0].si
        if len(got) == len(QUANTITY_NAMES):
            result.append(Conditions(got["load"], got["amplitude"], got["speed"], out.notes[index]))
    if any(p.severity == "error" for p in out.problems):
        return None, out.problems
    return result, out.problems
