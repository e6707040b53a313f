"""``idtool import-levels TABLE --out DIR``: a steady-state friction table (pin-on-disc,
reciprocating tribometer; OFF and ON friction per condition) into a validated dataset
of kind ``levels``. A thin layer over :func:`idtool.import_levels`."""

from __future__ import annotations

import argparse
import json
import textwrap
from typing import Any

__all__ = ["register"]

_EXAMPLE = """\
Example: a table with units in its headers, one row per measurement,

  load (N),amplitude (um),frequency (kHz),speed (mm/s),off (N),on (N),off se (N),on se (N),repeat
  10,5,22,20.3,3.0,1.14,0.03,0.03,1

  idtool import-levels table.csv --out datasets/pin-on-disc --material "steel on steel" \\
      --source "Dong & Dapino, pin-on-disc at 22 kHz"
  idtool fit datasets/pin-on-disc --out fits/pin-on-disc"""


def _run(args: argparse.Namespace) -> int:
    import idtool  # local: the readers load only when this command runs

    max_amplitude_m = args.max_amplitude_m
    if args.max_amplitude_um is not None:
        max_amplitude_m = args.max_amplitude_um * 1e-6
    table = idtool.import_levels(
        args.table,
        args.out,
        name=args.name,
        material=args.material,
        source=args.source or "",
        description=args.description or "",
        friction=args.friction,
        max_amplitude_m=max_amplitude_m,
        frequency_hz=args.frequency_hz,
        force=args.force,
    )
    if args.json:
        print(json.dumps(table.to_document(), indent=1))
        return 0
    print(f"imported {levels_summary(table)}")
    print("valid: no errors")
    return 0


def levels_summary(table: Any) -> str:
    """What ``import-levels`` and ``validate`` print about a :class:`idtool.LevelsTable`."""
    _, first = table.operating_points
    timed = table.has_times
    lines = [
        f"{table.n_rows} row(s), {first.size} condition(s) as dataset '{table.name}' "
        f"({table.material}); friction as {table.friction}",
        f"folder  {table.path}",
        f"sha256  {table.sha256}",
        "  load [N]  amplitude [um]  frequency [Hz]  speed [mm/s]    OFF      ON     FR"
        + ("  time [min]" if timed else ""),
    ]
    for i in range(table.n_rows):
        lines.append(
            f"  {table.normal_load_n[i]:8.4g}  {table.amplitude_m[i] * 1e6:14.4g}  "
            f"{table.vibration_frequency_hz[i]:14.6g}  {table.sliding_speed_m_s[i] * 1e3:12.4g}"
            f"  {table.off[i]:6.4g}  {table.on[i]:6.4g}  {table.friction_ratio[i]:.3f}"
            + (f"  {table.time_s[i] / 60.0:10.4g}" if timed else "")
        )
    if timed:
        hours = float(table.time_s.max() - table.time_s.min()) / 3600.0
        lines.append(f"measured over {hours:.3g} h: the fit fits the horn's drift over them")
    return "\n".join(lines)


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "import-levels",
        help="turn a table of steady OFF/ON friction per condition into a dataset",
        formatter_class=argparse.RawDescriptionHelpFormatter,  # the example as written
        description=textwrap.fill(
            "Turn a steady-state friction table (a tribometer's mean friction OFF and ON at "
            "each condition, with repeats) into a validated dataset of kind 'levels' "
            "(datasets_schema/levels_table.schema.json) that 'idtool fit' fits. Headers "
            "name the columns and their units: load, amplitude (%, fraction, m, mm, um, "
            "nm), frequency (Hz, kHz), speed (m/s, mm/s), off and on (a force unit, or none "
            "for a coefficient), optional off se, on se (standard errors), repeat, and "
            "time (s, min, h: when each row was measured, in every row; the fit then "
            "fits a drift of the horn over the campaign); "
            "values are converted to SI. Written to a temporary folder, validated, then "
            "renamed into place; on any problem nothing is written and every problem is "
            "listed with its file, row and column.",
            88,
        )
        + f"\n\n{_EXAMPLE}",
    )
    p.add_argument("table", help="the table (.csv, .txt, .parquet)")
    p.add_argument("--out", required=True, metavar="DIR", help="dataset folder to create")
    p.add_argument("--force", action="store_true", help="replace DIR if it exists")
    p.add_argument("--json", action="store_true", help="print dataset.json instead")
    p.add_argument("--name", metavar="NAME", help="dataset name (default: the folder name)")
    p.add_argument("--material", required=True, metavar="TEXT", help="the surfaces in contact")
    p.add_argument("--source", metavar="TEXT", help="citation: where the numbers come from")
    p.add_argument("--description", metavar="TEXT", help="free text")
    p.add_argument(
        "--friction",
        choices=("force", "coefficient"),
        help="what OFF and ON are, when their headers carry no unit (a force unit says force)",
    )
    amp = p.add_mutually_exclusive_group()
    amp.add_argument(
        "--max-amplitude-um",
        type=float,
        metavar="UM",
        help="the rig's amplitude at 100%% [µm]: needed when amplitudes are fractions or %%",
    )
    amp.add_argument("--max-amplitude-m", type=float, metavar="M", help="the same in metres")
    p.add_argument(
        "--frequency-hz",
        type=float,
        metavar="HZ",
        help="vibration frequency [Hz] of every row, for a table without a frequency column",
    )
    p.set_defaults(func=_run)
