"""Units of DAQ exports: read them from column headers and cells, convert values to SI.

A header names its column and, optionally, its unit: ``Time (s)``, ``Time [ms]``,
``Load (kN)``, ``speed mm/s``, ``t/s`` or the format's own ``time_s``, ``speed_mm_s``,
``amplitude_percent``. Units are looked up case-insensitively in one table per quantity,
each unit with its factor to the SI unit of the dataset format (s, N, V, m/s, fraction, m).
"""

from __future__ import annotations

import dataclasses
import math
import re

import numpy as np

from idtool._errors import Problem

__all__ = [
    "QUANTITIES",
    "Header",
    "canonical_unit",
    "column_unit",
    "parse_header",
    "scalar_to_si",
    "si_decimals",
    "split_value",
    "to_si",
    "value_in_si",
]

# quantity -> {unit: factor to the quantity's SI unit}; the first unit is the SI one.
QUANTITIES: dict[str, dict[str, float]] = {
    "time": {"s": 1.0, "ms": 1e-3, "us": 1e-6, "min": 60.0},
    "force": {"N": 1.0, "kN": 1e3, "daN": 10.0, "mN": 1e-3, "lbf": 4.4482216152605},
    "voltage": {"V": 1.0, "mV": 1e-3},
    "amplitude": {"fraction": 1.0, "%": 0.01},
    "speed": {"m/s": 1.0, "mm/s": 1e-3, "cm/s": 1e-2, "m/min": 1.0 / 60.0},
    "displacement": {"m": 1.0, "mm": 1e-3, "um": 1e-6, "nm": 1e-9},
}

# Spellings of the units above (lower case, micro sign as u) -> the unit.
_ALIASES = {
    **{a: "s" for a in ("s", "sec", "secs", "second", "seconds")},
    **{a: "ms" for a in ("ms", "msec", "millisecond", "milliseconds")},
    **{a: "us" for a in ("us", "usec", "microsecond", "microseconds")},
    "min": "min",
    **{a: "N" for a in ("n", "newton", "newtons")},
    "kn": "kN",
    "dan": "daN",
    "mn": "mN",
    "lbf": "lbf",
    **{a: "V" for a in ("v", "volt", "volts")},
    "mv": "mV",
    **{a: "fraction" for a in ("fraction", "frac", "-")},
    **{a: "%" for a in ("%", "percent", "pct")},
    **{a: "m/s" for a in ("m/s", "m_s", "mps")},
    **{a: "mm/s" for a in ("mm/s", "mm_s")},
    **{a: "cm/s" for a in ("cm/s", "cm_s")},
    **{a: "m/min" for a in ("m/min", "m_min")},
    **{a: "m" for a in ("m", "metre", "metres", "meter", "meters")},
    "mm": "mm",
    **{a: "um" for a in ("um", "micron", "microns", "micrometre", "micrometer")},
    "nm": "nm",
}

_BRACKETS = re.compile(r"(.*?)\s*[(\[{]\s*([^)\]}]*?)\s*[)\]}]")
# A number with a point or a comma as decimal mark, then an optional unit (cells like
# "50%", "25 mm/s", "0,67 kN").
_VALUE = re.compile(r"\s*([+-]?(?:\d+[.,]?\d*|[.,]\d+)(?:[eE][+-]?\d+)?)\s*(.*?)\s*")


def canonical_unit(text: str) -> str | None:
    """The unit ``text`` spells (``"KN"`` -> ``"kN"``, ``"µs"`` -> ``"us"``), if known."""
    key = " ".join(text.split()).lower().replace("µ", "u").replace("μ", "u")
    return _ALIASES.get(key)


@dataclasses.dataclass(frozen=True)
class Header:
    """A column header split into its name and unit.

    Attributes:
        text: the header as written.
        name: the header without its unit part (the whole header if it has none).
        unit_text: what the header gives as unit, if anything (brackets may hold a
            label that is no unit, e.g. ``Load (cell 2)``).
        unit: the known unit ``unit_text`` spells, else None.
    """

    text: str
    name: str
    unit_text: str | None = None
    unit: str | None = None


def parse_header(text: str) -> Header:
    """Split ``text``: ``"Time (s)"``, ``"Time [ms]"``, ``"speed mm/s"``, ``"t/s"``,
    ``"time_s"``, ``"speed_mm_s"`` give the name and the unit; anything else is a name."""
    flat = " ".join(text.split())
    match = _BRACKETS.fullmatch(flat)
    if match and match.group(1):
        return Header(text, match.group(1), match.group(2), canonical_unit(match.group(2)))
    # Unbracketed units only when they are known, so "Channel_A" stays a name.
    name, _, last = flat.rpartition(" ")
    if name and canonical_unit(last):
        return Header(text, name, last, canonical_unit(last))
    name, _, rest = flat.partition("/")
    if name and rest and canonical_unit(rest):
        return Header(text, name, rest, canonical_unit(rest))
    parts = flat.split("_")
    for k in (2, 1):  # "speed_mm_s" before "speed_mm_s" read as "speed_mm" in s
        suffix = "_".join(parts[-k:])
        if len(parts) > k and canonical_unit(suffix):
            return Header(text, "_".join(parts[:-k]), suffix, canonical_unit(suffix))
    return Header(text, flat)


