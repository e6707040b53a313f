"""The pyarrow CSV path gives exactly what the located, cell-by-cell path gives.

:func:`idtool._data._table_read.read_csv_table` parses a clean file with pyarrow and any
other with :func:`located_csv_table`. Every file, clean or tricky, must come out of
:func:`check_table` with the same samples (bit for bit) and the same problems either
way; these tests run both and compare, and check that clean files do take the fast path.
"""

from __future__ import annotations

import codecs
import csv

import numpy as np
import pytest
from bench_data_helpers import make_dataset
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import idtool._data._table_read as table_read
from idtool import load_dataset
from idtool._data._table_check import check_table
from idtool._data._table_fast import clean_csv_columns
from idtool._data._table_read import located_csv_table, read_csv_table

FILE = "traces/t.csv"
HEADER = "time_s,force_n,ultrasound_on"


def _table(*rows: str, header: str = HEADER, end: str = "\n") -> bytes:
    return (end.join([header, *rows]) + end).encode()


def _rows(n: int = 8, force: dict[int, str] | None = None, flag: dict[int, str] | None = None):
    """``n`` clean rows at 100 Hz, ON from the fourth; cells replaced by index."""
    force, flag = force or {}, flag or {}
    return [
        f"{i / 100:.2f},{force.get(i, f'{10 + i}.25')},{flag.get(i, '1' if i >= 3 else '0')}"
        for i in range(n)
    ]


def _plus_column(name: str, cell: str, last: str | None = None) -> bytes:
    """A clean table with one more column, ``name``, holding ``cell`` (``last`` in the
    last row, if given)."""
    rows = [f"{r},{cell}" for r in _rows()]
    if last is not None:
        rows[-1] = rows[-1].rpartition(",")[0] + "," + last
    return _table(*rows, header=f"{HEADER},{name}")


def _outcome(read, data: bytes):
    """What load_dataset would make of ``data`` read by ``read``: the problems, and the
    samples' arrays as bytes (bit-exact, -0.0 is not 0.0), windows and rate."""
    table, problems = read(data, FILE)
    if table is None:
        return problems, None
    samples, found = check_table(table, FILE)
    problems = problems + found
    if samples is None:
        return problems, None
    arrays = (samples.time_s, samples.force_n, samples.ultrasound_on)
    return problems, (
        *(np.ascontiguousarray(a).tobytes() for a in arrays),
        [a.dtype.str for a in arrays],
        samples.on_windows_s,
        samples.sample_rate_hz,
    )


def _same_both_ways(data: bytes) -> bool:
    """Assert both readers agree on ``data``; whether the fast path took it."""
    assert _outcome(read_csv_table, data) == _outcome(located_csv_table, data)
    return clean_csv_columns(data) is not None


LONG = "0" * (csv.field_size_limit() + 5) + "1"

