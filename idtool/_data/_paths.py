"""Find and read a dataset's files without ever leaving the dataset folder.

A trace's ``file`` is a relative path with forward slashes. Absolute paths, ``..``
segments and symbolic links that resolve outside the folder are refused, so a dataset
cannot make idtool read (and hash, and report on) files elsewhere on the machine.
"""

from __future__ import annotations

import re
from pathlib import Path, PurePosixPath

from idtool._data._schema import closest_name
from idtool._data._table_read import TABLE_SUFFIXES
from idtool._errors import IdtoolError, Problem

__all__ = ["dataset_json_path", "path_problem", "read_trace_file"]

DATASET_FILE = "dataset.json"
_DRIVE = re.compile(r"^[A-Za-z]:")


def dataset_json_path(path: str | Path) -> Path:
    """``path`` is a dataset folder or its ``dataset.json``; the ``dataset.json`` path.

    Raises:
        IdtoolError: when there is no such folder or no dataset.json in it.
    """
    path = Path(path)
    try:
        is_dir, is_file, exists = path.is_dir(), path.is_file(), path.exists()
        has_json = is_dir and (path / DATASET_FILE).is_file()
    except (OSError, ValueError) as err:  # e.g. a name too long, or with a NUL character
        raise IdtoolError(f"{path!s:.200}: not a usable path ({err})") from None
    if has_json:
        return path / DATASET_FILE
    if is_dir:
        raise IdtoolError(
            f"{path} has no {DATASET_FILE}: give the folder that holds it "
            "(see datasets_schema/README.md for the format)"
        )
    if path.name == DATASET_FILE and is_file:
        return path
    if not exists:
        raise IdtoolError(f"{path} does not exist: give a dataset folder")
    raise IdtoolError(f"{path} is not a dataset folder: give the folder holding {DATASET_FILE}")


def path_problem(rel: str) -> str | None:
    """Why the path text ``rel`` is refused before touching the file system, if it is."""
    if "\x00" in rel:
        return "the path contains a NUL character: remove it"
    if "\\" in rel:
        return "use forward slashes (/) in the path, not backslashes"
    if PurePosixPath(rel).is_absolute() or _DRIVE.match(rel):
        return "absolute paths are not allowed: give the path relative to the dataset folder"
    if ".." in PurePosixPath(rel).parts:
        return "'..' leads outside the dataset folder: move the file into the folder"
    if not rel.lower().endswith(TABLE_SUFFIXES):
        suffix = PurePosixPath(rel).suffix or "(none)"
        return f"unknown file type {suffix}: save the trace as .csv or .parquet"
    return None


def _not_found(root: Path, rel: str) -> str:
    parent = (root / rel).parent
    siblings = (
        [str((p.relative_to(root)).as_posix()) for p in parent.iterdir()] if parent.is_dir() else []
    )
    guess = closest_name(rel, siblings)
    hint = f"; did you mean '{guess}'?" if guess else "; check the name and the folder"
    return f"file '{rel}' not found in {root}{hint}"


def read_trace_file(root: Path, rel: str, where: str) -> tuple[bytes | None, list[Problem]]:
    """Bytes of the trace file ``rel`` inside the folder ``root``.

    Problems are located at the ``file`` field ``where`` (e.g. ``traces[2].file``) of
    dataset.json, since that is what has to change.
    """

    def problem(message: str) -> tuple[None, list[Problem]]:
        return None, [Problem(message, file=DATASET_FILE, column=where)]

    refused = path_problem(rel)
    if refused is not None:
        return problem(f"'{rel}': {refused}")
    candidate = root / rel
    try:
        if not candidate.exists() and not candidate.is_symlink():
            return problem(_not_found(root, rel))
        real_root = root.resolve()
        real = candidate.resolve()
        if not real.is_relative_to(real_root):
            return problem(
                f"'{rel}' is a symbolic link leading outside the dataset folder (to {real}): "
                "copy the file into the folder"
            )
        if not real.exists():
            return problem(f"'{rel}' is a broken symbolic link: replace it by the file")
        if real.is_dir():
            return problem(f"'{rel}' is a folder, not a file: name the trace file inside it")
        return real.read_bytes(), []
    except RuntimeError:  # Python 3.11 signals a symbolic link loop this way
        return problem(f"'{rel}' is a symbolic link loop: replace it by the file")
    except OSError as err:
        return problem(f"cannot read '{rel}' ({err.strerror or err}): check its permissions")
