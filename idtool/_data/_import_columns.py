"""Columns of a read DAQ export: find one by header or number, read it as numbers or flags.

Every bad cell is a problem naming the file, the row (header row 0), the column and,
for CSV, the line; the first few of a column are listed, the rest counted.
"""

from __future__ import annotations

import re

import numpy as np

from idtool._data._import_table import DaqTable
from idtool._data._schema import closest_name
from idtool._data._table_read import MAX_LISTED, RawColumn
from idtool._errors import Problem

__all__ = ["find_column", "parse_flags", "parse_numbers"]

_NUMBER = re.compile(r"[+-]?(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?", re.ASCII)
# The characters of plain-number cells joined by newlines. Over these, NumPy's float
# parsing accepts exactly the cells _NUMBER matches (tests/test_import.py checks every
# string of up to 6 of them), so a column of them either parses whole or needs a look:
# 20 times faster than matching _NUMBER cell by cell (1.4 s per 2.5 million cells).
_PLAIN_CHARS = re.compile(r"[0-9+\-.eE\n]*", re.ASCII)
_DECIMALS = re.compile(r"\.(\d+)")
_FLAGS = {"0": False, "1": True, "false": False, "true": True, "off": False, "on": True}
_EMPTY = "empty cell: every sample needs a value (fill it in or delete the row)"


def _problem(
    message: str, file: str, row: int | None = None, column: str | None = None
) -> tuple[None, list[Problem]]:
    return None, [Problem(message, file=file, row=row, column=column)]


def _norm(text: str) -> str:
    return " ".join(text.split()).casefold()


def find_column(table: DaqTable, spec: str | int, option: str) -> tuple[int | None, list[Problem]]:
    """The index of the column ``spec`` names: a 1-based number, or a header matched
    case-insensitively in full (``"Load (N)"``) or without its unit (``"Load"``)."""
    file, texts = table.file, [h.text for h in table.headers]
    listing = ", ".join(f"{j + 1}: {t!r}" for j, t in enumerate(texts))
    if isinstance(spec, int):
        if 1 <= spec <= len(texts):
            return spec - 1, []
        message = f"{option} {spec}: there is no column {spec}; the columns are {listing}"
        return _problem(message, file, 0)
    key = _norm(spec)
    for candidates in (
        [j for j, t in enumerate(texts) if _norm(t) == key],
        [j for j, h in enumerate(table.headers) if _norm(h.name) == key],
    ):
        if len(candidates) == 1:
            return candidates[0], []
        if len(candidates) > 1:
            which = " and ".join(f"{texts[j]!r} (column {j + 1})" for j in candidates)
            message = (
                f"{option} {spec!r} matches {len(candidates)} headers, {which}: give the "
                f"whole header with its unit, or the column number ({option} N)"
            )
            return _problem(message, file, 0, spec)
    guess = closest_name(spec, texts + [h.name for h in table.headers])
    hint = f"did you mean {guess!r}? " if guess else ""
    message = f"no column {spec!r} ({option}): {hint}the columns are {listing}"
    return _problem(message, file, 0, spec)


def _located(table: DaqTable, j: int, bad: list[tuple[int, str]]) -> list[Problem]:
    """The first few bad cells of column ``j`` one by one, the rest counted."""
    name = table.headers[j].text
    bad.sort()
    out = [
        Problem(f"{text}{table.line(i)}", file=table.file, row=i + 1, column=name)
        for i, text in bad[:MAX_LISTED]
    ]
    if len(bad) > MAX_LISTED:
        more = f"{len(bad) - MAX_LISTED} more cell(s) from here on are not usable either"
        out.append(Problem(more, file=table.file, row=bad[MAX_LISTED][0] + 1, column=name))
    return out


