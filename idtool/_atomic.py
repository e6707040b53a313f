"""All-or-nothing outputs: written to a temporary sibling, renamed into place.

:func:`atomic_file` for one file (every writer of a single output file uses it),
:func:`atomic_output_dir` for a whole output folder.
"""

from __future__ import annotations

import contextlib
import os
import shutil
import tempfile
from collections.abc import Iterator
from pathlib import Path

from idtool._errors import IdtoolError

__all__ = ["atomic_file", "atomic_output_dir", "refuse_existing", "write_text_atomic"]


@contextlib.contextmanager
def atomic_file(path: str | os.PathLike[str], *, sync: bool = False) -> Iterator[Path]:
    """Yield a temporary sibling of ``path`` (``path.partial``) to write; when the block
    succeeds it is renamed over ``path`` (atomic on one file system), else removed, so
    ``path`` is always either the old file or the complete new one. ``sync`` flushes
    the file to disk before the rename (for a checkpoint that must survive a crash)."""
    path = Path(path)
    tmp = path.with_name(path.name + ".partial")
    try:
        yield tmp
        if sync:
            with open(tmp, "rb+") as fh:
                os.fsync(fh.fileno())
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)


def write_text_atomic(path: str | os.PathLike[str], text: str) -> Path:
    """Write ``text`` to ``path`` all or nothing (:func:`atomic_file`)."""
    with atomic_file(path) as tmp:
        tmp.write_text(text)
    return Path(path)


def refuse_existing(out: str | os.PathLike[str], force: bool) -> None:
    """Stop with a clear message if ``out`` exists and ``force`` is off: commands call
    it before their work, so a refusal does not come after minutes of fitting."""
    if Path(out).exists() and not force:
        raise IdtoolError(f"{out} already exists; pass --force to replace it")


@contextlib.contextmanager
def atomic_output_dir(out: str | os.PathLike[str], *, force: bool = False) -> Iterator[Path]:
    """Yield a fresh temporary folder that replaces ``out`` only if the block succeeds.

    The folder is created next to ``out`` (same file system, so the final rename is
    atomic). On any exception, including KeyboardInterrupt, it is removed and ``out`` is
    left as it was. An existing ``out`` is replaced only with ``force=True``.
    """
    out = Path(out)
    refuse_existing(out, force)
    if out.exists() and not out.is_dir():
        raise IdtoolError(f"{out} exists and is not a folder; choose another --out")
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{out.name}.", suffix=".partial", dir=out.parent))
    umask = os.umask(0)
    os.umask(umask)
    tmp.chmod(0o777 & ~umask)  # mkdtemp makes it private; the result should not be
    try:
        yield tmp
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    if out.exists():
        old = Path(tempfile.mkdtemp(prefix=f".{out.name}.", suffix=".old", dir=out.parent))
        os.replace(out, old / out.name)
        os.replace(tmp, out)
        shutil.rmtree(old, ignore_errors=True)
    else:
        os.replace(tmp, out)
