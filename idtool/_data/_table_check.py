"""Check a raw trace table and turn it into clean sample arrays (format v1 trace table).

Every problem names the file, the row (header = row 0, first sample = row 1) and the
column, and says what to fix. A problem repeated down a column is listed for its first
few rows, then counted, so a broken file gives a readable report.
"""

from __future__ import annotations

import dataclasses
import re
from collections.abc import Callable

import numpy as np

from idtool._data._schema import closest_name, trace_columns
from idtool._data._table_read import MAX_LISTED, RawColumn, RawTable
from idtool._errors import Problem

__all__ = ["TraceSamples", "check_table", "on_windows"]

IRREGULAR_TOLERANCE = 0.01  # relative deviation of a time step from the median step

# ASCII only: no Unicode digits or exotic blanks, which other readers would reject.
_NUMBER = re.compile(r"\s*[+-]?(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?\s*", re.ASCII)
_NONFINITE = re.compile(r"\s*[+-]?(?:nan|inf|infinity)\s*", re.IGNORECASE | re.ASCII)
_FLAGS = {"0": False, "1": True, "false": False, "true": True, "0.0": False, "1.0": True}


@dataclasses.dataclass(frozen=True)
class TraceSamples:
    """Clean samples of one trace: times [s], forces [N], ON flags, derived timing."""

    time_s: np.ndarray
    force_n: np.ndarray
    ultrasound_on: np.ndarray
    on_windows_s: tuple[tuple[float, float], ...]
    sample_rate_hz: float


class _Collector:
    """Problems of one kind in one column: the first few located, the rest counted."""

    def __init__(self, file: str, column: str, message: Callable[[str], str]):
        self.file, self.column, self.message = file, column, message
        self.rows: list[tuple[int, str]] = []

    def add(self, index: int, cell: str) -> None:
        self.rows.append((index + 1, cell))

    def problems(self) -> list[Problem]:
        out = [
            Problem(self.message(cell), file=self.file, row=row, column=self.column)
            for row, cell in self.rows[:MAX_LISTED]
        ]
        if len(self.rows) > MAX_LISTED:
            row = self.rows[MAX_LISTED][0]
            more = len(self.rows) - MAX_LISTED
            text = f"{more} more row(s) from here on have the same problem: {self.message('…')}"
            out.append(Problem(text, file=self.file, row=row, column=self.column))
        return out


def _empty(_: str) -> str:
    return "empty cell: every sample needs a value here (or delete the row)"


def _nonfinite(cell: str) -> str:
    return (
        f"{cell.strip()!r} is not a finite number: replace it by a measured value or delete the row"
    )


def _parse_numbers(col: RawColumn, name: str, file: str) -> tuple[np.ndarray, list[Problem]]:
    """The column as float64 (NaN where bad) and one problem per bad cell."""
    empty = _Collector(file, name, _empty)
    nonfinite = _Collector(file, name, _nonfinite)
    text = _Collector(
        file,
        name,
        lambda c: (
            f"{c!r} is not a number: write a plain number with a point as the decimal "
            "mark (e.g. 12.5)"
        ),
    )
    if col.numbers is not None:
        values = col.numbers.astype(np.float64)
        null = col.null if col.null is not None else np.zeros(values.shape, bool)
        for i in np.flatnonzero(null):
            empty.add(int(i), "")
        for i in np.flatnonzero(~np.isfinite(values) & ~null):
            nonfinite.add(int(i), str(values[i]))
    else:
        cells = col.text or ()
        good = []
        for row, cell in enumerate(cells):
            if row in col.skip_rows:
                good.append("nan")
            elif _NUMBER.fullmatch(cell):
                good.append(cell.strip())
            else:
                good.append("nan")
                (
                    empty if not cell.strip() else nonfinite if _NONFINITE.fullmatch(cell) else text
                ).add(row, cell)
        values = np.asarray(good, dtype=np.float64) if good else np.zeros(0)
        for i in np.flatnonzero(np.isinf(values)):  # e.g. 1e999 overflows
            nonfinite.add(int(i), cells[i])
    return values, [*empty.problems(), *nonfinite.problems(), *text.problems()]


def _parse_flags(col: RawColumn, name: str, file: str) -> tuple[np.ndarray, list[Problem]]:
    """The ON flags as bool and one problem per cell that is not 0/1/true/false."""
    bad = _Collector(
        file, name, lambda c: f"ON flag {c!r} is not 0, 1, true or false: use 1 (ON) or 0 (OFF)"
    )
    empty = _Collector(file, name, _empty)
    if col.numbers is not None:
        null = col.null if col.null is not None else np.zeros(col.numbers.shape, bool)
        for i in np.flatnonzero(null):
            empty.add(int(i), "")
        for i in np.flatnonzero(~null & (col.numbers != 0.0) & (col.numbers != 1.0)):
            bad.add(int(i), f"{col.numbers[i]:g}")
        flags = col.numbers == 1.0
    else:
        cells = col.text or ()
        flags = np.zeros(len(cells), dtype=bool)
        for row, cell in enumerate(cells):
            token = cell.strip(" \t\n\r\f\v").lower()
            if row in col.skip_rows:
                continue
            if token in _FLAGS:
                flags[row] = _FLAGS[token]
            else:
                (empty if not token else bad).add(row, cell)
    return flags, [*empty.problems(), *bad.problems()]


