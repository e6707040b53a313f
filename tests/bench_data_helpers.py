"""Small, valid bench datasets (format v1) for the tests to corrupt, and helpers to do so."""

from __future__ import annotations

import dataclasses
import hashlib
import json
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

N_ROWS = 60  # samples per trace: 0.6 s at 100 Hz
TRACE_IDS = ("N450_A50", "N670_A70")


def trace_lines(load_n: float, n_rows: int = N_ROWS) -> list[str]:
    """CSV lines of a plausible trace: OFF at 0.3 N per N of load, ON from 0.2 to 0.3 s."""
    lines = ["time_s,force_n,ultrasound_on"]
    for i in range(n_rows):
        t = i / 100.0
        on = 0.2 <= t < 0.3 - 1e-9
        force = 0.3 * load_n * (0.5 if on else 1.0) + 0.1 * np.sin(i)
        lines.append(f"{t:.2f},{force:.2f},{int(on)}")
    return lines


def dataset_document(files: tuple[str, ...] = ("traces/a.csv", "traces/b.csv")) -> dict[str, Any]:
    """A valid dataset.json naming ``files`` (one trace each)."""
    loads = (450.0, 670.0)
    return {
        "schema_version": "1",
        "name": "tiny",
        "material": "webbing",
        "rig": {"vibration_frequency_hz": 20000.0, "max_amplitude_m": 85e-6},
        "traces": [
            {
                "id": TRACE_IDS[k],
                "file": file,
                "normal_load_n": loads[k],
                "amplitude_fraction": 0.5 + 0.2 * k,
                "pull_speed_m_s": 0.025,
            }
            for k, file in enumerate(files)
        ],
    }


def make_dataset(root: Path) -> Path:
    """Write the tiny valid CSV dataset into ``root`` (created) and return ``root``."""
    (root / "traces").mkdir(parents=True)
    document = dataset_document()
    for entry in document["traces"]:
        text = "\n".join(trace_lines(entry["normal_load_n"])) + "\n"
        (root / entry["file"]).write_text(text)
    write_json(root, document)
    return root


def write_json(root: Path, document: Any) -> None:
    (root / "dataset.json").write_text(json.dumps(document, indent=2))


def read_json(root: Path) -> Any:
    return json.loads((root / "dataset.json").read_text())


def set_cell(path: Path, row: int, column: str, text: str) -> None:
    """Replace the cell of data row ``row`` (1-based; header row 0) in ``column``."""
    lines = path.read_text().split("\n")
    header = lines[0].split(",")
    cells = lines[row].split(",")
    cells[header.index(column)] = text
    lines[row] = ",".join(cells)
    path.write_text("\n".join(lines))


def folder_fingerprint(root: Path) -> dict[str, str]:
    """Relative path -> sha256 of every file (and '<dir>' for folders) under ``root``."""
    out = {}
    for path in sorted(root.rglob("*")):
        key = str(path.relative_to(root))
        out[key] = "<dir>" if path.is_dir() else hashlib.sha256(path.read_bytes()).hexdigest()
    return out


# --- A catalogue of malformed datasets: what to break, and where the error must point. ---


@dataclasses.dataclass(frozen=True)
class Corruption:
    """Break a tiny dataset; the error must name ``file`` (relative), ``row`` and ``column``."""

    name: str
    apply: Callable[[Path], None]
    file: str
    row: int | None
    column: str | None
    hint: str


def _cell(file: str, row: int, column: str, text: str) -> Callable[[Path], None]:
    return lambda root: set_cell(root / file, row, column, text)


def _rewrite(file: str, edit: Callable[[list[str]], list[str]]) -> Callable[[Path], None]:
    def apply(root: Path) -> None:
        path = root / file
        path.write_text("\n".join(edit(path.read_text().split("\n"))))

    return apply


def _json(edit: Callable[[dict[str, Any]], None]) -> Callable[[Path], None]:
    def apply(root: Path) -> None:
        document = read_json(root)
        edit(document)
        write_json(root, document)

    return apply


def _replace_text(file: str, old: str, new: str) -> Callable[[Path], None]:
    def apply(root: Path) -> None:
        text = (root / file).read_text()
        assert old in text
        (root / file).write_text(text.replace(old, new, 1))

    return apply


def _set_trace(k: int, field: str, value: Any) -> Callable[[Path], None]:
    return _json(lambda d: d["traces"][k].__setitem__(field, value))


def _symlink_outside(root: Path) -> None:
    outside = root.parent / f"{root.name}-outside.csv"
    outside.write_text((root / "traces/a.csv").read_text())
    (root / "traces/link.csv").symlink_to(outside)
    _set_trace(0, "file", "traces/link.csv")(root)


def _parent_file(root: Path) -> None:
    (root.parent / "outside.csv").write_text((root / "traces/a.csv").read_text())
    _set_trace(0, "file", "../outside.csv")(root)


def _corrupt_parquet(root: Path) -> None:
    (root / "traces/a.parquet").write_bytes(b"PAR1 this is not really parquet PAR1")
    _set_trace(0, "file", "traces/a.parquet")(root)


def _rename_pull_speed(d: dict[str, Any]) -> None:
    d["traces"][1]["pull_speed"] = d["traces"][1].pop("pull_speed_m_s")


