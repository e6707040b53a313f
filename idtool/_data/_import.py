"""DAQ exports into a format-v1 dataset: :func:`import_daq` (``idtool import``).

Each export (CSV in any common dialect, or Parquet; :mod:`idtool._data._import_table`)
gives one trace: its time and force columns converted to s and N, its ON flags from a
trigger channel (:mod:`idtool._data._import_trigger`) or a 0/1 column, its operating
point from a conditions table, the file name or options
(:mod:`idtool._data._import_conditions`). The dataset is written to a temporary folder,
validated with :func:`load_dataset` and only then renamed into place.
"""

from __future__ import annotations

import dataclasses
import os
import re
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from idtool._atomic import atomic_output_dir, refuse_existing
from idtool._data._dataset import Dataset, Rig, load_dataset
from idtool._data._import_columns import find_column, parse_flags, parse_numbers
from idtool._data._import_conditions import Conditions, ConditionSources, conditions_for
from idtool._data._import_table import WHITESPACE, DaqTable, ReadOptions, read_daq
from idtool._data._import_trigger import TriggerSettings, trigger_flags
from idtool._data._import_units import QUANTITIES, column_unit, si_decimals, to_si
from idtool._data._paths import DATASET_FILE
from idtool._data._table_read import MAX_LISTED
from idtool._data._write import document, json_bytes, render_table, trace_entry, write_files
from idtool._errors import IdtoolError, Problem

__all__ = ["import_daq"]

TRACE_FORMATS = ("parquet", "csv")
_SEPARATOR_NAMES = {
    **{"tab": "\t", "\\t": "\t", "comma": ",", "semicolon": ";", "pipe": "|"},
    **{"whitespace": WHITESPACE, "blanks": WHITESPACE, "space": WHITESPACE},
}
_UNSAFE_ID = re.compile(r"[\\/\x00-\x1f]")


@dataclasses.dataclass(frozen=True)
class _Columns:
    """Which columns to read and in which units (None: from the header, else SI)."""

    time: str | int
    force: str | int
    trigger: str | int | None
    on: str | int | None
    time_unit: str | None
    force_unit: str | None
    trigger_unit: str | None


@dataclasses.dataclass(frozen=True)
class _Numbers:
    """A numeric column as read: its header, values, factor to SI, digits written after
    the decimal mark (None: unknown) and a note on where its unit came from."""

    header: str
    values: np.ndarray
    factor: float
    decimals: int | None
    note: str

    def si(self) -> np.ndarray:
        return to_si(self.values, self.factor, self.decimals)


@dataclasses.dataclass(frozen=True)
class _Samples:
    time_s: np.ndarray
    force_n: np.ndarray
    on: np.ndarray
    note: str


_UNIT_OPTIONS = {"time": "--time-unit", "force": "--force-unit", "voltage": "--trigger-unit"}


def _column(
    table: DaqTable, spec: str | int, option: str, quantity: str, unit: str | None
) -> tuple[_Numbers | None, list[Problem]]:
    """The numeric column ``spec`` names, in the unit of its header or ``unit``."""
    j, problems = find_column(table, spec, option)
    if j is None:
        return None, problems
    header = table.headers[j]
    found, how, problems = column_unit(header, unit, quantity, _UNIT_OPTIONS[quantity], table.file)
    if found is None:
        return None, problems
    if isinstance(table.columns[j], str):
        message = f"has Parquet type {table.columns[j]}: store it as numbers"
        return None, [Problem(message, file=table.file, row=0, column=header.text)]
    values, decimals, problems = parse_numbers(table, j)
    if problems:
        return None, problems
    factor = QUANTITIES[quantity][found]
    return _Numbers(
        header.text, values, factor, decimals, f"'{header.text}' in {found} ({how})"
    ), []


def _flags(table: DaqTable, spec: str | int) -> tuple[tuple[np.ndarray, str] | None, list[Problem]]:
    """The 0/1 column ``spec`` names, and a note for the trace."""
    j, problems = find_column(table, spec, "--on")
    if j is None:
        return None, problems
    header = table.headers[j].text
    if isinstance(table.columns[j], str):
        message = f"has Parquet type {table.columns[j]}: store it as booleans or 0/1"
        return None, [Problem(message, file=table.file, row=0, column=header)]
    flags, problems = parse_flags(table, j)
    return (None if problems else (flags, f"ON from the 0/1 column '{header}'")), problems


