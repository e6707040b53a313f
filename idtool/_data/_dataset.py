"""Bench datasets, format v1: load, check and hash (see ``datasets_schema/README.md``).

A dataset is a folder holding ``dataset.json`` and one table per trace. Loading reads the
bytes at the edge (:func:`load_dataset`), then checks them all (:func:`dataset_from_bytes`,
also used by the simulator on files it has not written yet) and either returns an
immutable :class:`Dataset` or raises one :class:`IdtoolError` listing every problem
found in every file, each located by file, row and column.
"""

from __future__ import annotations

import dataclasses
import hashlib
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from idtool._data._levels import is_levels_dataset
from idtool._data._paths import DATASET_FILE, dataset_json_path, path_problem, read_trace_file
from idtool._data._plausibility import force_warnings, metadata_warnings, time_warnings
from idtool._data._schema import DATASET_SCHEMA, schema_problems, trace_columns
from idtool._data._table_check import TraceSamples, check_table
from idtool._data._table_read import read_table
from idtool._errors import IdtoolError, Problem
from idtool._jsonio import parse_json

__all__ = [
    "Dataset",
    "Rig",
    "Trace",
    "TransducerSpec",
    "dataset_from_bytes",
    "dataset_sha256",
    "load_dataset",
]

Reader = Callable[[str, str], tuple[bytes | None, list[Problem]]]


@dataclasses.dataclass(frozen=True)
class TransducerSpec:
    """The horn's transducer as a single-degree-of-freedom resonator (paper eq. 6), for
    the ``sdof`` coupling law (:mod:`idtool._model._coupling_sdof`).

    Attributes:
        modal_mass_kg: modal mass m of the vibrating stack [kg].
        natural_frequency_hz: its natural frequency fn = sqrt(Ks / m) / (2 pi) [Hz].
        quality_factor: its mechanical Q (1 / (2 zeta)), or None: the fit identifies the
            damping.
    """

    modal_mass_kg: float
    natural_frequency_hz: float
    quality_factor: float | None = None

    @classmethod
    def from_dict(cls, doc: Any) -> TransducerSpec | None:
        """From ``rig.transducer`` (checked by the schema); None when left out."""
        if doc is None:
            return None
        q = doc.get("quality_factor")
        return cls(
            modal_mass_kg=float(doc["modal_mass_kg"]),
            natural_frequency_hz=float(doc["natural_frequency_hz"]),
            quality_factor=None if q is None else float(q),
        )

    def to_dict(self) -> dict[str, float]:
        out = {
            "modal_mass_kg": self.modal_mass_kg,
            "natural_frequency_hz": self.natural_frequency_hz,
        }
        if self.quality_factor is not None:
            out["quality_factor"] = self.quality_factor
        return out


@dataclasses.dataclass(frozen=True)
class Rig:
    """The bench: the ultrasonic horn's frequency [Hz] and amplitude at 100% command [m],
    and optionally the mains frequency [Hz] its load cell picks up as hum (None: not
    given; the fit then looks for the hum in the traces, see :mod:`idtool._data._mains`),
    and optionally the transducer's modal data (:class:`TransducerSpec`)."""

    vibration_frequency_hz: float
    max_amplitude_m: float
    mains_frequency_hz: float | None = None
    transducer: TransducerSpec | None = None


@dataclasses.dataclass(frozen=True, eq=False)
class Trace:
    """One pull: its operating point and its samples (arrays are read-only).

    Attributes:
        id: unique name within the dataset.
        file: table path relative to the dataset folder.
        normal_load_n: static normal load [N].
        amplitude_fraction: commanded horn amplitude, fraction of the maximum [-].
        pull_speed_m_s: pull speed [m/s].
        time_s: sample times [s], strictly increasing.
        force_n: load-cell force [N].
        ultrasound_on: logged ON flag per sample (bool).
        on_windows_s: ``(start_s, end_s)`` per ON window: time of the first ON sample and
            of the first OFF sample after it (last time plus one step if ON to the end).
        sample_rate_hz: one over the median time step [Hz].
        notes: optional free text from dataset.json.
    """

    id: str
    file: str
    normal_load_n: float
    amplitude_fraction: float
    pull_speed_m_s: float
    time_s: np.ndarray
    force_n: np.ndarray
    ultrasound_on: np.ndarray
    on_windows_s: tuple[tuple[float, float], ...]
    sample_rate_hz: float
    notes: str | None = None

    @property
    def duration_s(self) -> float:
        """Time from the first to the last sample [s]."""
        return float(self.time_s[-1] - self.time_s[0])

    @property
    def n_samples(self) -> int:
        """Number of samples."""
        return int(self.time_s.size)


