"""``idtool import``: awkward DAQ exports made from a known truth come back as that truth.

The truth is three traces of the shipped example dataset. They are written as a bench's
DAQ would write them (``;`` with decimal commas, BOM, CRLF, a clock that does not start
at 0, ms and kN, a noisy 0-5 V trigger that bounces at its edges) and imported; times,
forces (to the written precision), ON windows (within one sample) and operating points
must come back. Every error is exit status 2 naming the file, row and column, with
nothing written.
"""

from __future__ import annotations

import dataclasses
import itertools
import json
import subprocess
import sys
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest

import idtool
from idtool._cli._main import main
from idtool._data._import_columns import _NUMBER, _clean_numbers
from idtool._data._import_trigger import debounce, schmitt, trigger_levels
from idtool._data._import_units import parse_header, value_in_si
from idtool._data._table_read import RawColumn

TRACE_IDS = ("N270_A50_T1", "N450_A70_T0.5", "N670_A50_T2")
RIG = ["--material", "PES webbing", "--horn-hz", "20000", "--max-amplitude-um", "85"]
COLUMNS = ["--time", "Time", "--force-col", "Load", "--trigger", "US trigger"]
HEADER = ("Time (s)", "Load (N)", "US trigger (V)")
CLOCK_S = 12.5  # the DAQ's clock at the first sample
PATTERN = r"N(?P<load_n>\d+)_A(?P<amplitude_percent>\d+)"  # N670_A50_T2.csv: 670 N, 50%


@pytest.fixture(scope="module")
def truth() -> list[idtool.Trace]:
    dataset = idtool.load_dataset(idtool.example_dataset_path())
    return [dataset.trace(i) for i in TRACE_IDS]


def trigger_volts(trace: idtool.Trace, seed: int = 0, bounce: bool = True) -> np.ndarray:
    """A 0-5 V trigger with 50 mV noise; at each edge it falls back to the old level for
    one sample, twice (contact bounce of 1 ms pulses, within 4 ms of the edge)."""
    on = trace.ultrasound_on
    volts = np.where(on, 5.0, 0.0) + np.random.default_rng(seed).normal(0.0, 0.05, on.size)
    if bounce:
        for edge in np.flatnonzero(np.diff(on.astype(int))) + 1:  # first sample after it
            old = 0.0 if on[edge] else 5.0
            volts[[edge + 1, edge + 3]] = old + 0.2
    return volts


def daq_lines(
    trace: idtool.Trace,
    volts: np.ndarray,
    *,
    sep: str = ";",
    decimal: str = ",",
    header: tuple[str, ...] = HEADER,
    time_scale: float = 1.0,
    time_places: int = 3,
    force_scale: float = 1.0,
    force_places: int = 2,
    clock_s: float = CLOCK_S,
) -> list[str]:
    """The lines of a DAQ export of ``trace`` (header first; line r is data row r)."""
    lines = [sep.join(header)]
    for t, f, v in zip(trace.time_s, trace.force_n, volts, strict=True):
        cells = [
            f"{(t + clock_s) * time_scale:.{time_places}f}",
            f"{f * force_scale:.{force_places}f}",
            f"{v:.3f}",
        ]
        lines.append(sep.join(c.replace(".", decimal) for c in cells))
    return lines


def write_lines(path: Path, lines: list[str], *, bom: bool = True, crlf: bool = True) -> str:
    path.parent.mkdir(parents=True, exist_ok=True)
    text = ("\r\n" if crlf else "\n").join(lines) + ("\r\n" if crlf else "\n")
    path.write_bytes(("\ufeff" if bom else "").encode() + text.encode())
    return str(path)


def write_conditions(path: Path, traces: list[idtool.Trace], extra: list[str] = ()) -> str:
    """The operating points as a lab would type them: kN with decimal commas, percent."""
    lines = ["file;load (kN);amplitude;speed (mm/s)"]
    for t in traces:
        load = f"{t.normal_load_n / 1000:g}".replace(".", ",")
        lines.append(f"{t.id}.csv;{load};{t.amplitude_fraction * 100:g}%;25")
    return write_lines(path, [*lines, *extra], bom=False, crlf=False)


