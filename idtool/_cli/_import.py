"""``idtool import FILE... --out DIR``: DAQ exports into a validated format-v1 dataset.

A thin layer over :func:`idtool._data._import.import_daq`: options with units
(``--speed 25mm/s``, ``--debounce 5ms``) become SI values, and the summary is that of
``idtool validate`` plus where each trace came from.
"""

from __future__ import annotations

import argparse
import json
from collections.abc import Callable
from pathlib import Path
from typing import Any

from idtool._cli._validate import dataset_summary, summary_table
from idtool._data._dataset import Dataset
from idtool._data._import_units import value_in_si

__all__ = ["register"]

_EXAMPLE = """\
Example: a DAQ export per pull, semicolon-separated with decimal commas, header
'Time (s);Load (N);US trigger (V)', a 0-5 V trigger channel, and a table of operating
points conditions.csv ('file;load (N);amplitude (%);speed (mm/s)'):

  idtool import raw/*.csv --out datasets/run-0312 --material "PES webbing, steel horn" \\
      --horn-hz 20000 --max-amplitude-um 85 --time Time --force-col Load \\
      --trigger "US trigger" --conditions conditions.csv

or, with the operating point in the file names (N670_A50_run2.csv):

  ... --pattern 'N(?P<load_n>\\d+)_A(?P<amplitude_percent>\\d+)' --speed 25mm/s"""


class _Formatter(argparse.HelpFormatter):
    """Wraps paragraphs as usual but keeps indented ones (the examples) as written."""

    def _fill_text(self, text: str, width: int, indent: str) -> str:
        paragraphs = text.split("\n\n")
        return "\n\n".join(
            "\n".join(indent + line for line in p.splitlines())
            if p.startswith(" ")
            else super(_Formatter, self)._fill_text(p, width, indent)
            for p in paragraphs
        )


def _in_si(quantity: str) -> Callable[[str], float]:
    """An argparse type: a number with an optional unit, in SI."""

    def parse(text: str) -> float:
        try:
            return value_in_si(text, quantity)
        except ValueError as err:
            raise argparse.ArgumentTypeError(str(err)) from None

    parse.__name__ = quantity  # argparse names the type in its messages
    return parse


def _column(text: str) -> str | int:
    """A column: its 1-based number, or (part of) its header."""
    return int(text) if text.strip().isdigit() else text


def _extension(text: str) -> tuple[str, str]:
    key, sep, value = text.partition("=")
    if not sep or not key.strip():
        raise argparse.ArgumentTypeError(f"{text!r}: write KEY=VALUE, e.g. operator=J. Smith")
    key = key.strip()
    return (key if key.startswith("x_") else f"x_{key}"), value


def _summary(dataset: Dataset, files: list[str]) -> dict[str, Any]:
    """``idtool validate --json``'s summary, with the imported files and each trace's notes."""
    out = dataset_summary(dataset)
    out["imported_from"] = files
    for entry, trace in zip(out["traces"], dataset.traces, strict=True):
        entry["notes"] = trace.notes
    return out