@dataclasses.dataclass(frozen=True, eq=False)
class Dataset:
    """A checked bench dataset.

    Attributes:
        name, material: from dataset.json.
        rig: the horn.
        traces: in the order of dataset.json.
        sha256: :func:`dataset_sha256` of dataset.json and the trace files' bytes.
        warnings: problems of severity ``"warning"`` (legal but suspicious values).
        description: optional free text from dataset.json.
        extensions: the top-level ``x_*`` fields of dataset.json (the lab's own: operator,
            job number, webbing batch...), in file order; idtool's models ignore them,
            reports show them.
        path: the folder it was loaded from (None if built in memory).
    """

    name: str
    material: str
    rig: Rig
    traces: tuple[Trace, ...]
    sha256: str
    warnings: tuple[Problem, ...] = ()
    description: str | None = None
    path: Path | None = None
    extensions: Mapping[str, Any] = dataclasses.field(default_factory=dict)

    def trace(self, trace_id: str) -> Trace:
        """The trace named ``trace_id``."""
        for trace in self.traces:
            if trace.id == trace_id:
                return trace
        raise KeyError(trace_id)


def dataset_sha256(json_bytes: bytes, trace_bytes: Sequence[bytes]) -> str:
    """SHA-256 (hex) identifying a dataset's content.

    Over, in order, dataset.json then each trace file in the order of its ``traces``
    list: the file's size as an 8-byte big-endian unsigned integer, then its bytes.
    """
    digest = hashlib.sha256()
    for data in (json_bytes, *trace_bytes):
        _hash_file(digest, data)
    return digest.hexdigest()


def _hash_file(digest: Any, data: bytes) -> None:
    """Add one file to a :func:`dataset_sha256` digest: its size, then its bytes."""
    digest.update(len(data).to_bytes(8, "big"))
    digest.update(data)


def _read_only(values: np.ndarray, dtype: type) -> np.ndarray:
    """``values`` made read-only: in place when it is an array of its own (check_table
    builds fresh ones, and nothing else holds them), else a read-only copy. Not copying
    saves 20 MB per 2.5-million-sample column."""
    out: np.ndarray = np.asarray(values, dtype=dtype)
    if out is not values or not out.flags.owndata:
        out = np.array(values, dtype=dtype, copy=True)
    out.setflags(write=False)
    return out


def _duplicate_problems(entries: list[Any]) -> list[Problem]:
    """Two traces with one id (error) or one file (warning)."""
    problems = []
    first: dict[tuple[str, object], int] = {}
    for i, entry in enumerate(entries):
        if not isinstance(entry, Mapping):
            continue
        for field in ("id", "file"):
            value = entry.get(field)
            if not isinstance(value, str):
                continue
            if (field, value) not in first:
                first[(field, value)] = i
                continue
            j = first[(field, value)]
            if field == "id":
                text = f"id '{value}' is already used by traces[{j}]: give each trace its own id"
                problems.append(Problem(text, file=DATASET_FILE, column=f"traces[{i}].id"))
            else:
                text = f"'{value}' is also the file of traces[{j}]: is this a copy-paste slip?"
                problems.append(
                    Problem(text, file=DATASET_FILE, column=f"traces[{i}].file", severity="warning")
                )
    return problems


def _window_warnings(entry: Mapping[str, Any], samples: TraceSamples, file: str) -> list[Problem]:
    flag = trace_columns()[2]
    alpha = entry.get("amplitude_fraction")
    if not isinstance(alpha, int | float):
        return []
    if alpha > 0 and not samples.on_windows_s:
        text = f"ultrasound is never ON although amplitude_fraction is {alpha:g}"
    elif alpha == 0 and samples.on_windows_s:
        text = "ultrasound is ON in this trace although amplitude_fraction is 0"
    else:
        return []
    return [Problem(text, file=file, column=flag, severity="warning")]


def _check_trace(
    index: int, entry: object, read: Reader
) -> tuple[TraceSamples | None, bytes | None, list[Problem]]:
    """Read and check the file of ``traces[index]``; samples only if it is clean."""
    if not isinstance(entry, Mapping) or not isinstance(entry.get("file"), str):
        return None, None, []  # the schema check reports it
    rel = entry["file"]
    data, problems = read(rel, f"traces[{index}].file")
    if data is None:
        return None, None, problems
    table, found = read_table(data, rel)
    problems += found
    if table is None:
        return None, data, problems
    samples, found = check_table(table, rel)
    problems += found
    if samples is None:
        return None, data, problems
    time_name, force_name, _ = trace_columns()
    problems += force_warnings(
        samples.force_n, samples.ultrasound_on, entry.get("normal_load_n"), rel, force_name
    )
    problems += time_warnings(samples.time_s, rel, time_name)
    problems += _window_warnings(entry, samples, rel)
    return samples, data, problems


