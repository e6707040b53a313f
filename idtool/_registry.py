"""Registries of the model's interchangeable parts: friction laws, coupling laws, noise
models.

Each part is a class registered under a name by a decorator in the module that defines
it (``@COUPLINGS.register("constant")``). The command line's choices, the names written
to ``fit.json`` and the report's labels all come from here, so a new part is one module
plus its registration, with no string dispatch anywhere else.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from typing import Generic, TypeVar

from idtool._errors import IdtoolError

__all__ = ["Registry"]

T = TypeVar("T")


class Registry(Generic[T]):
    """Named classes of one kind (``kind`` names it in messages, e.g. "coupling law")."""

    def __init__(self, kind: str):
        self.kind = kind
        self._entries: dict[str, T] = {}

    def register(self, name: str) -> Callable[[T], T]:
        """Class decorator: register the class under ``name`` (and set its ``name``)."""

        def add(cls: T) -> T:
            if name in self._entries and self._entries[name] is not cls:
                raise ValueError(f"{self.kind} {name!r} is registered already")
            cls.name = name  # type: ignore[attr-defined]
            self._entries[name] = cls
            return cls

        return add

    def get(self, name: str | T) -> T:
        """The class registered as ``name`` (a class passes through unchanged)."""
        if not isinstance(name, str):
            return name
        try:
            return self._entries[name]
        except KeyError:
            raise IdtoolError(
                f"unknown {self.kind} {name!r}: choose one of {', '.join(self._entries)}"
            ) from None

    def names(self) -> tuple[str, ...]:
        return tuple(self._entries)

    def __contains__(self, name: object) -> bool:
        return name in self._entries

    def __iter__(self) -> Iterator[str]:
        return iter(self._entries)

    def __repr__(self) -> str:
        return f"Registry({self.kind!r}: {', '.join(self._entries)})"