def _run(args: argparse.Namespace) -> int:
    # local: the importer's readers, loaded only by the command that runs them (every
    # command's module is imported to build the parser)
    from idtool._data._import import import_daq

    dataset = import_daq(
        args.files,
        args.out,
        name=args.name or Path(args.out).resolve().name,
        material=args.material,
        vibration_frequency_hz=args.horn_hz,
        max_amplitude_m=(
            args.max_amplitude_m if args.max_amplitude_um is None else args.max_amplitude_um / 1e6
        ),
        mains_frequency_hz=args.mains_hz,
        description=args.description,
        extensions=dict(args.x or []),
        time_column=args.time,
        force_column=args.force_col,
        trigger_column=args.trigger,
        on_column=args.on,
        time_unit=args.time_unit,
        force_unit=args.force_unit,
        trigger_unit=args.trigger_unit,
        threshold_v=args.threshold,
        hysteresis_v=args.hysteresis,
        debounce_s=args.debounce,
        active_low=args.active_low,
        max_on_windows=args.max_windows,
        conditions=args.conditions,
        pattern=args.pattern,
        normal_load_n=args.load,
        amplitude_fraction=args.amplitude,
        pull_speed_m_s=args.speed,
        load_unit=args.load_unit,
        amplitude_unit=args.amplitude_unit,
        speed_unit=args.speed_unit,
        sep=args.sep,
        decimal=args.decimal,
        skip_rows=args.skip_rows,
        encoding=args.encoding,
        trace_format=args.format,
        force=args.force,
    )
    if args.json:
        print(json.dumps(_summary(dataset, args.files), indent=1))
        return 0
    rig = dataset.rig
    print(
        f"imported {len(dataset.traces)} file(s) as dataset '{dataset.name}' ({dataset.material})"
    )
    print(f"folder  {dataset.path}")
    print(f"sha256  {dataset.sha256}")
    print(
        f"rig     {rig.vibration_frequency_hz:g} Hz, max amplitude {rig.max_amplitude_m * 1e6:g} µm"
    )
    print(summary_table(dataset))
    print("where each trace came from:")
    for trace in dataset.traces:
        print(f"  {trace.id}: {trace.notes}")
    if dataset.warnings:
        print(f"{len(dataset.warnings)} warning(s):")
        for warning in dataset.warnings:
            print(f"  {warning}")
    print("valid: no errors (checked as `idtool validate` does)")
    return 0


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "import",
        help="turn DAQ exports (CSV or Parquet) into a validated dataset",
        formatter_class=_Formatter,
        description="Turn DAQ exports, one CSV or Parquet file per pull, into a format-v1 "
        "dataset (datasets_schema/README.md): any separator and decimal mark, units in the "
        "headers (Time (ms), Load [kN]...) converted to SI, the ON state from a trigger "
        "channel (Schmitt trigger with hysteresis, debounced) or a 0/1 column, the "
        "operating point of each file from a conditions table, the file name or options. "
        "The dataset is written to a temporary folder, validated, then renamed into "
        "place; on any problem nothing is written and every problem is listed with its "
        f"file, row and column.\n\n{_EXAMPLE}",
    )
    p.add_argument("files", nargs="+", metavar="FILE", help="DAQ exports (.csv, .txt, .parquet)")
    p.add_argument("--out", required=True, metavar="DIR", help="dataset folder to create")
    p.add_argument(
        "--force",
        action="store_true",
        help="replace DIR if it exists (takes no value: the force column is --force-col)",
    )
    p.add_argument("--json", action="store_true", help="print the summary as JSON")
    rig = p.add_argument_group("dataset and rig")
    rig.add_argument(
        "--name", metavar="NAME", help="dataset name (default: the folder name of --out)"
    )
    rig.add_argument("--material", required=True, metavar="TEXT", help="webbing and horn materials")
    rig.add_argument("--description", metavar="TEXT", help="free text: how, when, by whom")
    rig.add_argument(
        "--horn-hz", type=float, required=True, metavar="HZ", help="horn frequency [Hz], e.g. 20000"
    )
    amp = rig.add_mutually_exclusive_group(required=True)
    amp.add_argument(
        "--max-amplitude-um", type=float, metavar="UM", help="horn amplitude at 100%% [µm], e.g. 85"
    )
    amp.add_argument(
        "--max-amplitude-m", type=float, metavar="M", help="the same in metres, e.g. 85e-6"
    )
    rig.add_argument("--mains-hz", type=float, metavar="HZ", help="mains frequency [Hz] (50 or 60)")
    rig.add_argument(
        "--x",
        type=_extension,
        action="append",
        metavar="KEY=VALUE",
        help="an extension field x_KEY of dataset.json (repeatable)",
    )
    cols = p.add_argument_group(
        "columns",
        "COL is a header, matched without case and with or without its unit "
        "('Load' finds 'Load (N)'), or a 1-based column number",
    )
    cols.add_argument("--time", required=True, type=_column, metavar="COL", help="time column")
    cols.add_argument(
        "--force-col",
        required=True,
        type=_column,
        metavar="COL",
        help="load-cell (pull force) column",
    )
    on = cols.add_mutually_exclusive_group(required=True)
    on.add_argument("--trigger", type=_column, metavar="COL", help="trigger channel [V]")
    on.add_argument("--on", type=_column, metavar="COL", help="0/1 column of the ON state")
    for name, what in (("time", "s, ms, us"), ("force", "N, kN, daN"), ("trigger", "V, mV")):
        cols.add_argument(
            f"--{name}-unit",
            metavar="UNIT",
            help=f"unit of the {name} column if its header gives none ({what})",
        )
    trig = p.add_argument_group("trigger")
    trig.add_argument(
        "--threshold",
        type=_in_si("voltage"),
        metavar="V",
        help="switching threshold (default: midway between the two levels)",
    )
    trig.add_argument(
        "--hysteresis",
        type=_in_si("voltage"),
        metavar="V",
        help="band around the threshold (default: 20%% of the swing)",
    )
    trig.add_argument(
        "--debounce",
        type=_in_si("time"),
        default=0.005,
        metavar="T",
        help="ignore ON/OFF pulses shorter than this (default 5ms; 0: none)",
    )
    trig.add_argument("--active-low", action="store_true", help="the horn is ON while low")
    trig.add_argument(
        "--max-windows",
        type=int,
        default=10,
        metavar="N",
        help="more ON windows than this per trace is an error (default 10)",
    )
    cond = p.add_argument_group(
        "operating points", "each file needs a load, amplitude and speed, each from one source"
    )
    cond.add_argument(
        "--conditions",
        metavar="TABLE",
        help="CSV with columns file, load, amplitude, speed (units in the header "
        "or cells: 'load (kN)', '50%%', 'speed mm/s'), optional notes",
    )
    cond.add_argument(
        "--pattern",
        metavar="REGEX",
        help="named groups in the file names: load_n, load_kn, amplitude_percent, "
        "amplitude_fraction, speed_m_s, speed_mm_s",
    )
    cond.add_argument(
        "--load",
        type=_in_si("force"),
        metavar="VALUE",
        help="normal load of all files (670, 0.67kN)",
    )
    cond.add_argument(
        "--amplitude", type=_in_si("amplitude"), metavar="VALUE", help="amplitude (0.5 or 50%%)"
    )
    cond.add_argument(
        "--speed", type=_in_si("speed"), metavar="VALUE", help="pull speed (0.025 or 25mm/s)"
    )
    for name, what in (("load", "N, kN"), ("amplitude", "fraction, %%"), ("speed", "m/s, mm/s")):
        cond.add_argument(
            f"--{name}-unit", metavar="UNIT", help=f"unit of {name} values that name none ({what})"
        )
    csv = p.add_argument_group("reading CSV (sniffed unless given)")
    csv.add_argument("--sep", metavar="SEP", help="separator: ',' ';' tab '|' or whitespace")
    csv.add_argument("--decimal", choices=(".", ","), metavar="MARK", help="decimal mark")
    csv.add_argument(
        "--skip-rows",
        type=int,
        default=0,
        metavar="N",
        help="metadata lines above the header (# comment lines are skipped)",
    )
    csv.add_argument(
        "--encoding", metavar="NAME", help="text encoding (default UTF-8, with or without BOM)"
    )
    p.add_argument(
        "--format",
        choices=("parquet", "csv"),
        default="parquet",
        help="format of the written traces (default parquet)",
    )
    p.set_defaults(func=_run)
