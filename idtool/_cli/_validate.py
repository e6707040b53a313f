"""``idtool validate DIR``: check a bench dataset and summarise it (format v1).

Valid: a table of the traces and the warnings, exit status 0. Invalid: every problem
found, each located by file, row and column, exit status 2 (via :mod:`idtool._cli._main`).
"""

from __future__ import annotations

import argparse
import json
from typing import Any

from idtool._data._dataset import Dataset, Trace, load_dataset

__all__ = ["dataset_summary", "register", "summary_table"]

_HEADER = (
    f"{'id':<18} {'load_N':>7} {'ampl':>5} {'speed_m_s':>9} {'duration_s':>10} "
    f"{'rate_Hz':>8}  ON windows [s]"
)


def _windows(trace: Trace) -> str:
    return ", ".join(f"{a:.3f}-{b:.3f}" for a, b in trace.on_windows_s) or "none"


def summary_table(dataset: Dataset) -> str:
    """One line per trace: operating point, duration, sample rate and ON windows."""
    lines = [_HEADER]
    for t in dataset.traces:
        lines.append(
            f"{t.id:<18} {t.normal_load_n:>7g} {t.amplitude_fraction:>5.0%} "
            f"{t.pull_speed_m_s:>9g} {t.duration_s:>10.3f} {t.sample_rate_hz:>8.4g}  "
            f"{_windows(t)}"
        )
    return "\n".join(lines)


def dataset_summary(dataset: Dataset) -> dict[str, Any]:
    """The summary as plain JSON-able data."""
    return {
        "name": dataset.name,
        "material": dataset.material,
        "path": None if dataset.path is None else str(dataset.path),
        "sha256": dataset.sha256,
        "rig": {
            "vibration_frequency_hz": dataset.rig.vibration_frequency_hz,
            "max_amplitude_m": dataset.rig.max_amplitude_m,
        },
        "traces": [
            {
                "id": t.id,
                "file": t.file,
                "normal_load_n": t.normal_load_n,
                "amplitude_fraction": t.amplitude_fraction,
                "pull_speed_m_s": t.pull_speed_m_s,
                "n_samples": t.n_samples,
                "duration_s": t.duration_s,
                "sample_rate_hz": t.sample_rate_hz,
                "on_windows_s": [list(w) for w in t.on_windows_s],
            }
            for t in dataset.traces
        ],
        "warnings": [str(w) for w in dataset.warnings],
    }


def _run(args: argparse.Namespace) -> int:
    from idtool._data._levels import is_levels_dataset, load_levels

    if is_levels_dataset(args.dir):  # a friction table (kind: levels)
        from idtool._cli._import_levels import levels_summary

        table = load_levels(args.dir)
        if args.json:
            print(json.dumps(table.to_document(), indent=1))
            return 0
        print(f"friction table: {levels_summary(table)}")
        print("valid: no errors")
        return 0
    dataset = load_dataset(args.dir)
    if args.json:
        print(json.dumps(dataset_summary(dataset), indent=1))
        return 0
    rig = dataset.rig
    print(f"dataset '{dataset.name}' ({dataset.material})")
    print(f"folder  {dataset.path}")
    print(f"sha256  {dataset.sha256}")
    print(
        f"rig     {rig.vibration_frequency_hz:g} Hz, max amplitude {rig.max_amplitude_m * 1e6:g} µm"
    )
    print(f"{len(dataset.traces)} trace(s):")
    print(summary_table(dataset))
    if dataset.warnings:
        print(f"{len(dataset.warnings)} warning(s):")
        for warning in dataset.warnings:
            print(f"  {warning}")
    print("valid: no errors")
    return 0


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "validate",
        help="check a bench dataset (format v1) and summarise its traces",
        description="Check a dataset folder (dataset.json plus one CSV or Parquet table per "
        "trace; see datasets_schema/README.md) and print a summary of its traces, or every "
        "problem found with its file, row and column (exit status 2).",
    )
    p.add_argument("dir", metavar="DIR", help="dataset folder (or its dataset.json)")
    p.add_argument("--json", action="store_true", help="print the summary as JSON")
    p.set_defaults(func=_run)