def motivating_exports(folder: Path, traces: list[idtool.Trace]) -> list[str]:
    return [
        write_lines(folder / f"{t.id}.csv", daq_lines(t, trigger_volts(t, seed=k)))
        for k, t in enumerate(traces)
    ]


def assert_same_traces(dataset: idtool.Dataset, traces: list[idtool.Trace], force_places=2):
    assert [t.id for t in dataset.traces] == [t.id for t in traces]
    for got, want in zip(dataset.traces, traces, strict=True):
        np.testing.assert_allclose(got.time_s, want.time_s, rtol=0, atol=1e-12)
        np.testing.assert_allclose(
            got.force_n, np.round(want.force_n, force_places), rtol=0, atol=1e-9
        )
        assert len(got.on_windows_s) == len(want.on_windows_s) == 1
        step = 1.0 / want.sample_rate_hz
        np.testing.assert_allclose(got.on_windows_s, want.on_windows_s, rtol=0, atol=1.01 * step)
        assert got.normal_load_n == want.normal_load_n
        assert got.amplitude_fraction == want.amplitude_fraction
        assert got.pull_speed_m_s == want.pull_speed_m_s


# ------------------------------------------------------------------ the motivating export
def test_the_motivating_export_becomes_a_validated_dataset(tmp_path, truth, capsys):
    files = motivating_exports(tmp_path / "raw", truth)
    raw = Path(files[0]).read_bytes()
    assert raw.startswith(b"\xef\xbb\xbfTime (s);Load (N);US trigger (V)\r\n12,500;")
    table = write_conditions(tmp_path / "conditions.csv", truth)
    out = tmp_path / "run-0312"
    argv = ["import", *files, "--out", str(out), *RIG, *COLUMNS, "--conditions", table]
    argv += ["--mains-hz", "50", "--x", "operator=J. Smith", "--description", "bench B, run 12"]
    assert main(argv) == 0
    printed = capsys.readouterr().out
    dataset = idtool.load_dataset(out)
    assert_same_traces(dataset, truth)
    assert dataset.name == "run-0312" and dataset.rig.max_amplitude_m == 85e-6
    assert dataset.rig.mains_frequency_hz == 50.0 and dataset.description == "bench B, run 12"
    assert dict(dataset.extensions) == {"x_operator": "J. Smith"}
    assert sorted(p.name for p in out.iterdir()) == ["dataset.json", "traces"]
    assert sorted(p.name for p in (out / "traces").iterdir()) == [
        f"{i}.parquet" for i in sorted(TRACE_IDS)
    ]
    # The summary: every trace with its operating point and ON window, and its origin.
    assert "imported 3 file(s)" in printed and "valid: no errors" in printed
    assert "N670_A50_T2" in printed and "4.170-6.170" in printed and "670" in printed
    note = dataset.trace("N270_A50_T1").notes
    assert note is not None and "imported from N270_A50_T1.csv" in note
    assert "time shifted by -12.5 s" in note and "4 pulse(s) shorter than 5 ms ignored" in note
    assert "'US trigger (V)' above" in note
    # The same in Python, and the same bytes: the import is deterministic.
    again = idtool.import_daq(
        files,
        tmp_path / "again",
        name="run-0312",
        material="PES webbing",
        vibration_frequency_hz=20000,
        max_amplitude_m=85e-6,
        time_column="Time",
        force_column="Load",
        trigger_column="US trigger",
        conditions=table,
        mains_frequency_hz=50,
        description="bench B, run 12",
        extensions={"x_operator": "J. Smith"},
    )
    assert again.sha256 == dataset.sha256 and again.path == tmp_path / "again"


def test_json_summary(tmp_path, truth, capsys):
    files = motivating_exports(tmp_path / "raw", truth[:1])
    argv = ["import", *files, "--out", str(tmp_path / "d"), *RIG, *COLUMNS, "--json"]
    argv += ["--load", "0.27kN", "--amplitude", "50%", "--speed", "25mm/s", "-q"]
    assert main(argv) == 0
    summary = json.loads(capsys.readouterr().out)
    (trace,) = summary["traces"]
    assert trace["id"] == "N270_A50_T1" and trace["normal_load_n"] == 270.0
    assert trace["amplitude_fraction"] == 0.5 and trace["pull_speed_m_s"] == 0.025
    np.testing.assert_allclose(trace["on_windows_s"], truth[0].on_windows_s, atol=1.01e-3)
    assert "imported from" in trace["notes"] and summary["imported_from"] == files


