"""Read a clean CSV trace table in one pass with pyarrow; None whenever a cell needs a look.

A 50 kHz, 50 s pull is 2.5 million rows: the located reader
(:func:`idtool._data._table_read.located_csv_table`) keeps every cell as Python text so
it can quote a bad one and name its row, which takes seconds per trace and hundreds of
MB. Nearly every file is clean, so :func:`clean_csv_columns` first lets pyarrow's C++
reader parse the whole file and accepts its numbers only when the located reader and
the checks of :mod:`idtool._data._table_check` would have accepted every cell with the
very same value. It gives up (returns None) on anything it cannot prove is so:

* quotes or NUL bytes anywhere, any non-ASCII byte below the header, a line longer
  than half of ``csv.field_size_limit()``;
* a header that repeats a name or lacks one of the format's columns;
* blank lines (other than at the end), a line with the wrong number of values;
* a number pyarrow rejects (it rejects a superset of what the located checks reject,
  except NaN, inf and overflow, which it reads as non-finite values: those are refused
  here after reading), a flag other than ``0 1 0.0 1.0 true True TRUE false False
  FALSE`` (the other spellings the located checks accept, e.g. ``tRue`` or `` 1``, are
  left to them), fewer than 2 rows.

pyarrow's float parsing is correctly rounded, as is Python's ``float``, so an accepted
number has the value the located path gives it (``tests/test_table_fast.py`` holds
both paths to that, cell by cell). The caller then falls back to the located reader,
whose messages are unchanged.
"""

from __future__ import annotations

import codecs
import csv
import dataclasses

import numpy as np
import pyarrow as pa
import pyarrow.csv as pa_csv

from idtool._data._arrow_numpy import plain_numbers
from idtool._data._schema import trace_columns

__all__ = ["CleanCsv", "clean_csv_columns"]

MIN_ROWS = 2  # below this check_table reports the table (the located path is instant)
_TRUE = ["1", "1.0", "true", "True", "TRUE"]
_FALSE = ["0", "0.0", "false", "False", "FALSE"]
_LINE_ENDS = (b"\n", b"\r")


@dataclasses.dataclass(frozen=True)
class CleanCsv:
    """A CSV table whose format columns are all clean: the header names (stripped, in
    file order), each format column as float64 (flags as 0.0/1.0) and the row count."""

    names: tuple[str, ...]
    numbers: dict[str, np.ndarray]
    n_rows: int


def _header_end(data: bytes, start: int) -> int:
    """Index of the first line end at or after ``start`` (len(data) if none)."""
    ends = [i for i in (data.find(end, start) for end in _LINE_ENDS) if i >= 0]
    return min(ends, default=len(data))


def _has_long_line(data: bytes, start: int, stop: int) -> bool:
    """Whether a line may be longer than ``csv.field_size_limit()`` (the located reader
    then fails with a located error): some aligned window of half that length holds no
    line end. A line that long always covers one such window; a window without a line
    end means a line of at least half the limit, so this may refuse a file the located
    reader accepts, never the other way round. A few hundred ``find`` calls per 45 MB."""
    window = max(csv.field_size_limit() // 2, 1)
    for lo in range(start, stop - window + 1, window):
        if all(data.find(end, lo, lo + window) < 0 for end in _LINE_ENDS):
            return True
    return False


def _names(header: bytes) -> list[str] | None:
    """The header's names as the located reader reads them, or None if it would not."""
    try:
        text = header.decode("utf-8")
    except UnicodeDecodeError:
        return None
    return [name.strip() for name in next(csv.reader([text]), [])]


def clean_csv_columns(data: bytes) -> CleanCsv | None:
    """The format columns of ``data`` as numbers, or None when any cell, line or name of
    the file is not plainly clean (the located reader then reads it and says why)."""
    start = len(codecs.BOM_UTF8) if data.startswith(codecs.BOM_UTF8) else 0
    stop = len(data)
    while stop > start and data[stop - 1] in b"\r\n":
        stop -= 1  # blank lines at the end are harmless (as for the located reader)
    if b'"' in data or b"\x00" in data:
        return None
    end = _header_end(data, start)
    names = _names(data[start:end])
    required = trace_columns()
    if names is None or len(set(names)) < len(names) or not set(required) <= set(names):
        return None
    body = np.frombuffer(data, np.uint8, count=stop - end, offset=end) if stop > end else None
    if body is None or int(body.max()) >= 0x80 or _has_long_line(data, start, stop):
        return None
    keys = [f"c{j}" for j in range(len(names))]  # the names may be anything pyarrow dislikes
    wanted = {keys[names.index(name)]: name for name in required}
    flag = keys[names.index(required[2])]
    try:
        table = pa_csv.read_csv(
            pa.BufferReader(pa.py_buffer(data).slice(start, stop - start)),
            read_options=pa_csv.ReadOptions(skip_rows=1, column_names=keys),
            parse_options=pa_csv.ParseOptions(
                delimiter=",",
                quote_char=False,
                escape_char=False,
                newlines_in_values=False,
                ignore_empty_lines=False,  # a blank line inside the table is an error
            ),
            convert_options=pa_csv.ConvertOptions(
                column_types={k: pa.bool_() if k == flag else pa.float64() for k in wanted},
                include_columns=list(wanted),
                null_values=[],
                true_values=_TRUE,
                false_values=_FALSE,
                strings_can_be_null=False,
                quoted_strings_can_be_null=False,
            ),
        )
    except pa.ArrowException:
        return None  # a cell or a line the located reader will name
    if table.num_rows < MIN_ROWS:
        return None
    numbers = {}
    for key, name in wanted.items():
        values = plain_numbers(table.column(key))
        if values is None or values.size != table.num_rows or not np.isfinite(values).all():
            return None
        numbers[name] = values
    return CleanCsv(tuple(names), numbers, table.num_rows)
