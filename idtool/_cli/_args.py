"""Argument types shared by the commands."""

from __future__ import annotations

import argparse
import math

__all__ = ["number_list"]


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
