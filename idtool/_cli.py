"""The ``idtool`` command line: a thin layer over the Python API.

Each sub-command lives in its own ``_cmd_*.py`` module exposing ``register(sub)``, which
adds its parser and sets ``func(args) -> int``. Bad input raises :class:`IdtoolError`,
printed here without a traceback, with exit status 2.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence

from . import __version__
from ._errors import IdtoolError

_COMMANDS = ("_cmd_curve",)


def build_parser() -> argparse.ArgumentParser:
    """The argument parser with every sub-command registered."""
    import importlib

    parser = argparse.ArgumentParser(
        prog="idtool",
        description="Identify friction-model parameters of ultrasonically lubricated "
        "contacts from bench load-cell traces.",
    )
    parser.add_argument("--version", action="version", version=f"idtool {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    for name in _COMMANDS:
        importlib.import_module(f"idtool.{name}").register(sub)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``idtool`` console script; returns the exit status."""
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return int(args.func(args) or 0)
    except IdtoolError as err:
        print(f"idtool {args.command}: {err}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"idtool {args.command}: interrupted; nothing was written", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