# ------------------------------------------------------------------ dialects and units
@dataclasses.dataclass(frozen=True)
class Dialect:
    name: str
    write: Callable[[Path, idtool.Trace], str]
    options: dict


def _tabs_units_line_metadata(folder: Path, trace: idtool.Trace) -> str:
    """Tab-separated, points, two metadata lines and a comment above the header, a line
    of units under it, a separator at the end of every line, LF, ms and kN."""
    lines = daq_lines(
        trace,
        trigger_volts(trace),
        sep="\t",
        decimal=".",
        header=("Time", "Force", "Trig"),
        time_scale=1000.0,
        time_places=0,
        force_scale=1e-3,
        force_places=5,
    )
    lines.insert(1, "ms\tkN\tV")
    lines = ["Sample rate: 1000 Hz", "Operator: J. Smith", "# exported by DAQ 2.1", *lines]
    return write_lines(folder / f"{trace.id}.txt", [f"{s}\t" for s in lines], bom=False)


def _blanks_snake_headers(folder: Path, trace: idtool.Trace) -> str:
    """Columns aligned with runs of blanks; units in snake-case headers (time_ms)."""
    lines = daq_lines(
        trace,
        trigger_volts(trace),
        sep="   ",
        decimal=".",
        header=("time_ms", "force_kn", "trigger_v"),
        time_scale=1000.0,
        time_places=0,
        force_scale=1e-3,
        force_places=5,
    )
    return write_lines(folder / f"{trace.id}.dat", lines, bom=False, crlf=False)


def _commas_brackets_slash(folder: Path, trace: idtool.Trace) -> str:
    """Comma-separated with points, units in brackets and after a slash, CR only."""
    lines = daq_lines(
        trace,
        trigger_volts(trace),
        sep=",",
        decimal=".",
        header=("Zeit [ms]", "Kraft [kN]", "Trigger/V"),
        time_scale=1000.0,
        time_places=1,
        force_scale=1e-3,
        force_places=5,
    )
    path = folder / f"{trace.id}.csv"
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_bytes("\r".join(lines).encode())
    return str(path)


def _no_units_in_headers(folder: Path, trace: idtool.Trace) -> str:
    """';' with decimal commas, no units anywhere: --time-unit ms, --force-unit kN."""
    lines = daq_lines(
        trace,
        1000 * trigger_volts(trace),
        header=("t", "F", "trig"),
        time_scale=1000.0,
        time_places=0,
        force_scale=1e-3,
        force_places=5,
    )
    return write_lines(folder / f"{trace.id}.csv", lines)


DIALECTS = (
    Dialect(
        "tabs_units_line_metadata",
        _tabs_units_line_metadata,
        {"time_column": "time", "force_column": "FORCE", "trigger_column": 3, "skip_rows": 2},
    ),
    Dialect(
        "blanks_snake_headers",
        _blanks_snake_headers,
        {"time_column": "time", "force_column": "force", "trigger_column": "trigger"},
    ),
    Dialect(
        "commas_brackets_slash",
        _commas_brackets_slash,
        {"time_column": "zeit", "force_column": "Kraft [kN]", "trigger_column": "trigger"},
    ),
    Dialect(
        "no_units_in_headers",
        _no_units_in_headers,
        {
            "time_column": 1,
            "force_column": 2,
            "trigger_column": 3,
            "time_unit": "ms",
            "force_unit": "kN",
            "trigger_unit": "mV",
        },
    ),
)


@pytest.mark.parametrize("dialect", DIALECTS, ids=lambda d: d.name)
def test_dialects_and_units_come_back_in_si(tmp_path, truth, dialect: Dialect):
    trace = truth[1]
    file = dialect.write(tmp_path / "raw", trace)
    dataset = idtool.import_daq(
        [file],
        tmp_path / "out",
        name="d",
        material="m",
        vibration_frequency_hz=20000,
        max_amplitude_m=85e-6,
        normal_load_n=450.0,
        amplitude_fraction=0.7,
        pull_speed_m_s=0.025,
        trace_format="csv",
        **dialect.options,
    )
    assert_same_traces(dataset, [trace])
    assert (tmp_path / "out" / "traces" / f"{trace.id}.csv").is_file()
    assert "time shifted by -12.5 s" in (dataset.traces[0].notes or "")