def _time_problems(table: DaqTable, time_s: np.ndarray, column: str) -> list[Problem]:
    """Times must strictly increase: the first few steps back or repeats, located."""
    bad = np.flatnonzero(np.diff(time_s) <= 0.0) + 1
    out = [
        Problem(
            f"time {time_s[i]:g} s{table.line(int(i))} is not after the previous row's "
            f"({time_s[i - 1]:g} s): sort the rows by time, or remove the repeated sample",
            file=table.file,
            row=int(i) + 1,
            column=column,
        )
        for i in bad[:MAX_LISTED]
    ]
    if bad.size > MAX_LISTED:
        more = f"{bad.size - MAX_LISTED} more row(s) from here on go back in time or repeat"
        out.append(Problem(more, file=table.file, row=int(bad[MAX_LISTED]) + 1, column=column))
    return out


def _samples(
    path: Path, label: str, columns: _Columns, read: ReadOptions, trigger: TriggerSettings
) -> tuple[_Samples | None, list[Problem]]:
    """One export's samples in SI with ON flags, or the problems that prevent them."""
    table, problems = read_daq(path, label, read)
    if table is None:
        return None, problems
    time, found = _column(table, columns.time, "--time", "time", columns.time_unit)
    problems += found
    force, found = _column(table, columns.force, "--force-col", "force", columns.force_unit)
    problems += found
    volts = on = None
    if columns.trigger is not None:
        volts, found = _column(table, columns.trigger, "--trigger", "voltage", columns.trigger_unit)
    else:
        assert columns.on is not None
        on, found = _flags(table, columns.on)
    problems += found
    if table.n_rows < 2:
        problems.append(Problem("fewer than 2 samples: export the whole pull", file=label))
    if problems or time is None or force is None:
        return None, problems
    time_s = time.si()
    problems = _time_problems(table, time_s, time.header)
    if problems:
        return None, problems
    notes = [f"imported from {Path(label).name}: time {time.note}, force {force.note}"]
    start = float(time_s[0])
    if start != 0.0:
        places = si_decimals(time.factor, time.decimals)
        time_s = time_s - start if places is None else np.round(time_s - start, places)
        notes.append(f"time shifted by {-start:.10g} s to start at 0")
    if volts is not None:
        flags, on_note, problems = trigger_flags(
            time_s, to_si(volts.values, volts.factor, None), trigger, label, volts.header
        )
        if flags is None:
            return None, problems
        on = (flags, on_note)
    assert on is not None
    notes.insert(1, on[1])
    return _Samples(time_s, force.si(), on[0], "; ".join(notes)), []


def _trace_ids(labels: Sequence[str]) -> tuple[list[str], list[Problem]]:
    """Trace ids from the file names without suffix: unique, also ignoring case (the
    trace files are named after them), and usable as file names."""
    ids = [Path(label).stem for label in labels]
    problems = []
    first: dict[str, int] = {}
    for k, trace_id in enumerate(ids):
        if not trace_id or _UNSAFE_ID.search(trace_id):
            message = "the file name makes no usable trace id: rename the file"
            problems.append(Problem(message, file=labels[k]))
        j = first.setdefault(trace_id.casefold(), k)
        if j != k:
            message = (
                f"gives the trace id '{trace_id}' as {labels[j]} does (ids come from the "
                "file names, ignoring case): rename one of the files"
            )
            problems.append(Problem(message, file=labels[k]))
    return ids, problems


def _options_problems(
    columns: _Columns, read: ReadOptions, trigger: TriggerSettings, trace_format: str
) -> list[str]:
    """Contradictory or out-of-range options, before any file is read."""
    out = []
    if (columns.trigger is None) == (columns.on is None):
        out.append(
            "give the ON state either as a trigger channel (--trigger) or a 0/1 column (--on)"
        )
    if trace_format not in TRACE_FORMATS:
        out.append(f"unknown trace format {trace_format!r}: use parquet or csv")
    if read.sep is not None and (len(read.sep) != 1 or read.sep in "0123456789.-+eE\"'"):
        out.append(f"--sep {read.sep!r} is not a separator: use ',', ';', tab, '|' or whitespace")
    if read.decimal not in (None, ".", ","):
        out.append(f"--decimal {read.decimal!r}: the decimal mark is '.' or ','")
    if read.skip_rows < 0:
        out.append("--skip-rows must be 0 or more")
    if trigger.debounce_s < 0 or (trigger.hysteresis_v or 0.0) < 0:
        out.append("--debounce and --hysteresis must be 0 or more")
    if trigger.max_on_windows < 1:
        out.append("--max-windows must be 1 or more")
    return out


