"""Selecting a dataset's traces by id (``--traces``, :func:`idtool.fit`'s ``traces``,
:meth:`idtool.Fit.validate`): a data operation, done on the :class:`Dataset` before any
model sees it."""

from __future__ import annotations

import dataclasses
import fnmatch
from collections.abc import Sequence

from idtool._data._dataset import Dataset
from idtool._errors import IdtoolError

__all__ = ["first_traces", "select_traces"]


def select_traces(dataset: Dataset, patterns: str | Sequence[str]) -> Dataset:
    """The traces of ``dataset`` whose ids match any of ``patterns`` (shell globs,
    comma-separated in a string; a pattern starting with ``!`` excludes). Raises
    IdtoolError naming a pattern that matches nothing, or when none is left."""
    if isinstance(patterns, str):
        patterns = [p.strip() for p in patterns.split(",") if p.strip()]
    include = [p for p in patterns if not p.startswith("!")]
    exclude = [p[1:] for p in patterns if p.startswith("!")]
    ids = [t.id for t in dataset.traces]
    for p in include + exclude:
        if not fnmatch.filter(ids, p):
            raise IdtoolError(
                f"--traces {p!r} matches no trace of {dataset.name}; its ids are "
                + ", ".join(ids[:8])
                + (" ..." if len(ids) > 8 else "")
            )
    kept = tuple(
        t
        for t in dataset.traces
        if (not include or any(fnmatch.fnmatchcase(t.id, p) for p in include))
        and not any(fnmatch.fnmatchcase(t.id, p) for p in exclude)
    )
    if not kept:
        raise IdtoolError(f"--traces {','.join(patterns)!r} leaves no trace of {dataset.name}")
    return dataclasses.replace(dataset, traces=kept)


def first_traces(dataset: Dataset, n: int) -> Dataset:
    """``dataset`` with its first ``n`` traces only (in the dataset's order). Raises
    ValueError unless 1 <= ``n`` <= the number of traces."""
    if not 1 <= n <= len(dataset.traces):
        raise ValueError(f"n = {n}: {dataset.name} has {len(dataset.traces)} traces")
    return dataclasses.replace(dataset, traces=tuple(dataset.traces[:n]))