def test_parquet_export_with_an_on_column(tmp_path, truth):
    trace = truth[2]
    table = pa.table(
        {
            "Time (ms)": pa.array(np.round((trace.time_s + CLOCK_S) * 1000.0), pa.int64()),
            "Load (kN)": pa.array(trace.force_n / 1000.0, pa.float64()),
            "horn on": pa.array(trace.ultrasound_on, pa.bool_()),
        }
    )
    pq.write_table(table, tmp_path / f"{trace.id}.parquet")
    dataset = idtool.import_daq(
        [tmp_path / f"{trace.id}.parquet"],
        tmp_path / "out",
        name="d",
        material="m",
        vibration_frequency_hz=20000,
        max_amplitude_m=85e-6,
        time_column="Time",
        force_column="load",
        on_column="Horn On",
        pattern=PATTERN,
        pull_speed_m_s=0.025,
    )
    (got,) = dataset.traces
    np.testing.assert_allclose(got.time_s, trace.time_s, rtol=0, atol=1e-12)
    np.testing.assert_allclose(got.force_n, trace.force_n, rtol=1e-15, atol=0)
    np.testing.assert_array_equal(got.ultrasound_on, trace.ultrasound_on)
    assert got.on_windows_s == trace.on_windows_s
    assert (got.normal_load_n, got.amplitude_fraction) == (670.0, 0.5)
    assert "ON from the 0/1 column 'horn on'" in (got.notes or "")
    # a conditions table may be Parquet too, its units in the column names
    points = {
        "file": [f"{trace.id}.parquet"],
        "normal_load_kn": [0.67],
        "amplitude_percent": [50],
        "pull_speed_mm_s": [25.0],
        "notes": ["second pull of the day"],
    }
    pq.write_table(pa.table(points), tmp_path / "conditions.parquet")
    again = idtool.import_daq(
        [tmp_path / f"{trace.id}.parquet"],
        tmp_path / "again",
        name="d",
        material="m",
        vibration_frequency_hz=20000,
        max_amplitude_m=85e-6,
        time_column="Time",
        force_column="load",
        on_column="Horn On",
        conditions=tmp_path / "conditions.parquet",
    )
    (got,) = again.traces
    assert (got.normal_load_n, got.amplitude_fraction, got.pull_speed_m_s) == (670.0, 0.5, 0.025)
    assert (got.notes or "").startswith("second pull of the day; imported from")


def test_a_table_and_a_file_name_pattern_give_the_same_dataset(tmp_path, truth, capsys):
    """The README's table (units in the headers, plus a column of the lab's own, which is
    ignored with a warning) and the README's pattern give the same bytes."""
    files = motivating_exports(tmp_path / "raw", truth)
    table = tmp_path / "conditions.csv"
    rows = [f"{t.id}.csv;{t.normal_load_n:g};{t.amplitude_fraction * 100:g};25;JS" for t in truth]
    table.write_text("\n".join(["file;load (N);amplitude (%);speed (mm/s);operator", *rows]))
    common = ["import", *files, *RIG, *COLUMNS, "--name", "run"]
    assert main([*common, "--out", str(tmp_path / "a"), "--conditions", str(table)]) == 0
    printed = capsys.readouterr().out
    assert "1 warning(s)" in printed
    assert "column 'operator' is not file, load, amplitude, speed or notes: ignored" in printed
    b = [*common, "--out", str(tmp_path / "b"), "--pattern", PATTERN, "--speed", "25mm/s"]
    assert main(b) == 0
    capsys.readouterr()
    a, b = idtool.load_dataset(tmp_path / "a"), idtool.load_dataset(tmp_path / "b")
    assert (tmp_path / "a/dataset.json").read_bytes() == (tmp_path / "b/dataset.json").read_bytes()
    assert a.sha256 == b.sha256
    assert [t.amplitude_fraction for t in a.traces] == [0.5, 0.7, 0.5]