def _choices(quantity: str) -> str:
    return ", ".join(QUANTITIES[quantity])


def column_unit(
    header: Header, option: str | None, quantity: str, option_name: str, file: str
) -> tuple[str | None, str, list[Problem]]:
    """The unit of a column: from its header, else from ``option``, else the SI one.

    Returns the unit (None on error), how it was found, and the problems: an unknown
    unit, a unit of another quantity, or a header and an option that disagree.
    """
    column = header.text
    choices = _choices(quantity)

    def error(message: str, located: bool = True) -> tuple[None, str, list[Problem]]:
        problem = Problem(message, file=file, row=0, column=column) if located else Problem(message)
        return None, "", [problem]

    wanted = None
    if option is not None:
        wanted = canonical_unit(option)
        if wanted not in QUANTITIES[quantity]:
            return error(f"{option_name} {option!r} is not a {quantity} unit: use {choices}", False)
    if header.unit is not None:
        if header.unit not in QUANTITIES[quantity]:
            return error(
                f"the header gives the unit '{header.unit_text}', which is not a {quantity} "
                f"unit ({choices}): is this the {quantity} column?"
            )
        if wanted is not None and wanted != header.unit:
            return error(
                f"the header says '{header.unit_text}' but {option_name} says {option!r}: "
                f"drop {option_name} or fix the header"
            )
        return header.unit, "from the header", []
    if wanted is not None:
        return wanted, f"from {option_name}", []
    if header.unit_text is not None:
        return error(
            f"'{header.unit_text}' in the header is not a unit idtool knows: give "
            f"{option_name} ({choices})"
        )
    si = next(iter(QUANTITIES[quantity]))
    return si, "assumed: no unit in the header", []


def split_value(text: str) -> tuple[float, str, int | None] | None:
    """``"25 mm/s"`` -> ``(25.0, "mm/s", 0)``, ``"0,5"`` -> ``(0.5, "", 1)``: the number,
    its unit and its digits after the decimal mark (None with an exponent); None if
    ``text`` is no number."""
    match = _VALUE.fullmatch(text)
    if not match or ("," in match.group(1) and "." in match.group(1)):
        return None
    number = match.group(1).replace(",", ".")
    mantissa, exponent, _ = number.lower().partition("e")
    decimals = None if exponent else len(mantissa.partition(".")[2])
    return float(number), match.group(2), decimals


def scalar_to_si(value: float, factor: float, decimals: int | None) -> float:
    """One value as :func:`to_si` converts columns (``70 %`` is exactly 0.7)."""
    return float(to_si(np.array([value]), factor, decimals)[0])


def value_in_si(text: str, quantity: str, default_unit: str | None = None) -> float:
    """A number with an optional unit (``"25mm/s"``, ``"50%"``, ``"0.67 kN"``) in SI.

    Without a unit, ``default_unit`` (else the SI unit) applies.

    Raises:
        ValueError: not a number, or a unit that is not one of ``quantity``'s.
    """
    parts = split_value(text)
    if parts is None:
        raise ValueError(f"{text!r} is not a number (with an optional unit)")
    value, unit_text, decimals = parts
    unit = canonical_unit(unit_text) if unit_text else default_unit
    unit = unit or next(iter(QUANTITIES[quantity]))
    if unit not in QUANTITIES[quantity]:
        raise ValueError(f"{text!r}: '{unit_text}' is not a {quantity} unit ({_choices(quantity)})")
    if not math.isfinite(value):
        raise ValueError(f"{text!r} is not a finite number")
    return scalar_to_si(value, QUANTITIES[quantity][unit], decimals)


def to_si(values: np.ndarray, factor: float, decimals: int | None) -> np.ndarray:
    """``values * factor``, rounded back to the written precision when the factor is a
    power of ten (``decimals``: digits after the decimal mark in the file), so 1.81 kN
    becomes exactly 1810.0 N and 3770 ms exactly 3.77 s."""
    inverse = 1.0 / factor
    # dividing by 1000 is correctly rounded; multiplying by 0.001 is not
    exact = factor < 1.0 and inverse == round(inverse)
    out = values / round(inverse) if exact else values * factor
    places = si_decimals(factor, decimals)
    if places is not None:
        out = np.round(out, places)
    return np.asarray(out, dtype=np.float64)


def si_decimals(factor: float, decimals: int | None) -> int | None:
    """Digits after the decimal point of values written with ``decimals`` digits once
    multiplied by ``factor``; None unless that is exact (a power of ten) and sensible."""
    shift = math.log10(factor)
    if decimals is None or shift != round(shift):
        return None
    places = decimals - round(shift)
    return places if 0 <= places <= 15 else None