def _column_problems(table: RawTable, file: str) -> list[Problem]:
    """Missing or misspelled required columns (errors) and extra columns (warnings)."""
    required = trace_columns()
    extra = [n for n in table.names if n not in required]
    problems, claimed = [], set()
    for name in required:
        if name in table.columns or name in table.unusable:
            continue
        guess = closest_name(name, [e for e in extra if e not in claimed])
        if guess is not None:
            claimed.add(guess)
            message = f"missing column '{name}': the header has '{guess}'; rename it to '{name}'"
        else:
            have = ", ".join(repr(n) for n in table.names) or "nothing"
            message = f"missing column '{name}' (the header has {have}): add it"
        problems.append(Problem(message, file=file, row=0, column=name))
    for name in extra:
        if name in claimed:
            continue
        guess = closest_name(name, required)
        hint = f" (did you mean '{guess}'?)" if guess else ""
        problems.append(
            Problem(
                f"column '{name}' is not part of format v1 and is ignored{hint}",
                file=file,
                row=0,
                column=name,
                severity="warning",
            )
        )
    return problems


def _time_problems(time_s: np.ndarray, file: str, column: str) -> list[Problem]:
    """Times must strictly increase: duplicates and steps back are errors."""
    step = np.diff(time_s)
    dup = _Collector(
        file, column, lambda c: f"time {c} repeats the previous row's: remove the duplicate sample"
    )
    back = _Collector(
        file,
        column,
        lambda c: (
            f"time {c} is earlier than the previous row's: sort the rows by time or fix the value"
        ),
    )
    for i in np.flatnonzero(step <= 0.0):
        (dup if step[i] == 0.0 else back).add(int(i) + 1, f"{time_s[i + 1]:g}")
    return [*dup.problems(), *back.problems()]


def _sampling(time_s: np.ndarray, file: str, column: str) -> tuple[float, list[Problem]]:
    """Sample rate [Hz] from the median step, and a warning if the steps vary."""
    step = np.diff(time_s)
    median = float(np.median(step))
    off = np.abs(step - median) > IRREGULAR_TOLERANCE * median
    if not np.any(off):
        return 1.0 / median, []
    worst = int(np.argmax(np.abs(step - median)))
    message = (
        f"irregular sampling: {int(off.sum())} of {step.size} time steps differ from the "
        f"median step {median * 1e3:.4g} ms by more than {IRREGULAR_TOLERANCE:.0%}; the "
        f"largest, {step[worst] * 1e3:.4g} ms, ends here (accepted; check for lost samples)"
    )
    return 1.0 / median, [
        Problem(message, file=file, row=worst + 2, column=column, severity="warning")
    ]


def on_windows(
    time_s: np.ndarray, on: np.ndarray, step_s: float
) -> tuple[tuple[float, float], ...]:
    """ON windows ``(start_s, end_s)``: first ON sample, first OFF sample after it.

    A window still ON at the last sample ends one median step ``step_s`` after it, so a
    window's length is always its number of ON samples times the step.
    """
    flags = np.concatenate([[False], on, [False]]).astype(np.int8)
    edges = np.diff(flags)
    starts, ends = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)
    padded = np.concatenate([time_s, [time_s[-1] + step_s]])
    return tuple((float(padded[s]), float(padded[e])) for s, e in zip(starts, ends, strict=True))


def check_table(table: RawTable, file: str) -> tuple[TraceSamples | None, list[Problem]]:
    """Validate ``table`` (read from ``file``); samples only if it has no errors."""
    problems = _column_problems(table, file)
    time_name, force_name, flag_name = trace_columns()
    if table.n_rows < 2:
        problems.append(
            Problem(
                f"has {table.n_rows} data row(s): a trace needs at least 2 samples",
                file=file,
                row=table.n_rows,
            )
        )
    parsed: dict[str, np.ndarray] = {}
    clean: set[str] = set()
    for name in (time_name, force_name, flag_name):
        if name not in table.columns:
            continue
        parse = _parse_flags if name == flag_name else _parse_numbers
        values, found = parse(table.columns[name], name, file)
        parsed[name] = values
        problems += found
        if not found and not table.columns[name].skip_rows:
            clean.add(name)
    rate = float("nan")
    if time_name in clean and table.n_rows >= 2:
        order = _time_problems(parsed[time_name], file, time_name)
        problems += order
        if not order:
            rate, irregular = _sampling(parsed[time_name], file, time_name)
            problems += irregular
    reported = any(c.skip_rows for c in table.columns.values())  # by the reader
    if reported or len(clean) < 3 or any(p.severity == "error" for p in problems):
        return None, problems
    time_s, flags = parsed[time_name], parsed[flag_name]
    samples = TraceSamples(
        time_s=time_s,
        force_n=parsed[force_name],
        ultrasound_on=flags.astype(bool),
        on_windows_s=on_windows(time_s, flags.astype(bool), 1.0 / rate),
        sample_rate_hz=rate,
    )
    return samples, problems