def _clean_numbers(column: RawColumn, mark: str) -> tuple[np.ndarray, int | None] | None:
    """The values and decimals of a column without a single bad cell, in a few passes
    in C (a million-row export in about a second); None if any cell needs a look."""
    if column.skip_rows or not column.text:
        return None
    joined = "\n".join(cell.strip() for cell in column.text)
    if mark == ",":
        if "." in joined:
            return None
        joined = joined.replace(",", ".")
    if not _PLAIN_CHARS.fullmatch(joined):
        return None
    try:
        values = np.array(joined.split("\n"), dtype=np.float64)
    except ValueError:  # e.g. an empty cell, "1e", "+" or "1.2.3": located below
        return None
    if not np.isfinite(values).all():  # 1e999
        return None
    if "e" in joined or "E" in joined:
        return values, None
    return values, max((len(d) for d in _DECIMALS.findall(joined)), default=0)


def parse_numbers(table: DaqTable, j: int) -> tuple[np.ndarray, int | None, list[Problem]]:
    """Column ``j`` as float64, the most digits after a decimal mark (None: unknown, as
    for Parquet floats or exponent notation), and one problem per empty, non-numeric or
    non-finite cell."""
    column = table.columns[j]
    assert isinstance(column, RawColumn)
    bad: list[tuple[int, str]] = []
    if column.numbers is not None:
        values = np.array(column.numbers, dtype=np.float64)
        null = column.null if column.null is not None else np.zeros(values.shape, bool)
        bad += [(int(i), _EMPTY) for i in np.flatnonzero(null)]
        for i in np.flatnonzero(~np.isfinite(values) & ~null):
            bad.append((int(i), f"{values[i]} is not a finite number: fix or delete the row"))
        finite = values[np.isfinite(values)]
        whole = bool(np.all(finite == np.round(finite)))  # integers: 3770 ms is 3.77 s
        return values, 0 if whole else None, _located(table, j, bad)
    clean = _clean_numbers(column, table.decimal)
    if clean is not None:
        return *clean, []
    mark = table.decimal
    other = "." if mark == "," else ","
    values = np.full(table.n_rows, np.nan)
    decimals: int | None = 0
    for row, raw in enumerate(column.text or ()):
        cell = raw.strip()
        if row in column.skip_rows:
            continue
        text = cell.replace(",", ".") if mark == "," else cell
        if not cell:
            bad.append((row, _EMPTY))
        elif other in cell:
            bad.append(
                (
                    row,
                    f"{cell!r} has {other!r} but the decimal mark is {mark!r}: remove "
                    f"thousands separators, or give --decimal {other}",
                )
            )
        elif not _NUMBER.fullmatch(text) or not np.isfinite(value := float(text)):
            bad.append((row, f"{cell!r} is not a number: fix or delete the row"))
        else:
            values[row] = value
            if decimals is not None:
                mantissa, e, _ = text.lower().partition("e")
                decimals = None if e else max(decimals, len(mantissa.partition(".")[2]))
    return values, decimals, _located(table, j, bad)


def parse_flags(table: DaqTable, j: int) -> tuple[np.ndarray, list[Problem]]:
    """Column ``j`` as ON flags: 0/1, true/false or on/off (or a boolean Parquet column)."""
    column = table.columns[j]
    assert isinstance(column, RawColumn)
    hint = "use 1 (ON) or 0 (OFF); for a voltage channel use --trigger instead of --on"
    bad: list[tuple[int, str]] = []
    if column.numbers is not None:
        null = column.null if column.null is not None else np.zeros(column.numbers.shape, bool)
        bad += [(int(i), _EMPTY) for i in np.flatnonzero(null)]
        odd = ~null & (column.numbers != 0.0) & (column.numbers != 1.0)
        bad += [
            (int(i), f"ON flag {column.numbers[i]:g} is not 0 or 1: {hint}")
            for i in np.flatnonzero(odd)
        ]
        return column.numbers == 1.0, _located(table, j, bad)
    flags = np.zeros(table.n_rows, dtype=bool)
    for row, raw in enumerate(column.text or ()):
        token = raw.strip().lower()
        token = token.replace(",", ".").removesuffix(".0")  # 1.0 or 1,0 from a float channel
        if row in column.skip_rows:
            continue
        if token in _FLAGS:
            flags[row] = _FLAGS[token]
        else:
            bad.append(
                (row, _EMPTY if not token else f"ON flag {raw.strip()!r} is not 0 or 1: {hint}")
            )
    return flags, _located(table, j, bad)