# ------------------------------------------------------------------ trigger
def test_debounce_and_hysteresis_matter(tmp_path, truth, capsys):
    """The same bouncing trigger: one window per pull with the defaults; the bounces as
    windows of their own without debounce and hysteresis."""
    files = motivating_exports(tmp_path / "raw", truth)
    common = ["import", *files, *RIG, *COLUMNS, "--pattern", PATTERN, "--speed", "0.025"]
    assert main([*common, "--out", str(tmp_path / "clean")]) == 0
    raw = [*common, "--out", str(tmp_path / "raw-edges"), "--debounce", "0", "--hysteresis", "0"]
    assert main(raw) == 0
    capsys.readouterr()
    clean = idtool.load_dataset(tmp_path / "clean")
    bouncy = idtool.load_dataset(tmp_path / "raw-edges")
    assert [len(t.on_windows_s) for t in clean.traces] == [1, 1, 1]
    # two bounces at each edge: 2 extra windows at the ON edge, 2 after the OFF edge
    assert [len(t.on_windows_s) for t in bouncy.traces] == [5, 5, 5]
    # and the chatter of a slow, noisy edge is held off by the hysteresis alone
    t = np.arange(2000) * 1e-3
    ramp = np.clip((t - 0.9) / 0.2, 0.0, 1.0) * 5.0 + np.random.default_rng(1).normal(0, 0.3, 2000)
    assert np.sum(np.diff(schmitt(ramp, 2.5, 2.5).astype(int)) == 1) > 3
    assert np.sum(np.diff(schmitt(ramp, 3.0, 2.0).astype(int)) == 1) == 1


def test_debounce_puts_the_edge_at_the_first_sample_of_a_burst():
    flags = np.array([0] * 10 + [1, 0, 1, 0] + [1] * 10 + [0] + [1] * 10 + [0, 1, 0] + [0] * 10)
    time_s = np.arange(flags.size) * 1e-3
    clean, changed = debounce(flags.astype(bool), time_s, 0.005)
    want = np.zeros(flags.size, bool)
    want[10:35] = True  # ON from the first bounce to the first OFF sample
    np.testing.assert_array_equal(clean, want)
    assert changed == 4  # two bounces at the ON edge, one glitch, one at the OFF edge
    assert trigger_levels(np.r_[np.zeros(980), np.full(20, 5.0)])[:2] == (0.0, 5.0)


# ------------------------------------------------------------------ headers and values
@pytest.mark.parametrize(
    ("header", "name", "unit"),
    [
        ("Time (s)", "Time", "s"),
        ("Time [ms]", "Time", "ms"),
        ("Load (kN)", "Load", "kN"),
        ("speed mm/s", "speed", "mm/s"),
        ("t/s", "t", "s"),
        ("time_s", "time", "s"),
        ("pull_speed_mm_s", "pull_speed", "mm/s"),
        ("amplitude_percent", "amplitude", "%"),
        ("Zeit [µs]", "Zeit", "us"),
        ("Channel_A", "Channel_A", None),
        ("Load (cell 2)", "Load", None),
    ],
)
def test_header_units(header, name, unit):
    parsed = parse_header(header)
    assert (parsed.name, parsed.unit) == (name, unit)


def test_values_with_units():
    assert value_in_si("70%", "amplitude") == 0.7  # exactly, not 0.7000000000000001
    assert value_in_si("0,67 kN", "force") == 670.0
    assert value_in_si("25mm/s", "speed") == 0.025
    assert value_in_si("5 ms", "time") == 0.005
    with pytest.raises(ValueError, match="not a speed unit"):
        value_in_si("25 kN", "speed")


# ------------------------------------------------------------------ errors
A, B = TRACE_IDS[0], TRACE_IDS[1]
FA, FB = f"raw/{A}.csv", f"raw/{B}.csv"
SHORT = 5000  # samples per export in the error cases (both ON windows end before 5 s)


@dataclasses.dataclass(frozen=True)
class Broken:
    """Make exports, the table and options that must fail; ``where`` must be in the
    message (Problem's ``file, row N, column 'X'``), and ``hint``."""

    name: str
    where: str
    hint: str
    edit: Callable[[list[str]], list[str]] | None = None  # the lines of export A
    options: tuple[str, ...] = ()
    table: tuple[str, ...] | None = None  # extra rows, or None: the default table
    setup: Callable[[Path], None] | None = None


