"""Read one DAQ export (CSV in any common dialect, or Parquet) into raw columns.

CSV: UTF-8 with or without a byte-order mark (UTF-16 with one, or any ``encoding``),
CRLF, LF or CR line ends; ``skip_rows`` lines, then blank or ``#`` comment lines, are
skipped; then a header line, optionally a line of units (``s;N;V``), then the samples.
The separator (``,`` ``;`` tab ``|`` or blanks) and the decimal mark (``.`` or ``,``)
are sniffed unless given. Rows are counted as in :class:`idtool._errors.Problem` (the
header is row 0, the first sample row 1); messages add the file's line number.
"""

from __future__ import annotations

import codecs
import csv
import dataclasses
import re
from pathlib import Path

import pyarrow as pa
import pyarrow.parquet as pq

from idtool._data._import_units import Header, canonical_unit, parse_header
from idtool._data._table_read import MAX_LISTED, RawColumn, parquet_column
from idtool._errors import Problem

__all__ = ["WHITESPACE", "DaqTable", "ReadOptions", "read_daq", "separator_name"]

WHITESPACE = " "  # as a separator: any run of blanks or tabs
_SEPARATORS = (";", "\t", ",", "|", WHITESPACE)
SNIFF_LINES = 200  # data lines the separator must split like the header
SNIFF_AGREEMENT = 0.9  # of them, at least this fraction
_POINT = re.compile(r"[+-]?\d*\.\d+(?:[eE][+-]?\d+)?", re.ASCII)
_COMMA = re.compile(r"[+-]?\d*,\d+(?:[eE][+-]?\d+)?", re.ASCII)


def separator_name(sep: str) -> str:
    """How messages name a separator."""
    return {"\t": "tab", WHITESPACE: "blanks"}.get(sep, repr(sep))


@dataclasses.dataclass(frozen=True)
class ReadOptions:
    """How to read CSV exports; None sniffs. ``sep``: one character, or
    :data:`WHITESPACE` for runs of blanks; ``decimal``: ``"."`` or ``","``;
    ``skip_rows``: lines above the header to skip (metadata)."""

    sep: str | None = None
    decimal: str | None = None
    skip_rows: int = 0
    encoding: str | None = None


@dataclasses.dataclass(frozen=True)
class DaqTable:
    """One export as read: headers, raw columns (text, or numbers for Parquet), the
    file line of each data row (CSV only), the separator and the decimal mark."""

    file: str
    headers: tuple[Header, ...]
    columns: tuple[RawColumn | str, ...]  # str: the Parquet type it cannot read
    n_rows: int
    lines: tuple[int, ...] | None = None
    sep: str | None = None
    decimal: str = "."

    def line(self, index: int) -> str:
        """`` (line N)`` for data row ``index`` (0-based) of a CSV file, else ``""``."""
        return f" (line {self.lines[index]})" if self.lines is not None else ""


def _problem(
    message: str, file: str, row: int | None = None, column: str | None = None
) -> tuple[None, list[Problem]]:
    return None, [Problem(message, file=file, row=row, column=column)]


def read_daq(path: Path, file: str, options: ReadOptions) -> tuple[DaqTable | None, list[Problem]]:
    """Read the export at ``path`` (named ``file`` in messages): Parquet by its suffix,
    else CSV."""
    try:
        data = path.read_bytes()
    except OSError as err:
        return _problem(f"cannot read the file ({err.strerror or err}): check the path", file)
    if not data.strip():
        return _problem("the file is empty: export the data again", file)
    if path.suffix.lower() == ".parquet":
        return _read_parquet(data, file)
    text, problems = _decode(data, file, options.encoding)
    if text is None:
        return None, problems
    return _read_csv(text, file, options)


