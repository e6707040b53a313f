"""Read a trace table (CSV or Parquet bytes) into raw columns, without judging the values.

A clean CSV file (:mod:`idtool._data._table_fast`) and a Parquet column of numbers give
``numbers`` (float64 with a null mask); any other CSV file is read cell by cell as text,
so the checks in :mod:`idtool._data._table_check` can quote a bad cell and name its row.
Rows are counted as in :class:`idtool._errors.Problem`: the header is row 0, the first
sample row 1.
"""

from __future__ import annotations

import csv
import dataclasses
import io

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from idtool._data._arrow_numpy import plain_numbers
from idtool._data._schema import trace_columns
from idtool._data._table_fast import clean_csv_columns
from idtool._errors import Problem

__all__ = [
    "RawColumn",
    "RawTable",
    "located_csv_table",
    "parquet_column",
    "read_csv_table",
    "read_parquet_table",
    "read_table",
]

TABLE_SUFFIXES = (".csv", ".parquet")
MAX_LISTED = 5  # located problems listed per kind before they are counted


@dataclasses.dataclass(frozen=True)
class RawColumn:
    """One column as read: ``text`` (str per row) or ``numbers`` (float64, NaN where null).

    ``skip_rows`` holds 0-based row indices whose cells were already reported (a CSV line
    with the wrong number of values): the value checks leave them out.
    """

    text: tuple[str, ...] | None = None
    numbers: np.ndarray | None = None
    null: np.ndarray | None = None
    skip_rows: frozenset[int] = frozenset()


@dataclasses.dataclass(frozen=True)
class RawTable:
    """Column names in file order, their data, and the number of data rows.

    ``unusable`` names columns that exist but could not be read (already reported).
    ``columns`` may leave out columns that are not part of the format (a clean CSV file
    or a Parquet file): only their names matter, for a warning.
    """

    names: tuple[str, ...]
    columns: dict[str, RawColumn]
    n_rows: int
    unusable: frozenset[str] = frozenset()


def read_table(data: bytes, file: str) -> tuple[RawTable | None, list[Problem]]:
    """Read ``data`` as CSV or Parquet according to the suffix of ``file``."""
    if not data:
        message = "the file is empty (0 bytes): export the trace again"
        return None, [Problem(message, file=file, row=0)]
    if file.lower().endswith(".parquet"):
        return read_parquet_table(data, file)
    return read_csv_table(data, file)


def _csv_records(text: str, file: str) -> tuple[list[list[str]], list[int], list[Problem]]:
    """All records with the line each starts on; a csv.Error becomes a problem."""
    reader = csv.reader(io.StringIO(text, newline=""))
    records: list[list[str]] = []
    lines: list[int] = []
    line = 1
    try:
        for record in reader:
            records.append(record)
            lines.append(line)
            line = reader.line_num + 1
    except csv.Error as err:
        row = len(records)  # the record being read; the header is row 0
        message = f"unreadable CSV near line {reader.line_num} ({err}); fix or remove that line"
        return records, lines, [Problem(message, file=file, row=row)]
    return records, lines, []


def _header_problems(header: list[str], file: str) -> list[Problem]:
    problems = []
    if len(header) == 1:
        for sep, name in ((";", "semicolons"), ("\t", "tabs")):
            if sep in header[0]:
                problems.append(
                    Problem(
                        f"the header is separated by {name}: save the CSV with commas "
                        "and a point as the decimal mark",
                        file=file,
                        row=0,
                    )
                )
    seen: set[str] = set()
    for name in header:
        if name in seen:
            problems.append(
                Problem("this column name appears twice: keep one", file=file, row=0, column=name)
            )
        seen.add(name)
    return problems


def read_csv_table(data: bytes, file: str) -> tuple[RawTable | None, list[Problem]]:
    """Parse UTF-8, comma-separated ``data``; the first line names the columns.

    A clean file is parsed by pyarrow (:mod:`idtool._data._table_fast`, 0.2-0.7 s for
    2.5 million rows) into ``numbers`` columns of the format's columns only; any other
    file by :func:`located_csv_table`, which names the file, row and column of each bad
    cell. Both give the same samples and problems for every file.
    """
    clean = clean_csv_columns(data)
    if clean is None:
        return located_csv_table(data, file)
    columns = {
        name: RawColumn(numbers=values, null=np.zeros(values.size, bool))
        for name, values in clean.numbers.items()
    }
    return RawTable(clean.names, columns, clean.n_rows), []