def _cell(row: int, col: int, text: str) -> Callable[[list[str]], list[str]]:
    def edit(lines: list[str]) -> list[str]:
        cells = lines[row].split(";")
        cells[col] = text
        return [*lines[:row], ";".join(cells), *lines[row + 1 :]]

    return edit


def _trigger(fn: Callable[[np.ndarray], np.ndarray]) -> Callable[[list[str]], list[str]]:
    """Replace the trigger column of every data row by ``fn(on flags of the truth)``."""

    def edit(lines: list[str]) -> list[str]:
        on = np.array([float(line.split(";")[2].replace(",", ".")) > 2.5 for line in lines[1:]])
        volts = fn(on)
        cells = [f"{v:.3f}".replace(".", ",") for v in volts]
        rows = [f"{line.rsplit(';', 1)[0]};{c}" for line, c in zip(lines[1:], cells, strict=True)]
        return [lines[0], *rows]

    return edit


def _noise(n: int) -> np.ndarray:
    return np.random.default_rng(5).normal(0.0, 0.05, n)


def _rows(fn: Callable[[str], str]) -> Callable[[list[str]], list[str]]:
    return lambda lines: [lines[0], *(fn(line) for line in lines[1:])]


def _same_stem_elsewhere(root: Path) -> None:
    other = root / "raw2" / f"{A}.csv"
    other.parent.mkdir()
    other.write_bytes((root / FA).read_bytes())


BROKEN = (
    Broken(
        "text_in_force",
        f"{FA}, row 7, column 'Load (N)'",
        "'abc' is not a number",
        _cell(7, 1, "abc"),
    ),
    Broken("empty_cell", f"{FA}, row 12, column 'Load (N)'", "empty cell", _cell(12, 1, "")),
    Broken("nan_cell", f"{FA}, row 3, column 'US trigger (V)'", "not a number", _cell(3, 2, "NaN")),
    Broken(
        "time_goes_back",
        f"{FA}, row 30, column 'Time (s)'",
        "sort the rows",
        _cell(30, 0, "12,520"),
    ),
    Broken(
        "short_line",
        f"{FA}, row 15",
        "has 2 values but the header names 3",
        lambda lines: [*lines[:15], lines[15].rsplit(";", 1)[0], *lines[16:]],
    ),
    Broken(
        "two_headers_match",
        f"{FA}, row 0, column 'Load'",
        "matches 2 headers",
        lambda lines: [lines[0] + ";Load (kN)", *(s + ";0,1" for s in lines[1:])],
    ),
    Broken(
        "no_such_column",
        f"{FA}, row 0, column 'Kraft'",
        "no column 'Kraft'",
        options=("--force-col", "Kraft"),
    ),
    Broken(
        "separator_unknown",
        f"{FA}, row 0",
        "cannot tell the separator",
        _rows(lambda s: s.replace(";", "\t")),
    ),
    Broken(
        "decimal_comma_in_comma_file",
        f"{FA}, row 1",
        "decimal commas in a comma-separated",
        lambda lines: [s.replace(";", ",") for s in lines],
    ),
    Broken(
        "mixed_decimal_marks", f"{FA}, row 20, column 'Load (N)'", "--decimal", _cell(20, 1, "3.5")
    ),
    Broken(
        "unknown_unit",
        f"{FA}, row 0, column 'Load (lb)'",
        "--force-unit",
        lambda lines: [lines[0].replace("(N)", "(lb)"), *lines[1:]],
    ),
    Broken(
        "unit_of_another_quantity",
        f"{FA}, row 0, column 'Load (ms)'",
        "not a force unit",
        lambda lines: [lines[0].replace("(N)", "(ms)"), *lines[1:]],
    ),
    Broken(
        "header_contradicts_option",
        f"{FA}, row 0, column 'Time (s)'",
        "the header says 's' but --time-unit says 'ms'",
        options=("--time-unit", "ms"),
    ),
    Broken(
        "trigger_never_switches",
        f"{FA}, column 'US trigger (V)'",
        "never switches",
        _trigger(lambda on: _noise(on.size)),
    ),
    Broken(
        "trigger_never_switches_off",
        f"{FA}, row 3771, column 'US trigger (V)'",
        "never OFF",
        _trigger(lambda on: 5.0 * np.maximum.accumulate(on) + _noise(on.size)),
    ),
    Broken(
        "trigger_active_low",
        f"{FA}, row 1, column 'US trigger (V)'",
        "--active-low",
        _trigger(lambda on: 5.0 * ~on + _noise(on.size)),
    ),
    Broken(
        "too_many_pulses",
        f"{FA}, row 4772, column 'US trigger (V)'",
        "longer --debounce",
        options=("--debounce", "0", "--max-windows", "3"),
    ),
    Broken(
        "not_utf8",
        f"{FA}: line 1 is not valid utf-8",
        "--encoding cp1252",
        setup=lambda root: (root / FA).write_bytes("Zeit (µs);".encode("cp1252")),
    ),
    Broken(
        "condition_row_without_file",
        "conditions.csv, row 3, column 'file'",
        "'ghost.csv' is not one of the imported files",
        table=("ghost.csv;0,3;50%;25",),
    ),
    Broken(
        "file_listed_twice",
        "conditions.csv, row 3, column 'file'",
        "already has row 1",
        table=(f"{A}.csv;0,3;50%;25",),
    ),
    Broken(
        "file_without_conditions",
        "conditions.csv, column 'file'",
        f"no row for the imported file '{FB}'",
        table=(),
    ),
    Broken(
        "amplitude_in_percent_without_unit",
        "conditions.csv, row 1, column 'amplitude'",
        "looks like a percentage",
        setup=lambda root: (root / "conditions.csv").write_text(
            f"file;load;amplitude;speed\n{A}.csv;270;50;0.025\n{B}.csv;450;70;0.025\n"
        ),
    ),
    Broken(
        "condition_given_twice",
        f"{FA}: the speed comes from both conditions.csv row 1 and --speed",
        "give it once",
        options=("--speed", "0.025"),
    ),
    Broken(
        "pattern_does_not_match",
        f"{FA}: the file name does not match --pattern",
        "N(?P<load_n>",
        options=("--pattern", r"N(?P<load_n>\d+)kN"),
    ),
    Broken(
        "same_trace_id_twice",
        f"raw2/{A}.csv",
        f"gives the trace id '{A}'",
        options=(f"raw2/{A}.csv",),
        setup=_same_stem_elsewhere,
    ),
)