def _decode(data: bytes, file: str, encoding: str | None) -> tuple[str | None, list[Problem]]:
    if encoding is None and data.startswith((codecs.BOM_UTF16_LE, codecs.BOM_UTF16_BE)):
        encoding = "utf-16"
    try:
        return data.decode(encoding or "utf-8-sig"), []
    except LookupError:
        return _problem(f"unknown encoding {encoding!r}: use e.g. utf-8, cp1252, latin-1", file)
    except UnicodeDecodeError as err:
        line = data[: err.start].count(b"\n") + 1
        message = (
            f"line {line} is not valid {err.encoding} (byte {data[err.start]:#04x}): give "
            "the file's encoding, e.g. --encoding cp1252 (most Windows exports)"
        )
        return _problem(message, file)


def _fields(line: str, sep: str) -> list[str]:
    return line.split() if sep == WHITESPACE else next(csv.reader([line], delimiter=sep))


def _sniff_sep(header: str, sample: list[str], file: str) -> tuple[str | None, list[Problem]]:
    """The one separator that splits the header into 2 or more columns and nearly all
    of the first lines alike (a broken line is reported later, with its row)."""
    fits = {}
    for sep in _SEPARATORS:
        n = len(_fields(header, sep))
        alike = sum(len(_fields(line, sep)) == n for line in sample)
        if n >= 2 and alike >= SNIFF_AGREEMENT * len(sample):
            fits[sep] = n
    if len(fits) > 1:  # blanks inside names ("Time (s)") must not beat a real separator
        fits.pop(WHITESPACE, None)
    if len(fits) == 1:
        return next(iter(fits)), []
    if fits:
        both = " or ".join(f"{separator_name(s)} ({n} columns)" for s, n in fits.items())
        return _problem(f"the columns could be split by {both}: give --sep", file, 0)
    header_commas = len(_fields(header, ","))
    if sample and header_commas >= 2 and all(len(_fields(s, ",")) > header_commas for s in sample):
        message = (
            "the samples have more commas than the header: decimal commas in a "
            "comma-separated file cannot be told apart from separators; export with "
            "another separator (e.g. ';') or with a point as the decimal mark"
        )
        return _problem(message, file, 1)
    message = (
        "cannot tell the separator: none of ',' ';' tab '|' or blanks splits the header "
        f"and the next {len(sample)} line(s) into the same number (2 or more) of columns; "
        "give --sep, and --skip-rows N if metadata lines stand above the header"
    )
    return _problem(message, file, 0)


def _units_row(cells: list[str]) -> bool:
    """A line of units under the header (``s;N;V``, ``[s];[N];[V]``)."""
    units = [canonical_unit(c.strip().strip("()[]{}")) for c in cells if c.strip()]
    return bool(units) and all(units)


def _with_units(
    headers: list[str], units: list[str], file: str
) -> tuple[list[Header], list[Problem]]:
    """The headers, with the unit of a units line where the header itself has none."""
    out, problems = [], []
    for text, unit in zip(headers, [*units, *[""] * len(headers)], strict=False):
        header = parse_header(text)
        unit = unit.strip().strip("()[]{}")
        if unit and header.unit_text is None:
            header = Header(text, header.name, unit, canonical_unit(unit))
        elif unit and canonical_unit(unit) != header.unit:
            message = f"the header says '{header.unit_text}' but the units line says '{unit}'"
            problems.append(Problem(message + ": fix one", file=file, row=0, column=text))
        out.append(header)
    return out, problems


