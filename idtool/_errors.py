"""User-facing errors: the CLI prints them without a traceback and exits with status 2."""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence

__all__ = ["IdtoolError", "Problem"]


@dataclasses.dataclass(frozen=True)
class Problem:
    """One located problem in user input.

    Attributes:
        message: what is wrong and what to do about it.
        file: the file it is in (as the user named it), if any.
        row: 1-based data row (the header is row 0), if any.
        column: column or JSON field, if any.
        severity: ``"error"`` stops the command; ``"warning"`` is reported only.
    """

    message: str
    file: str | None = None
    row: int | None = None
    column: str | None = None
    severity: str = "error"

    def __str__(self) -> str:
        where = self.file or ""
        if self.row is not None:
            where += f", row {self.row}"
        if self.column is not None:
            where += f", column '{self.column}'"
        prefix = f"{where}: " if where else ""
        return f"{self.severity}: {prefix}{self.message}"


class IdtoolError(Exception):
    """Bad input or a refused action; carries every problem found, not just the first."""

    def __init__(self, message: str, problems: Sequence[Problem] = ()):
        super().__init__(message)
        self.message = message
        self.problems = tuple(problems)

    def __str__(self) -> str:
        lines = [self.message, *(f"  {p}" for p in self.problems)]
        return "\n".join(lines)