@pytest.fixture(scope="module")
def short_lines(truth) -> dict[str, list[str]]:
    """The motivating exports of A and B, cut to their first SHORT samples."""
    out = {}
    for k, trace in enumerate(truth[:2]):
        out[trace.id] = daq_lines(trace, trigger_volts(trace, seed=k))[: SHORT + 1]
    return out


@pytest.mark.parametrize("case", BROKEN, ids=lambda c: c.name)
def test_every_error_is_located_exit_2_and_nothing_written(
    tmp_path, truth, short_lines, capsys, monkeypatch, case: Broken
):
    monkeypatch.chdir(tmp_path)
    lines = short_lines[A]
    write_lines(tmp_path / FA, case.edit(lines) if case.edit else lines)
    write_lines(tmp_path / FB, short_lines[B])
    write_conditions(
        tmp_path / "conditions.csv",
        truth[:2] if case.table != () else truth[:1],
        list(case.table or []),
    )
    if case.setup:
        case.setup(tmp_path)
    before = sorted(p.relative_to(tmp_path) for p in tmp_path.rglob("*"))
    files = [FA, FB, *(o for o in case.options if o.endswith(".csv"))]
    options = [o for o in case.options if not o.endswith(".csv")]
    argv = ["import", *files, "--out", "out", *RIG, *COLUMNS, "--conditions", "conditions.csv"]
    assert main([*argv, *options]) == 2
    out, err = capsys.readouterr()
    assert out == ""
    assert err.startswith("idtool import: nothing was written") or "nothing" in err
    assert case.where in err, err
    assert case.hint in err, err
    assert "Traceback" not in err
    assert sorted(p.relative_to(tmp_path) for p in tmp_path.rglob("*")) == before