def located_csv_table(data: bytes, file: str) -> tuple[RawTable | None, list[Problem]]:
    """Parse ``data`` cell by cell into text columns, keeping each line's number, so
    the checks can quote a bad cell and locate it (slow: seconds per million rows)."""
    try:
        text = data.decode("utf-8-sig")
    except UnicodeDecodeError as err:
        return None, [
            Problem(f"not UTF-8 text (byte {err.start}): save the CSV as UTF-8", file=file)
        ]
    if not text.strip():
        message = "the file has no header and no rows: export it again"
        return None, [Problem(message, file=file, row=0)]
    records, lines, problems = _csv_records(text, file)
    while records and not any(cell.strip() for cell in records[-1]):
        records.pop()  # blank lines at the end are harmless
        lines.pop()
    header = [name.strip() for name in records[0]]
    problems += _header_problems(header, file)
    width = len(header)
    rows = records[1:]
    skip = [i for i, record in enumerate(rows) if len(record) != width]
    for i in skip[:MAX_LISTED]:
        what = "is blank" if not rows[i] else f"has {len(rows[i])} values"
        # Locate at the first column without a value, or the last one before extras.
        column = header[min(len(rows[i]), width - 1)] if header else None
        problems.append(
            Problem(
                f"line {lines[i + 1]} {what} but the header names {width} columns: "
                "give one value per column (or delete the line)",
                file=file,
                row=i + 1,
                column=column,
            )
        )
    if len(skip) > MAX_LISTED:
        more = len(skip) - MAX_LISTED
        message = f"{more} more line(s) from here on have the wrong number of values"
        problems.append(Problem(message, file=file, row=skip[MAX_LISTED] + 1))
    padded = [r if len(r) == width else [*r[:width], *[""] * (width - len(r))] for r in rows]
    cells = list(zip(*padded, strict=True)) if padded else [() for _ in header]
    columns: dict[str, RawColumn] = {}
    for j, name in enumerate(header):
        # setdefault keeps the first of duplicated names (reported above)
        columns.setdefault(name, RawColumn(text=tuple(cells[j]), skip_rows=frozenset(skip)))
    return RawTable(tuple(header), columns, len(rows)), problems


def parquet_column(column: pa.ChunkedArray) -> RawColumn | str:
    """The column's data, or the name of its unsupported type."""
    kind = column.type
    if pa.types.is_dictionary(kind):
        column = column.cast(kind.value_type)
        kind = column.type
    plain = plain_numbers(column)
    if plain is not None:
        return RawColumn(numbers=plain, null=np.zeros(plain.size, bool))
    null = np.asarray(column.is_null().to_numpy(zero_copy_only=False), dtype=bool)
    if pa.types.is_string(kind) or pa.types.is_large_string(kind):
        values = column.to_pylist()
        return RawColumn(text=tuple("" if v is None else v for v in values), null=null)
    numeric = (
        pa.types.is_integer(kind)
        or pa.types.is_floating(kind)
        or pa.types.is_boolean(kind)
        or pa.types.is_decimal(kind)
    )
    if not numeric:
        return str(kind)
    as_float = column.cast(pa.float64(), safe=False).fill_null(float("nan"))
    numbers = np.asarray(as_float.to_numpy(zero_copy_only=False), dtype=np.float64)
    return RawColumn(numbers=numbers, null=null)


def read_parquet_table(data: bytes, file: str) -> tuple[RawTable | None, list[Problem]]:
    """Read Parquet ``data``; columns must be numbers, booleans or text."""
    try:
        # ParquetFile, not pq.read_table: that goes through pyarrow.dataset, whose
        # import pulls in pandas (0.3 s of a fit's 0.4 s of loading the example)
        table = pq.ParquetFile(pa.BufferReader(data)).read()
        names = tuple(str(n) for n in table.column_names)  # may hold invalid UTF-8
    except Exception as err:  # pyarrow raises many types on corrupt input; all mean "bad file"
        message = (
            f"not a readable Parquet file ({type(err).__name__}: {err}); "
            "export the trace again (or save it as .csv)"
        )
        return None, [Problem(message, file=file)]
    problems = _header_problems(list(names), file) if len(set(names)) < len(names) else []
    columns: dict[str, RawColumn] = {}
    unusable: set[str] = set()
    for j, name in enumerate(names):
        if name in columns or name in unusable:
            continue
        if name not in trace_columns():
            unusable.add(name)  # ignored, with a warning from the column check
            continue
        try:
            raw = parquet_column(table.column(j))
        except Exception as err:  # same reason: a corrupt page can fail only when decoded
            message = f"unreadable column ({err}); export the trace again"
            problems.append(Problem(message, file=file, row=0, column=name))
            unusable.add(name)
            continue
        if isinstance(raw, str):
            problems.append(
                Problem(
                    f"has Parquet type {raw}: store it as float64 (booleans or 0/1 integers "
                    "for ultrasound_on)",
                    file=file,
                    row=0,
                    column=name,
                )
            )
            unusable.add(name)
            continue
        columns[name] = raw
    return RawTable(names, columns, table.num_rows, frozenset(unusable)), problems
