"""The ``idtool`` command line: one module per sub-command, each a thin layer over the
public Python API (:mod:`idtool`)."""

from idtool._cli._main import build_parser, console, main

__all__ = ["build_parser", "console", "main"]