def test_options_that_contradict_are_refused_before_reading(tmp_path, capsys):
    argv = ["import", "nowhere.csv", "--out", str(tmp_path / "o"), *RIG]
    argv += ["--time", "1", "--force-col", "2", "--trigger", "3", "--sep", "ab"]
    assert main(argv) == 2
    assert "--sep 'ab' is not a separator" in capsys.readouterr().err
    with pytest.raises(idtool.IdtoolError, match="as a trigger channel"):
        idtool.import_daq(
            ["x.csv"],
            tmp_path / "o",
            name="n",
            material="m",
            vibration_frequency_hz=2e4,
            max_amplitude_m=8.5e-5,
            time_column=1,
            force_column=2,
        )
    assert not (tmp_path / "o").exists()


def test_an_existing_output_is_replaced_only_with_force(tmp_path, truth, capsys):
    files = motivating_exports(tmp_path / "raw", truth[:1])
    out = tmp_path / "d"
    out.mkdir()
    (out / "keep.txt").write_text("mine")
    argv = ["import", *files, "--out", str(out), *RIG, *COLUMNS]
    argv += ["--load", "270", "--amplitude", "0.5", "--speed", "0.025"]
    assert main(argv) == 2
    assert "already exists; pass --force" in capsys.readouterr().err
    assert (out / "keep.txt").read_text() == "mine"
    # A dataset that fails validation (a negative horn frequency) leaves the old folder.
    bad = [a if a != "20000" else "-5" for a in argv]
    assert main([*bad, "--force"]) == 2
    err = capsys.readouterr().err
    assert "the dataset it would write is not valid, so nothing was written: 1 error(s)" in err
    assert "error: dataset.json, column 'rig.vibration_frequency_hz': -5.0 is out of range" in err
    assert ".partial" not in err
    assert (out / "keep.txt").read_text() == "mine"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["d", "raw"]  # no temporary left
    assert main([*argv, "--force"]) == 0
    assert not (out / "keep.txt").exists() and idtool.load_dataset(out).traces[0].id == A


def test_validation_warnings_are_printed(tmp_path, truth, capsys):
    """A force column in kN without a unit is read as N; the check of the written
    dataset says so."""
    trace = truth[0]
    lines = daq_lines(
        trace,
        trigger_volts(trace),
        header=("Time (s)", "Load", "US trigger (V)"),
        force_scale=1e-3,
        force_places=5,
    )
    file = write_lines(tmp_path / f"{trace.id}.csv", lines)
    argv = ["import", file, "--out", str(tmp_path / "d"), *RIG, *COLUMNS]
    assert main([*argv, "--load", "270", "--amplitude", "0.5", "--speed", "0.025"]) == 0
    out = capsys.readouterr().out
    assert "1 warning(s)" in out and "multiply it by 1000" in out
    assert "'Load' in N (assumed: no unit in the header)" in out


def test_help_shows_the_motivating_example_and_import_loads_no_jax(capsys):
    with pytest.raises(SystemExit):
        main(["import", "--help"])
    text = capsys.readouterr().out
    assert "'Time (s);Load (N);US trigger (V)'" in text
    assert '--trigger "US trigger" --conditions conditions.csv' in text
    code = (
        "import sys, idtool._cli._import, idtool._data._import; "
        "print(sorted(m for m in ('jax', 'equinox', 'matplotlib') if m in sys.modules))"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert done.stdout.strip() == "[]"


@pytest.mark.parametrize("mark", [".", ","])
def test_a_clean_column_parses_as_its_cells_would(mark):
    """_clean_numbers reads a column at once only if every cell passes the per-cell
    check, with its value: over the characters of plain numbers NumPy's parsing accepts
    exactly what _NUMBER does (every string of up to 5 such characters, alone and beside
    a good cell)."""
    for n in range(6):
        for chars in itertools.product("09+-.eE", repeat=n):
            cell = "".join(chars)
            if mark == ",":
                cell = cell.replace(".", ",")
            text = cell.replace(",", ".") if mark == "," else cell
            ok = _NUMBER.fullmatch(text) is not None and np.isfinite(float(text))
            for cells in ((cell,), ("1", f" {cell}\t")):
                clean = _clean_numbers(RawColumn(text=cells), mark)
                assert (clean is not None) == ok, cells
                if clean is not None:
                    assert clean[0][-1] == float(text)
