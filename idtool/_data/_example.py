"""The example dataset shipped with idtool (simulated; see ``idtool/data/README.md``)."""

from __future__ import annotations

from pathlib import Path

__all__ = ["EXAMPLE_SEED", "example_dataset_path", "example_params_path"]

EXAMPLE_SEED = 2010  # the paper's year; regenerating with it reproduces the files
_DATA = Path(__file__).resolve().parent.parent / "data"


def example_dataset_path() -> Path:
    """Folder of the example dataset (format v1, with ``true_parameters.json``)."""
    return _DATA / "example"


def example_params_path() -> Path:
    """The simulator parameter file the example dataset was made from."""
    return _DATA / "example_params.json"