def _trace(entry: Mapping[str, Any], samples: TraceSamples) -> Trace:
    return Trace(
        id=entry["id"],
        file=entry["file"],
        normal_load_n=float(entry["normal_load_n"]),
        amplitude_fraction=float(entry["amplitude_fraction"]),
        pull_speed_m_s=float(entry["pull_speed_m_s"]),
        time_s=_read_only(samples.time_s, np.float64),
        force_n=_read_only(samples.force_n, np.float64),
        ultrasound_on=_read_only(samples.ultrasound_on, np.bool_),
        on_windows_s=samples.on_windows_s,
        sample_rate_hz=float(samples.sample_rate_hz),
        notes=entry.get("notes"),
    )


def _optional_float(value: object) -> float | None:
    """``float(value)``, or None for a field left out (the schema checked its type)."""
    return None if value is None else float(value)  # type: ignore[arg-type]


def _located(problems: list[Problem], root: Path | None) -> list[Problem]:
    """File names as the user can open them: under the dataset folder; errors first."""
    if root is not None:
        problems = [
            dataclasses.replace(p, file=str(root / p.file)) if p.file else p for p in problems
        ]
    return sorted(problems, key=lambda p: p.severity != "error")


def _assemble(json_bytes: bytes, read: Reader, root: Path | None, label: str) -> Dataset:
    document, problems = parse_json(json_bytes, DATASET_FILE)
    if problems:
        raise IdtoolError(f"{label}: {DATASET_FILE} is not valid", _located(problems, root))
    problems += schema_problems(document, DATASET_SCHEMA, DATASET_FILE)
    problems += metadata_warnings(document, DATASET_FILE)
    entries = document.get("traces") if isinstance(document, dict) else None
    entries = entries if isinstance(entries, list) else []
    problems += _duplicate_problems(entries)
    # Hashed as read, so that only one trace file's bytes are held at a time (a 2.5
    # million-row CSV file is 45 MB); the digest is used only if every file was read.
    digest = hashlib.sha256()
    _hash_file(digest, json_bytes)
    checked = []
    for i, entry in enumerate(entries):
        samples, data, found = _check_trace(i, entry, read)
        problems += found
        if data is not None:
            _hash_file(digest, data)
        checked.append((entry, samples))
        del data
    errors = sum(p.severity == "error" for p in problems)
    if errors:
        raise IdtoolError(
            f"{label}: {errors} error(s) in the dataset; fix them all and check again with "
            "`idtool validate`",
            _located(problems, root),
        )
    traces = []
    for entry, samples in checked:
        assert samples is not None  # no error: every trace was read (and hashed)
        traces.append(_trace(entry, samples))
    return Dataset(
        name=document["name"],
        material=document["material"],
        rig=Rig(
            vibration_frequency_hz=float(document["rig"]["vibration_frequency_hz"]),
            max_amplitude_m=float(document["rig"]["max_amplitude_m"]),
            mains_frequency_hz=_optional_float(document["rig"].get("mains_frequency_hz")),
            transducer=TransducerSpec.from_dict(document["rig"].get("transducer")),
        ),
        traces=tuple(traces),
        sha256=digest.hexdigest(),
        warnings=tuple(_located(problems, root)),
        description=document.get("description"),
        path=root,
        extensions={k: v for k, v in document.items() if k.startswith("x_")},
    )


def load_dataset(path: str | Path) -> Dataset:
    """Load and check the dataset in folder ``path`` (or at its ``dataset.json``).

    Raises:
        IdtoolError: listing every problem in dataset.json and in every trace file.
    """
    json_file = dataset_json_path(path)
    root = json_file.parent
    try:
        json_bytes = json_file.read_bytes()
    except OSError as err:
        raise IdtoolError(f"cannot read {json_file} ({err.strerror or err})") from None
    if is_levels_dataset(json_file):
        raise IdtoolError(
            f"{root} is a friction table (kind: levels), not traces: load it with "
            "idtool.load_levels and fit it with idtool.fit_levels (or `idtool fit`)"
        )
    return _assemble(
        json_bytes, lambda rel, where: read_trace_file(root, rel, where), root, str(root)
    )


def dataset_from_bytes(
    json_bytes: bytes, files: Mapping[str, bytes], label: str = "dataset"
) -> Dataset:
    """Check a dataset given as bytes: ``dataset.json`` and trace files by relative path.

    Exactly the checks of :func:`load_dataset` except those of the file system.
    """

    def read(rel: str, where: str) -> tuple[bytes | None, list[Problem]]:
        refused = path_problem(rel)
        if refused is None and rel in files:
            return files[rel], []
        message = f"'{rel}': {refused}" if refused else f"file '{rel}' not provided"
        return None, [Problem(message, file=DATASET_FILE, column=where)]

    return _assemble(json_bytes, read, None, label)