# (name, file bytes, whether the fast path takes it)
CASES = [
    ("clean", _table(*_rows()), True),
    ("crlf", _table(*_rows(), end="\r\n"), True),
    ("cr_only", _table(*_rows(), end="\r"), True),
    ("bom", codecs.BOM_UTF8 + _table(*_rows()), True),
    ("no_final_newline", _table(*_rows())[:-1], True),
    ("blank_lines_at_end", _table(*_rows()) + b"\n\r\n\n", True),
    ("reordered_columns", b"force_n,ultrasound_on,time_s\n1.5,0,0.0\n1.6,1,0.01\n", True),
    ("blanks_around_names", b" time_s ,force_n,\tultrasound_on\n0,1.5,0\n0.01,1.6,1\n", True),
    ("extra_text_column", _plus_column("note", "x y"), True),
    ("trailing_separator", _plus_column("", ""), True),
    ("time_backwards", _table(*_rows(), "0.05,1.0,0"), True),
    ("time_repeats", _table(*_rows(), "0.07,1.0,0"), True),
    ("irregular_sampling", _table(*_rows(), "0.5,1.0,0"), True),
    ("one_row", _table(*_rows(1)), False),
    ("header_only", _table(), False),
    ("empty", b"", False),
    ("blank", b" \n\n", False),
    # numbers pyarrow and the located checks both accept, with one value
    *[
        (f"number_{cell!r}", _table(*_rows(force={2: cell})), True)
        for cell in (
            " 1.5",
            "1.5 ",
            "\t2",
            "+1.5",
            "-0",
            "-0.0",
            "1.",
            ".5",
            "1.e5",
            "1E-3",
            "1e+05",
            "000123",
            "0.1000000000000000055511151231257827",
            "123456789012345678901234567890",
            "4.9e-324",
            "2.4703282292062328e-324",
            "1e-400",
            "1.7976931348623157e308",
        )
    ],
    # numbers the located checks accept and pyarrow does not: the located path reads them
    ("number_form_feed", _table(*_rows(force={2: "1.5\f"})), False),
    ("number_quoted", _table(*_rows(force={2: '"1.5"'})), False),
    ("number_too_long_for_csv", _table(*_rows(force={2: LONG})), False),
    # cells the located checks reject
    *[
        (f"bad_number_{cell!r}", _table(*_rows(force={4: cell})), False)
        for cell in (
            "",
            " ",
            "nan",
            "NaN",
            "-nan",
            "inf",
            "-inf",
            "Infinity",
            "nan(1)",
            "1e400",
            "-1e999",
            "0x10",
            "1_000",
            "1e",
            ".",
            "1.2.3",
            "--1",
            "abc",
            "１",
            "½",
            "1\x00",
            '"1,5"',
        )
    ],
    ("bad_time", _table(*_rows()[:3], "x,1.0,0", *_rows()[4:]), False),
    # flags
    *[
        (f"flags_{on}_{off}", _table(*_rows(flag={0: off, 5: on})), True)
        for on, off in (("true", "false"), ("TRUE", "FALSE"), ("True", "False"), ("1.0", "0.0"))
    ],
    *[
        (f"flag_{cell!r}", _table(*_rows(flag={5: cell})), False)
        for cell in ("tRuE", " 1", "1 ", "\t0", "", "2", "1.00", "+1", "01", "on", "yes", "nan")
    ],
    # lines and names
    ("short_line", _table(*_rows()[:4], "0.04,1.0", *_rows()[5:]), False),
    ("long_line", _table(*_rows()[:4], "0.04,1.0,0,7", *_rows()[5:]), False),
    ("blank_line_inside", _table(*_rows()[:4], "", *_rows()[4:]), False),
    ("blanks_line_inside", _table(*_rows()[:4], "  ", *_rows()[4:]), False),
    ("blanks_line_at_end", _table(*_rows(), "  "), False),
    ("commas_line_at_end", _table(*_rows(), ",,"), False),
    ("lf_cr", _table(*_rows()).replace(b"\n", b"\n\r", 3), False),
    ("quoted_newline", _table(*_rows()[:4], '0.04,"1.0\n",0', *_rows()[5:]), False),
    ("duplicate_column", _plus_column("force_n", "1"), False),
    ("missing_column", _table(*_rows(), header="time_s,force_n,x"), False),
    ("misspelled_column", _table(*_rows(), header="time_s,forse_n,ultrasound_on"), False),
    ("semicolons", _table(*_rows()).replace(b",", b";"), False),
    ("non_ascii_extra", _plus_column("note", "µ"), False),
    ("non_ascii_name", _plus_column("temp_°c", "1"), True),
    ("long_extra_cell", _plus_column("x", "1", last=LONG), False),
    ("not_utf8", _table(*_rows()) + b"0.5,1\xff,0\n", False),
    ("nul_in_extra", _plus_column("x", "a\x00b"), False),
    ("double_bom", codecs.BOM_UTF8 * 2 + _table(*_rows()), False),
]  # fmt: skip


@pytest.mark.parametrize(("data", "fast"), [c[1:] for c in CASES], ids=[c[0] for c in CASES])
def test_fast_and_located_paths_agree(data, fast):
    assert _same_both_ways(data) is fast


def test_the_cases_cover_accepted_and_rejected_files():
    accepted = [name for name, data, _ in CASES if _outcome(read_csv_table, data)[1] is not None]
    assert "clean" in accepted and "number_form_feed" in accepted and "flag_'tRuE'" in accepted
    assert "bad_number_'nan'" not in accepted and "short_line" not in accepted


def test_a_clean_dataset_never_reaches_the_located_reader(tmp_path, monkeypatch):
    root = make_dataset(tmp_path / "d")

    def refuse(data, file):
        raise AssertionError(f"{file} took the located path")

    monkeypatch.setattr(table_read, "located_csv_table", refuse)
    dataset = load_dataset(root)
    assert all(t.n_samples > 2 for t in dataset.traces)


def test_a_rejected_cell_is_still_located(tmp_path):
    data = _table(*_rows(force={4: "nan"}))
    problems, samples = _outcome(read_csv_table, data)
    assert samples is None
    assert [str(p) for p in problems] == [
        f"error: {FILE}, row 5, column 'force_n': 'nan' is not a finite number: replace "
        "it by a measured value or delete the row"
    ]


_NUMBERS = st.from_regex(
    r"[+-]?(?:\d{1,30}\.?\d{0,30}|\.\d{1,30})(?:[eE][+-]?\d{1,3})?", fullmatch=True
).filter(lambda s: s.isascii())


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.lists(_NUMBERS, min_size=2, max_size=12))
def test_every_number_reads_to_the_same_bits(cells):
    data = _table(*(f"{i},{c},0" for i, c in enumerate(cells)))
    values = [float(c) for c in cells]
    assert _same_both_ways(data) is all(np.isfinite(values))


_JUNK = st.text(st.sampled_from(list('0123456789.eE+- \t,"\r\n\x00\fnaifINFtrueTRUEµ')), max_size=8)


@settings(max_examples=200, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.lists(st.tuples(_JUNK, _JUNK), min_size=0, max_size=6), st.sampled_from(["\n", "\r\n"]))
def test_any_cell_gives_the_same_outcome_both_ways(cells, end):
    rows = _rows(6)
    for k, (force, flag) in enumerate(cells):
        t = rows[k].split(",")[0]
        rows[k] = f"{t},{force or '1.5'},{flag or '0'}"
    _same_both_ways(_table(*rows, end=end))
