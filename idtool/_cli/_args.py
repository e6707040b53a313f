"""Argument types shared by the commands."""

from __future__ import annotations

import argparse
import functools
import math
from collections.abc import Callable, Iterable, Iterator

__all__ = [
    "LazyChoices",
    "add_law_argument",
    "load_numerics",
    "number_list",
    "registry_names",
]


# Set by the console script (idtool._cli._main.console): this process runs one command.
freeze_on_load = False


def load_numerics() -> None:
    """Import the numerical core (JAX, equinox, optimistix, idtool's models, fit and
    figures), for a command that fits or samples; in the console script's process,
    also exempt what exists then from the cyclic garbage collector (``gc.freeze``).

    Such a command allocates millions of objects, and each full collection also
    scanned the ~360 000 that the imports left (modules, functions, classes: alive
    until the process ends anyway): 0.55 s of collections in a warm ``idtool fit``,
    0.2 s with them frozen. Only there, and once: frozen objects that later become
    cyclic garbage are never collected, which a process of one command can afford and
    a Python session calling :func:`~idtool._cli._main.main` (tests, notebooks) cannot.
    There the collector is also off during the imports, which leave next to no cyclic
    garbage: their two full collections and dozens of young ones took 0.2-0.3 s of a
    warm ``idtool fit`` (2 cores, load 7)."""
    global freeze_on_load
    import gc

    freezing = freeze_on_load and gc.isenabled()
    if freezing:
        gc.disable()
    try:
        import idtool._entry
        import idtool._workflow  # noqa: F401
    finally:
        if freezing:
            gc.enable()
    if freeze_on_load:
        freeze_on_load = False
        gc.freeze()


class LazyChoices:
    """An argparse ``choices`` whose names are read only when argparse needs them (to
    check a given value, or to print this command's help). The registries' names come
    with the modules that define the laws, which import JAX (about a second): building
    every command's parser eagerly made ``idtool --help``, ``validate`` and ``import``
    pay it too."""

    def __init__(self, names: Callable[[], Iterable[str]]):
        self._names = names

    @functools.cached_property
    def _values(self) -> tuple[str, ...]:
        return tuple(self._names())

    def __contains__(self, value: object) -> bool:
        return value in self._values

    def __iter__(self) -> Iterator[str]:
        return iter(self._values)

    def __len__(self) -> int:
        return len(self._values)


def registry_names(registry: str, *extra: str, fittable: bool = False) -> LazyChoices:
    """The names registered in ``idtool.<registry>`` (``"COUPLINGS"``, ``"ACTUATORS"``,
    ...) then ``extra`` (e.g. ``"auto"``), read when first needed; ``fittable``: only the
    friction laws with parameters to fit (not Coulomb's)."""

    def names() -> tuple[str, ...]:
        import idtool  # the registries import JAX: read when argparse needs them

        found = getattr(idtool, registry)
        kept = [n for n in found.names() if not fittable or found.get(n).fit_params]
        return (*kept, *extra)

    return LazyChoices(names)


def add_law_argument(parser: argparse.ArgumentParser) -> None:
    """``--law``: the friction law to fit (those with parameters), default Dahl."""
    parser.add_argument(
        "--law",
        choices=registry_names("FRICTION_LAWS", fittable=True),
        metavar="LAW",
        default="dahl",
        help="friction law: %(choices)s (default dahl)",
    )


def number_list(text: str) -> list[float]:
    """``"450,670"`` -> ``[450.0, 670.0]`` (an argparse ``type``: a bad entry is a usage
    error naming it)."""
    out = []
    for part in text.split(","):
        try:
            value = float(part)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{part!r} is not a number") from None
        if not math.isfinite(value):
            raise argparse.ArgumentTypeError(f"{part!r} is not a finite number")
        out.append(value)
    return out