def _relocated(problems: Sequence[Problem], tmp: Path, out: Path | None) -> tuple[Problem, ...]:
    """Problems found in the temporary folder, named as files of the final one (or, for
    a dataset that is not written, relative to it: ``dataset.json``)."""
    prefix = str(tmp) + os.sep
    new = "" if out is None else str(out) + os.sep
    return tuple(
        dataclasses.replace(p, file=new + p.file.removeprefix(prefix))
        if p.file and p.file.startswith(prefix)
        else p
        for p in problems
    )


def import_daq(
    files: str | os.PathLike[str] | Sequence[str | os.PathLike[str]],
    out: str | os.PathLike[str],
    *,
    name: str,
    material: str,
    vibration_frequency_hz: float,
    max_amplitude_m: float,
    time_column: str | int,
    force_column: str | int,
    trigger_column: str | int | None = None,
    on_column: str | int | None = None,
    time_unit: str | None = None,
    force_unit: str | None = None,
    trigger_unit: str | None = None,
    threshold_v: float | None = None,
    hysteresis_v: float | None = None,
    debounce_s: float = 0.005,
    active_low: bool = False,
    max_on_windows: int = 10,
    conditions: str | os.PathLike[str] | None = None,
    pattern: str | None = None,
    normal_load_n: float | None = None,
    amplitude_fraction: float | None = None,
    pull_speed_m_s: float | None = None,
    load_unit: str | None = None,
    amplitude_unit: str | None = None,
    speed_unit: str | None = None,
    sep: str | None = None,
    decimal: str | None = None,
    skip_rows: int = 0,
    encoding: str | None = None,
    trace_format: str = "parquet",
    mains_frequency_hz: float | None = None,
    description: str | None = None,
    extensions: Mapping[str, Any] | None = None,
    force: bool = False,
) -> Dataset:
    """Import DAQ exports (one file per pull) as the format-v1 dataset folder ``out``.

    Args:
        files: CSV exports (separator ``,`` ``;`` tab ``|`` or blanks and decimal mark
            sniffed unless ``sep``/``decimal`` are given; ``sep`` may be ``"tab"`` or
            ``"whitespace"``) or Parquet files. Trace ids are the file names without suffix.
        out: dataset folder to create (replaced only with ``force=True``).
        name: the dataset's name.
        material: the dataset's materials (free text).
        description: the dataset's description (optional).
        extensions: the dataset's ``x_*`` fields.
        vibration_frequency_hz: the rig's horn frequency [Hz].
        max_amplitude_m: the rig's horn amplitude at 100% command [m].
        mains_frequency_hz: the rig's mains frequency [Hz] (optional).
        time_column: header (matched case-insensitively, with or without its unit) or
            1-based number of the time column.
        force_column: the same for the force column.
        trigger_column: a trigger channel [V]: ON above ``threshold_v`` (default midway
            between its two levels) plus half of ``hysteresis_v`` (default 20% of the
            swing), OFF below it minus half; ON or OFF pulses shorter than
            ``debounce_s`` [s] are ignored; ``active_low``: ON while low; more than
            ``max_on_windows`` ON windows in a trace is an error.
        on_column: instead of a trigger, a 0/1 (true/false, on/off) column.
        time_unit: the time column's unit where its header gives none (a header unit
            must agree); without either, s.
        force_unit: the same for the force column; without either, N.
        trigger_unit: the same for the trigger channel; without either, V.
        conditions: a table (CSV or Parquet) with a ``file`` column and ``load``,
            ``amplitude``, ``speed`` (and optional ``notes``) columns.
        pattern: a regular expression searched in each file name without suffix, with
            named groups ``load_n``, ``load_kn``, ``amplitude_percent``,
            ``amplitude_fraction``, ``speed_m_s``, ``speed_mm_s`` (or ``load``,
            ``amplitude``, ``speed`` in ``load_unit``, ``amplitude_unit``, ``speed_unit``).
        normal_load_n: one normal load for every file [N]. Each file must get each
            quantity (load, amplitude, speed) from exactly one source.
        amplitude_fraction: one commanded amplitude for every file [-].
        pull_speed_m_s: one pull speed for every file [m/s].
        skip_rows: lines above the header to skip.
        encoding: of CSV files (default UTF-8 with or without a byte-order mark).
        trace_format: ``"parquet"`` or ``"csv"``, the written trace tables.
        force: replace an existing ``out``.

    Returns:
        The written dataset as :func:`load_dataset` reads it, with the import's own
        warnings (ignored columns of the conditions table) before its validation
        warnings. Each trace's ``notes`` say where it came from and how its ON flags
        and time origin were found.

    Raises:
        IdtoolError: every problem in every input (file, row, column and what to do);
            nothing is written.
    """
    labels = [str(files)] if isinstance(files, str | os.PathLike) else [str(f) for f in files]
    columns = _Columns(
        time_column, force_column, trigger_column, on_column, time_unit, force_unit, trigger_unit
    )
    read = ReadOptions(
        _SEPARATOR_NAMES.get(sep, sep) if sep else None, decimal, skip_rows, encoding
    )
    trigger = TriggerSettings(threshold_v, hysteresis_v, debounce_s, active_low, max_on_windows)
    wrong = _options_problems(columns, read, trigger, trace_format)
    if not labels:
        wrong.append("no files to import: name at least one export")
    bad_keys = [k for k in extensions or {} if not k.startswith("x_")]
    if bad_keys:
        wrong.append(f"extension fields must start with 'x_': {', '.join(bad_keys)}")
    if wrong:
        raise IdtoolError("; ".join(wrong))
    refuse_existing(out, force)
    ids, problems = _trace_ids(labels)
    constants = {"load": normal_load_n, "amplitude": amplitude_fraction, "speed": pull_speed_m_s}
    sources = ConditionSources(
        table=None if conditions is None else Path(conditions),
        pattern=pattern,
        values={q: float(v) for q, v in constants.items() if v is not None},
        units={"load": load_unit, "amplitude": amplitude_unit, "speed": speed_unit},
    )
    points, found = conditions_for(labels, sources)
    problems += found
    traces: list[_Samples | None] = []
    for label in labels:
        samples, found = _samples(Path(label), label, columns, read, trigger)
        traces.append(samples)
        problems += found
    errors = [p for p in problems if p.severity == "error"]
    if errors or points is None:
        raise IdtoolError(
            f"nothing was written: {len(errors)} error(s) in the input; fix them and import again",
            sorted(problems, key=lambda p: p.severity != "error"),
        )
    mains = None if mains_frequency_hz is None else float(mains_frequency_hz)
    rig = Rig(float(vibration_frequency_hz), float(max_amplitude_m), mains)  # 20000.0 in JSON
    entries, tables = _render(ids, traces, points, trace_format)
    doc = document(name, material, rig, entries, description, extensions)
    with atomic_output_dir(out, force=force) as tmp:
        write_files(tmp, {DATASET_FILE: json_bytes(doc), **tables})
        try:
            dataset = load_dataset(tmp)
        except IdtoolError as err:  # e.g. a rig value out of range: name the written file
            errors = [p for p in err.problems if p.severity == "error"]
            raise IdtoolError(
                f"the dataset it would write is not valid, so nothing was written: "
                f"{len(errors)} error(s); fix the options or inputs they point to",
                _relocated(errors, tmp, None),
            ) from None
    return dataclasses.replace(
        dataset,
        path=Path(out),
        warnings=(*problems, *_relocated(dataset.warnings, tmp, Path(out))),
    )


def _render(
    ids: Sequence[str],
    traces: Sequence[_Samples | None],
    points: Sequence[Conditions],
    trace_format: str,
) -> tuple[list[dict[str, Any]], dict[str, bytes]]:
    """dataset.json's trace entries and the trace tables' bytes by relative path."""
    entries, tables = [], {}
    for trace_id, samples, point in zip(ids, traces, points, strict=True):
        assert samples is not None
        file = f"traces/{trace_id}.{trace_format}"
        tables[file] = render_table(file, samples.time_s, samples.force_n, samples.on)
        notes = samples.note if point.notes is None else f"{point.notes}; {samples.note}"
        entries.append(
            trace_entry(
                trace_id,
                file,
                point.normal_load_n,
                point.amplitude_fraction,
                point.pull_speed_m_s,
                notes,
            )
        )
    return entries, tables
