"""What produced an output: command line, versions, time; written beside every result."""

from __future__ import annotations

import datetime
import importlib.metadata
import platform
import shlex
import sys
from collections.abc import Sequence

__all__ = ["provenance"]

_PACKAGES = ("idtool", "jax", "jaxlib", "equinox", "numpy", "scipy", "pandas", "emcee", "arviz")


def _version(name: str) -> str | None:
    try:
        return importlib.metadata.version(name)
    except importlib.metadata.PackageNotFoundError:
        return None


def provenance(argv: Sequence[str] | None = None) -> dict:
    """Command (``idtool`` + ``argv``, default the process's), versions, platform, UTC time."""
    args = sys.argv[1:] if argv is None else list(argv)
    return {
        "command": shlex.join(["idtool", *args]),
        "versions": {name: _version(name) for name in _PACKAGES},
        "python": platform.python_version(),
        "platform": platform.platform(),
        "created_utc": datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds"),
    }