A, B, J = "traces/a.csv", "traces/b.csv", "dataset.json"
CORRUPTIONS = (
    # cell and column problems: file, row and column
    Corruption("text_in_force", _cell(A, 7, "force_n", "abc"), A, 7, "force_n", "not a number"),
    Corruption("nan_time", _cell(A, 3, "time_s", "NaN"), A, 3, "time_s", "not a finite number"),
    Corruption("inf_force", _cell(B, 12, "force_n", "-inf"), B, 12, "force_n", "finite"),
    Corruption("overflow", _cell(B, 40, "force_n", "1e999"), B, 40, "force_n", "finite"),
    Corruption("empty_cell", _cell(A, 20, "force_n", ""), A, 20, "force_n", "empty cell"),
    Corruption("repeated_time", _cell(B, 10, "time_s", "0.08"), B, 10, "time_s", "repeats"),
    Corruption("time_backwards", _cell(A, 30, "time_s", "0.1"), A, 30, "time_s", "earlier"),
    Corruption("bad_flag", _cell(B, 5, "ultrasound_on", "2"), B, 5, "ultrasound_on", "0, 1"),
    Corruption(
        "word_flag", _cell(A, 25, "ultrasound_on", "on"), A, 25, "ultrasound_on", "true or false"
    ),
    Corruption(
        "misspelled_column",
        _rewrite(A, lambda lines: [lines[0].replace("force_n", "forse_n"), *lines[1:]]),
        A,
        0,
        "force_n",
        "rename it to 'force_n'",
    ),
    Corruption(
        "missing_column",
        _rewrite(B, lambda lines: [line.rpartition(",")[0] for line in lines]),
        B,
        0,
        "ultrasound_on",
        "missing column",
    ),
    Corruption(
        "short_row",
        _rewrite(A, lambda lines: [*lines[:15], lines[15].rpartition(",")[0], *lines[16:]]),
        A,
        15,
        "ultrasound_on",
        "one value per column",
    ),
    Corruption(
        "header_only", _rewrite(B, lambda lines: lines[:1]), B, 0, None, "at least 2 samples"
    ),
    Corruption(
        "semicolons",
        _rewrite(A, lambda lines: [line.replace(",", ";") for line in lines]),
        A,
        0,
        None,
        "commas",
    ),
    # file problems
    Corruption("empty_file", lambda root: (root / A).write_bytes(b""), A, None, None, "empty"),
    Corruption(
        "not_utf8", lambda root: (root / B).write_bytes(b"time_s\xff\xfe"), B, None, None, "UTF-8"
    ),
    Corruption("corrupt_parquet", _corrupt_parquet, "traces/a.parquet", None, None, "Parquet"),
    # dataset.json problems: the file and the field
    Corruption(
        "percent_amplitude",
        _set_trace(0, "amplitude_fraction", 50),
        J,
        None,
        "traces[0].amplitude_fraction",
        "divide by 100",
    ),
    Corruption(
        "negative_load",
        _set_trace(1, "normal_load_n", -670),
        J,
        None,
        "traces[1].normal_load_n",
        "> 0",
    ),
    Corruption(
        "missing_file",
        _set_trace(0, "file", "traces/c.csv"),
        J,
        None,
        "traces[0].file",
        "not found",
    ),
    Corruption("path_traversal", _parent_file, J, None, "traces[0].file", "outside"),
    Corruption(
        "absolute_path",
        lambda root: _set_trace(0, "file", str((root / A).resolve()))(root),
        J,
        None,
        "traces[0].file",
        "absolute",
    ),
    Corruption("symlink_escape", _symlink_outside, J, None, "traces[0].file", "symbolic link"),
    Corruption(
        "folder_as_file",
        lambda root: ((root / "traces/d.csv").mkdir(), _set_trace(1, "file", "traces/d.csv")(root)),
        J,
        None,
        "traces[1].file",
        "folder",
    ),
    Corruption(
        "unknown_suffix",
        _set_trace(1, "file", "traces/b.xlsx"),
        J,
        None,
        "traces[1].file",
        ".csv or .parquet",
    ),
    Corruption(
        "duplicate_id",
        _set_trace(1, "id", TRACE_IDS[0]),
        J,
        None,
        "traces[1].id",
        "already used",
    ),
    Corruption(
        "misspelled_field",
        _json(_rename_pull_speed),
        J,
        None,
        "traces[1].pull_speed",
        "did you mean 'pull_speed_m_s'",
    ),
    Corruption(
        "schema_version",
        _json(lambda d: d.__setitem__("schema_version", "2")),
        J,
        None,
        "schema_version",
        "'1'",
    ),
    Corruption(
        "huge_number",
        _replace_text(J, '"normal_load_n": 450.0', '"normal_load_n": 4.5e400'),
        J,
        None,
        None,
        "too large for a double",
    ),
    Corruption(
        "duplicate_key",
        _replace_text(J, '"name": "tiny",', '"name": "tiny",\n  "name": "again",'),
        J,
        None,
        None,
        "line 4: field 'name' appears twice",
    ),
    Corruption(
        "invalid_json",
        lambda root: (root / J).write_text('{"schema_version": "1",\n  "name": }'),
        J,
        None,
        None,
        "line 2",
    ),
)


def expected_location(root: Path, case: Corruption) -> list[str]:
    """Fragments the printed problem must contain: file path, row, column and hint."""
    parts = [str(root / case.file), case.hint]
    if case.row is not None:
        parts.append(f"row {case.row}")
    if case.column is not None:
        parts.append(f"column '{case.column}'")
    return parts
