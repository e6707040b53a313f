"""Strict JSON reading: syntax errors, NaN/Infinity and duplicate keys become located problems."""

from __future__ import annotations

import json
import math
import re
from typing import Any

from idtool._errors import Problem

__all__ = ["parse_json"]


class _Rejected(ValueError):
    """Raised inside the decoder hooks; turned into a problem by :func:`parse_json`.

    ``pattern`` finds the offending text, to tell the user on which line it is.
    """

    def __init__(self, message: str, pattern: str):
        super().__init__(message)
        self.pattern = pattern


def _line_of(text: str, pattern: str, nth: int = 1) -> str:
    """``line L: `` for the ``nth`` match of ``pattern`` in ``text``, if found."""
    matches = list(re.finditer(pattern, text))
    if len(matches) < nth:
        return ""
    return f"line {text.count(chr(10), 0, matches[nth - 1].start()) + 1}: "


def _no_constants(name: str) -> float:
    raise _Rejected(
        f"{name} is not valid JSON: write a finite number (or leave the field out)",
        rf"\b{name}\b",
    )


def _finite_float(text: str) -> float:
    value = float(text)
    if not math.isfinite(value):
        raise _Rejected(
            f"number {text} is too large for a double: check its exponent", re.escape(text)
        )
    return value


def _bounded_int(text: str) -> int:
    if len(text.lstrip("-")) > 300:  # beyond any double, and slow to convert
        raise _Rejected(f"integer with {len(text)} digits is too large: check it", re.escape(text))
    return int(text)


def _no_duplicates(pairs: list[tuple[str, Any]]) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for key, value in pairs:
        if key in out:
            raise _Rejected(
                f"field '{key}' appears twice in one object: keep one",
                re.escape(json.dumps(key)) + r"\s*:",
            )
        out[key] = value
    return out


def parse_json(data: bytes, file: str) -> tuple[Any, list[Problem]]:
    """Parse UTF-8 JSON ``data`` read from ``file``: ``(value, [])``, or ``(None, problems)``.

    Test the problems, not the value, for success: ``null`` is valid JSON.
    """
    try:
        text = data.decode("utf-8-sig")
    except UnicodeDecodeError as err:
        return None, [
            Problem(f"not UTF-8 text (byte {err.start}): save the file as UTF-8", file=file)
        ]
    if not text.strip():
        return None, [Problem("the file is empty: it must hold a JSON object", file=file)]
    try:
        value = json.loads(
            text,
            parse_constant=_no_constants,
            parse_float=_finite_float,
            parse_int=_bounded_int,
            object_pairs_hook=_no_duplicates,
        )
    except json.JSONDecodeError as err:
        where = f"line {err.lineno}, column {err.colno}"
        return None, [Problem(f"invalid JSON at {where}: {err.msg}; fix the syntax", file=file)]
    except _Rejected as err:
        # A repeated key is found at its second occurrence (a good guess, not a proof).
        nth = 2 if "appears twice" in str(err) else 1
        where = _line_of(text, err.pattern, nth)
        return None, [Problem(f"{where}{err}", file=file)]
    except RecursionError:
        return None, [Problem("JSON nested too deeply: flatten it", file=file)]
    return value, []
