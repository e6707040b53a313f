"""The ``idtool`` command line: a thin layer over the Python API.

Each sub-command lives in its own ``_cmd_*.py`` module exposing ``register(sub)``, which
adds its parser and sets ``func(args) -> int``. Bad input raises :class:`IdtoolError`,
printed here without a traceback, with exit status 2.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import os
import sys
from collections.abc import Sequence

from idtool._cli import _args
from idtool._cli._cache import enable_compilation_cache
from idtool._errors import IdtoolError
from idtool._version import __version__

# Exit statuses (also in every command's --help and the README); 0 is done.
EXIT_BAD_INPUT = 2  # bad input or refused overwrite: nothing written
EXIT_NOT_CONVERGED = 3  # sample: outputs written, but the chain did not converge
EXIT_INTERRUPTED = 130

EXIT_CODES = (
    f"exit status: 0 done; {EXIT_BAD_INPUT} bad input or an output that exists without "
    f"--force (nothing written); {EXIT_NOT_CONVERGED} 'sample' wrote its outputs but the "
    f"chain did not converge (run longer with --resume); {EXIT_INTERRUPTED} interrupted"
)

_COMMANDS = (
    "_curve",
    "_seed_study",
    "_validate",
    "_import",
    "_import_levels",
    "_simulate_bench",
    "_parameters",
    "_fit",
    "_fit_law",
    "_validate_fit",
    "_sample",
    "_predict",
    "_plan",
    "_study",
    "_report",
    "_compare",
    "_demo",
)


def build_parser() -> argparse.ArgumentParser:
    """The argument parser with every sub-command registered."""
    import importlib

    parser = argparse.ArgumentParser(
        prog="idtool",
        description="Identify friction-model parameters of ultrasonically lubricated "
        "contacts from bench load-cell traces.",
    )
    parser.add_argument("--version", action="version", version=f"idtool {__version__}")
    parser.epilog = EXIT_CODES
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    for name in _COMMANDS:
        importlib.import_module(f"idtool._cli.{name}").register(sub)
    for command in sub.choices.values():  # what every command understands alike
        command.add_argument(
            "-q",
            "--quiet",
            action="store_true",
            help="print nothing but errors and what --json asks for; no progress bars "
            "(the exit status says how it went)",
        )
        command.epilog = EXIT_CODES
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``idtool`` console script; returns the exit status."""
    enable_compilation_cache()
    parser = build_parser()
    argv = sys.argv[1:] if argv is None else list(argv)
    args = parser.parse_args(argv)
    args.argv = argv  # recorded in every output's provenance
    try:
        silent = args.quiet and not getattr(args, "json", False)
        with contextlib.redirect_stdout(io.StringIO()) if silent else contextlib.nullcontext():
            return int(args.func(args) or 0)
    except IdtoolError as err:
        print(f"idtool {args.command}: {err}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except KeyboardInterrupt:
        print(f"idtool {args.command}: interrupted; nothing was written", file=sys.stderr)
        return EXIT_INTERRUPTED
    except BrokenPipeError:
        # The reader went away (``idtool ... | head``): not an error of ours. Point
        # stdout at devnull so the interpreter's final flush does not complain.
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 0


def console() -> int:
    """Entry point of the ``idtool`` console script: one command in this interpreter
    (:func:`main`), whose numerical core's imports are then exempt from the garbage
    collector (:func:`idtool._cli._args.load_numerics`)."""
    _args.freeze_on_load = True  # a process of one command
    single_threaded_blas()
    return main(sys.argv[1:])


def single_threaded_blas() -> None:
    """One OpenBLAS thread (NumPy's, and SciPy's, whose LAPACK JAX's CPU kernels call),
    unless ``OPENBLAS_NUM_THREADS`` says otherwise; before NumPy loads, as OpenBLAS
    reads it once.

    The fit's matrices are small (blocks of a few dozen rows), yet OpenBLAS split some
    of them over every core and its idle workers spin between calls: 44% of the CPU
    samples of a warm ``idtool fit`` of the example were in OpenBLAS's thread server
    and wait loops, and user CPU went from 6.5-8.0 s to 4.6-5.0 s with one thread
    (2 cores, load 9). One thread also makes the command's numbers independent of the
    machine's core count (a split reduction rounds differently: fit.json's values
    moved by at most 5e-13 relative). Only the console script: a Python session that
    imported NumPy already keeps its own setting."""
    os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")


if __name__ == "__main__":
    sys.exit(console())
