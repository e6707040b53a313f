"""Write a :class:`Dataset` as format v1 files: deterministic bytes, all-or-nothing folder.

Rendering is a pure function of the dataset, and loading its output gives back the same
arrays (CSV numbers are written in their shortest exact form), so rendering a loaded
dataset again reproduces the bytes and the sha256.
"""

from __future__ import annotations

import json
import os
from collections.abc import Mapping
from pathlib import Path, PurePosixPath
from typing import Any

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from idtool._atomic import atomic_output_dir
from idtool._data._dataset import Dataset, Rig
from idtool._data._paths import DATASET_FILE
from idtool._data._schema import trace_columns

__all__ = [
    "dataset_document",
    "document",
    "json_bytes",
    "render_dataset",
    "render_table",
    "trace_entry",
    "write_dataset",
    "write_files",
]


def trace_entry(
    trace_id: str,
    file: str,
    normal_load_n: float,
    amplitude_fraction: float,
    pull_speed_m_s: float,
    notes: str | None = None,
) -> dict[str, Any]:
    """One item of dataset.json's ``traces`` list."""
    entry: dict[str, Any] = {"id": trace_id, "file": file, "normal_load_n": normal_load_n}
    entry["amplitude_fraction"] = amplitude_fraction
    entry["pull_speed_m_s"] = pull_speed_m_s
    if notes is not None:
        entry["notes"] = notes
    return entry


def document(
    name: str,
    material: str,
    rig: Rig,
    entries: list[dict[str, Any]],
    description: str | None,
    extensions: Mapping[str, Any] | None = None,
) -> dict[str, Any]:
    """A dataset.json document, fields in the order of the schema, then the ``x_*``
    extension fields."""
    out: dict[str, Any] = {"schema_version": "1", "name": name, "material": material}
    if description is not None:
        out["description"] = description
    out["rig"] = {
        "vibration_frequency_hz": rig.vibration_frequency_hz,
        "max_amplitude_m": rig.max_amplitude_m,
    }
    if rig.mains_frequency_hz is not None:
        out["rig"]["mains_frequency_hz"] = rig.mains_frequency_hz
    if rig.transducer is not None:
        out["rig"]["transducer"] = rig.transducer.to_dict()
    out["traces"] = entries
    for key, value in (extensions or {}).items():
        if not key.startswith("x_"):
            raise ValueError(f"extensions: {key!r} is not an extension field (x_...)")
        out[key] = value
    return out


def dataset_document(dataset: Dataset) -> dict[str, Any]:
    """The dataset.json content of ``dataset``, its top-level ``x_*`` fields kept (those
    of the rig and the traces are not)."""
    entries = [
        trace_entry(t.id, t.file, t.normal_load_n, t.amplitude_fraction, t.pull_speed_m_s, t.notes)
        for t in dataset.traces
    ]
    return document(
        dataset.name,
        dataset.material,
        dataset.rig,
        entries,
        dataset.description,
        dataset.extensions,
    )


def json_bytes(document: Mapping[str, Any]) -> bytes:
    """Indented UTF-8 JSON with a final newline; NaN and inf are refused."""
    return (json.dumps(document, indent=2, allow_nan=False, ensure_ascii=False) + "\n").encode()


def _csv_bytes(time_s: np.ndarray, force_n: np.ndarray, on: np.ndarray) -> bytes:
    # repr is the shortest text that reads back as the same double.
    lines = [",".join(trace_columns())]
    lines += [
        f"{t!r},{f!r},{int(o)}"
        for t, f, o in zip(time_s.tolist(), force_n.tolist(), on.tolist(), strict=True)
    ]
    return ("\n".join(lines) + "\n").encode()


# zstd's own default level. Level 19 (until 2026-11-27) wrote an example trace (7,271
# rows) in 16.6 ms, 24.2 kB; level 3 in 0.4 ms, 29.5 kB (+22%). Every simulated bench is
# rendered to these bytes and read back (its sha256 is that of the files it would write),
# and the simulator's rendering at 19 was 6% of the test suite's CPU time (py-spy).
PARQUET_ZSTD_LEVEL = 3


def _parquet_bytes(time_s: np.ndarray, force_n: np.ndarray, on: np.ndarray) -> bytes:
    names = trace_columns()
    table = pa.table(
        {
            names[0]: pa.array(time_s, pa.float64()),
            names[1]: pa.array(force_n, pa.float64()),
            names[2]: pa.array(on, pa.bool_()),
        }
    )
    sink = pa.BufferOutputStream()
    # Plain encoding + zstd: half the size of dictionary or byte-stream-split encodings
    # on noisy, quantised forces (measured on the example dataset).
    pq.write_table(
        table,
        sink,
        compression="zstd",
        compression_level=PARQUET_ZSTD_LEVEL,
        use_dictionary=False,
        write_statistics=False,
    )
    return bytes(sink.getvalue().to_pybytes())


def render_table(file: str, time_s: np.ndarray, force_n: np.ndarray, on: np.ndarray) -> bytes:
    """A trace table's bytes, CSV or Parquet according to the suffix of ``file``."""
    writer = _parquet_bytes if file.lower().endswith(".parquet") else _csv_bytes
    return writer(np.asarray(time_s), np.asarray(force_n), np.asarray(on, dtype=bool))


def render_dataset(dataset: Dataset) -> dict[str, bytes]:
    """Every file of the dataset by relative path: dataset.json first, then the traces."""
    files = {DATASET_FILE: json_bytes(dataset_document(dataset))}
    for t in dataset.traces:
        files[t.file] = render_table(t.file, t.time_s, t.force_n, t.ultrasound_on)
    return files


def write_files(folder: Path, files: Mapping[str, bytes]) -> None:
    """Write ``files`` (relative POSIX paths) under ``folder``."""
    for rel, data in files.items():
        target = folder.joinpath(*PurePosixPath(rel).parts)
        target.parent.mkdir(parents=True, exist_ok=True)
        target.write_bytes(data)


def write_dataset(
    dataset: Dataset,
    out: str | os.PathLike[str],
    *,
    force: bool = False,
    extra_files: Mapping[str, bytes] | None = None,
) -> Path:
    """Write ``dataset`` (and ``extra_files``) as folder ``out``, all or nothing.

    Raises:
        IdtoolError: ``out`` exists and ``force`` is False.
    """
    with atomic_output_dir(out, force=force) as tmp:
        write_files(tmp, render_dataset(dataset))
        write_files(tmp, extra_files or {})
    return Path(out)