def _read_csv(text: str, file: str, options: ReadOptions) -> tuple[DaqTable | None, list[Problem]]:
    lines = re.split(r"\r\n|\r|\n", text)
    start = options.skip_rows
    while start < len(lines) and (not lines[start].strip() or lines[start].startswith("#")):
        start += 1
    if start >= len(lines):
        return _problem(f"no header line after skipping {options.skip_rows} line(s)", file)
    numbered = [(k + 1, line) for k, line in enumerate(lines) if k > start and line.strip()]
    sep = options.sep
    if sep is None:
        sep, problems = _sniff_sep(lines[start], [s for _, s in numbered[:SNIFF_LINES]], file)
        if sep is None:
            return None, problems
    names = [c.strip() for c in _fields(lines[start], sep)]
    if len(names) < 2:
        message = f"--sep {separator_name(sep)} splits the header into 1 column: check --sep"
        return _problem(message, file, 0)
    rows = (
        [s.split() for _, s in numbered]
        if sep == WHITESPACE
        else list(csv.reader([s for _, s in numbered], delimiter=sep))
    )
    units: list[str] = []
    if rows and _units_row(rows[0]):
        units, rows, numbered = rows[0], rows[1:], numbered[1:]
    headers, problems = _with_units(names, units, file)
    width = len(names)
    if names[-1] == "" and all(len(r) == width and not r[-1].strip() for r in rows):
        width, headers = width - 1, headers[:-1]  # a separator at the end of every line
        rows = [r[:-1] for r in rows]
    wrong = [i for i, r in enumerate(rows) if len(r) != width]
    for i in wrong[:MAX_LISTED]:
        problems.append(
            Problem(
                f"line {numbered[i][0]} has {len(rows[i])} values but the header names "
                f"{width} columns: give one value per column (or delete the line)",
                file=file,
                row=i + 1,
            )
        )
    if len(wrong) > MAX_LISTED:
        more = f"{len(wrong) - MAX_LISTED} more line(s) have the wrong number of values"
        problems.append(Problem(more, file=file, row=wrong[MAX_LISTED] + 1))
    # padded only if needed: a copy of every row costs 1.5 s per million rows
    padded = [r[:width] + [""] * (width - len(r)) for r in rows] if wrong else rows
    cells = list(zip(*padded, strict=True)) if padded else [() for _ in range(width)]
    skip = frozenset(wrong)
    columns = tuple(RawColumn(text=tuple(c), skip_rows=skip) for c in cells)
    decimal, found = _decimal(options, sep, columns, headers, file)
    problems += found
    line_numbers = tuple(k for k, _ in numbered)
    table = DaqTable(file, tuple(headers), columns, len(rows), line_numbers, sep, decimal)
    return (None if problems else table), problems


def _decimal(
    options: ReadOptions, sep: str, columns: tuple[RawColumn, ...], headers: list[Header], file: str
) -> tuple[str, list[Problem]]:
    """The decimal mark: given, or the one the cells use; both in use is an error."""
    if options.decimal is not None:
        if options.decimal == sep:
            message = f"the separator and the decimal mark are both {sep!r}: check --decimal"
            return options.decimal, [Problem(message, file=file)]
        return options.decimal, []
    if sep == ",":
        return ".", []
    seen: dict[str, tuple[int, str, str]] = {}
    for header, column in zip(headers, columns, strict=True):
        for i, cell in enumerate((column.text or ())[: SNIFF_LINES * 10]):
            for mark, pattern in ((".", _POINT), (",", _COMMA)):
                if mark not in seen and pattern.fullmatch(cell.strip()):
                    seen[mark] = (i + 1, header.text, cell.strip())
    if len(seen) == 2:
        # located at the later cell: the one that breaks the pattern of the file so far
        first, later = sorted(seen.values())
        message = (
            f"the decimal mark is unclear: {later[2]!r} here but {first[2]!r} in row "
            f"{first[0]}, column '{first[1]}': give --decimal . or --decimal ,"
        )
        return ".", [Problem(message, file=file, row=later[0], column=later[1])]
    return ("," if "," in seen else "."), []


def _read_parquet(data: bytes, file: str) -> tuple[DaqTable | None, list[Problem]]:
    try:
        table = pq.read_table(pa.BufferReader(data))
        columns = tuple(parquet_column(table.column(j)) for j in range(table.num_columns))
    except Exception as err:  # pyarrow raises many types on a corrupt file
        return _problem(f"not a readable Parquet file ({type(err).__name__}: {err})", file)
    headers = tuple(parse_header(str(n)) for n in table.column_names)
    return DaqTable(file, headers, columns, table.num_rows), []
