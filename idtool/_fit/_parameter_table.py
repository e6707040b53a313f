"""The user's parameter table (PEtab-like) and ``--fix NAME=VALUE``.

A parameter table is a TSV or CSV file (tab, comma or semicolon; ``#`` starts a
comment line), one row per shared parameter the user wants to set, with PEtab's column
names (Schmiester et al. 2021, "PEtab -- Interoperable specification of parameter
estimation problems in systems biology", PLoS Comput Biol 17: e1008646)::

    parameterId    estimate  nominalValue  lowerBound  upperBound  parameterScale
    mu             0         0.31
    Kt             1                       1e6         1e10        log

with a prior for the sampler (two more columns)::

    parameterId    objectivePriorType  objectivePriorParameters
    coupling_gain  logNormal           -3.9;0.5

Columns (only ``parameterId`` is required; an empty cell keeps idtool's default):

* ``parameterId``: ``Kt``, ``mu``, ``coupling_gain``, ``power_load_n``, ``slope_n_s``,
  ... (``idtool parameters`` lists a model's, with their defaults);
* ``estimate``: 1 (default) or 0, which fixes the parameter at ``nominalValue``;
* ``nominalValue``: the fixed value, or the start of an estimated parameter (every
  multi-start point then begins it there);
* ``lowerBound``, ``upperBound``: its range, SI units (``unit``, optional, is checked
  against idtool's unit of the parameter: a table in mm is refused, not misread);
* ``parameterScale``: ``lin`` or ``log`` (``log10`` is the same transform here);
* ``objectivePriorType`` and ``objectivePriorParameters`` (two numbers, ``;``-separated):
  the sampler's prior, on the physical scale: ``uniform`` (lo; hi), ``normal`` (mean; sd),
  ``logNormal`` (PEtab's: mean; sd of the natural log), ``parameterScaleUniform`` (lo;
  hi: log-uniform on a log scale), and idtool's ``logUniform`` (lo; hi) and ``gamma``
  (shape; rate). PEtab's Laplace priors are refused. Every prior is truncated to the
  bounds.

Differences from PEtab: bounds and values are never on the log scale (PEtab's are not
either); the ``parameterName`` column is ignored; only shared parameters can be set.
"""

from __future__ import annotations

import csv
import io
import math
import os
from collections.abc import Iterable, Mapping
from pathlib import Path

from idtool._errors import IdtoolError, Problem
from idtool._model._actuator import ACTUATORS
from idtool._model._benchmodel import shared_params_of
from idtool._model._coupling import COUPLINGS
from idtool._model._laws import FRICTION_LAWS
from idtool._model._level_model import LEVEL_MODELS
from idtool._model._params import Param
from idtool._model._settings import ParameterSetting

__all__ = [
    "COLUMNS",
    "parameter_template",
    "parameter_units",
    "parse_fix",
    "read_parameter_table",
]

COLUMNS = (
    "parameterId",
    "estimate",
    "nominalValue",
    "lowerBound",
    "upperBound",
    "parameterScale",
    "objectivePriorType",
    "objectivePriorParameters",
)
_OPTIONAL = ("parameterName", "unit")
# PEtab's prior type -> idtool's distribution and how its two numbers map
_PRIORS = {
    "uniform": "uniform",
    "normal": "normal",
    "logNormal": "lognormal",
    "parameterScaleUniform": None,  # uniform on the parameter's scale
    "logUniform": "loguniform",
    "gamma": "gamma",
}
_TRUE, _FALSE = ("1", "true", "yes"), ("0", "false", "no")


def _number(cell: str, problem) -> float | None:
    if cell == "":
        return None
    try:
        x = float(cell)
    except ValueError:
        problem(f"{cell!r} is not a number (SI units, a decimal point: 0.31, 2e8)")
        return None
    if not math.isfinite(x):
        problem(f"{cell!r} is not a finite number")
        return None
    return x


def _prior(kind: str, numbers: str, scale: str | None, problem) -> tuple[str, float, float] | None:
    if kind == "":
        if numbers:
            problem("objectivePriorParameters given without objectivePriorType")
        return None
    if kind not in _PRIORS:
        problem(
            f"prior {kind!r} is not supported; use one of {', '.join(_PRIORS)}",
            "objectivePriorType",
        )
        return None
    parts = [p.strip() for p in numbers.split(";")] if numbers else []
    values = []
    for p in parts:
        try:
            values.append(float(p))
        except ValueError:
            values.append(math.nan)
    if len(values) != 2 or not all(math.isfinite(v) for v in values):
        problem(
            f"{kind} takes two numbers separated by ';' (got {numbers!r})",
            "objectivePriorParameters",
        )
        return None
    a, b = values
    dist = _PRIORS[kind]
    if kind == "logNormal":  # PEtab's parameters are those of the log: median exp(a)
        a = math.exp(a)
    if dist is None:
        dist = "loguniform" if scale in ("log", "log10") else "uniform"
    return dist, a, b


def parameter_units() -> dict[str, str]:
    """The unit of every shared parameter of every registered law and model, by name."""
    units: dict[str, str] = {}
    for law in FRICTION_LAWS.names():
        for coupling in COUPLINGS.names():
            for actuator in ACTUATORS.names():
                for level in LEVEL_MODELS.names():
                    every = shared_params_of(
                        FRICTION_LAWS.get(law),
                        COUPLINGS.get(coupling),
                        ACTUATORS.get(actuator),
                        level=LEVEL_MODELS.get(level),
                    )
                    units |= {p.name: p.unit for p in every}
    return units


def read_parameter_table(
    path: str | os.PathLike, units: Mapping[str, str] | None = None
) -> tuple[ParameterSetting, ...]:
    """The settings of a parameter table (module docstring). ``units``: idtool's unit of
    each parameter, to check a ``unit`` column against (default: the registered laws'
    and models'). Every problem is reported with its row and column, all at once
    (:class:`IdtoolError`)."""
    path = Path(path)
    units = parameter_units() if units is None else units
    try:
        text = path.read_text(encoding="utf-8-sig")
    except (OSError, UnicodeDecodeError) as err:
        raise IdtoolError(f"{path}: cannot read the parameter table ({err})") from None
    lines = [ln for ln in text.splitlines() if ln.strip() and not ln.lstrip().startswith("#")]
    if not lines:
        raise IdtoolError(f"{path}: the parameter table is empty; it needs a header row")
    try:
        dialect = csv.Sniffer().sniff(lines[0], delimiters="\t,;")
        delimiter = dialect.delimiter
    except csv.Error:
        delimiter = "\t"
    rows = list(csv.reader(io.StringIO("\n".join(lines)), delimiter=delimiter))
    header = [h.strip() for h in rows[0]]
    problems: list[Problem] = []
    unknown = [h for h in header if h not in COLUMNS and h not in _OPTIONAL]
    for h in unknown:
        problems.append(
            Problem(
                f"unknown column; the columns are {', '.join(COLUMNS)} (and unit)", str(path), 0, h
            )
        )
    if "parameterId" not in header:
        problems.append(Problem("no parameterId column: the header must name it", str(path), 0))
        raise IdtoolError(f"{path}: not a parameter table", problems)
    out = []
    for r, raw in enumerate(rows[1:], start=1):
        cells = [c.strip() for c in raw]
        if len(cells) != len(header):
            problems.append(
                Problem(f"{len(cells)} cells, the header has {len(header)}", str(path), r)
            )
            continue
        row = dict(zip(header, cells, strict=True))
        before = len(problems)

        def problem(message: str, column: str = "", r=r) -> None:
            problems.append(Problem(message, str(path), r, column or None))

        name = row["parameterId"]
        if not name:
            problem("empty parameterId", "parameterId")
            continue
        flag = row.get("estimate", "").lower()
        if flag not in ("", *_TRUE, *_FALSE):
            problem(f"{row['estimate']!r}: give 1 (estimate) or 0 (fix)", "estimate")
        nominal = _number(row.get("nominalValue", ""), lambda m: problem(m, "nominalValue"))
        lower = _number(row.get("lowerBound", ""), lambda m: problem(m, "lowerBound"))
        upper = _number(row.get("upperBound", ""), lambda m: problem(m, "upperBound"))
        scale = row.get("parameterScale", "") or None
        if scale is not None and scale not in ("lin", "log", "log10"):
            problem(f"{scale!r}: give lin or log", "parameterScale")
        prior = _prior(
            row.get("objectivePriorType", ""),
            row.get("objectivePriorParameters", ""),
            scale,
            problem,
        )
        unit = row.get("unit", "")
        if unit and name in units and unit != units[name]:
            problem(f"{name} is in {units[name]} in idtool (SI); convert the row", "unit")
        if len(problems) > before:
            continue
        try:
            out.append(
                ParameterSetting(
                    name,
                    estimate=flag not in _FALSE,
                    nominal=nominal,
                    lower=lower,
                    upper=upper,
                    scale=scale,
                    prior=prior,
                    source=f"{path}, row {r}",
                )
            )
        except ValueError as err:
            problem(str(err))
    if problems:
        raise IdtoolError(f"{path}: bad parameter table", problems)
    return tuple(out)


def parse_fix(items: Iterable[str]) -> tuple[ParameterSetting, ...]:
    """Settings from ``NAME=VALUE`` texts (``--fix mu=0.3``): each parameter fixed."""
    out = []
    for item in items:
        name, sep, value = item.partition("=")
        try:
            if not sep or not name.strip():
                raise ValueError
            x = float(value)
        except ValueError:
            raise IdtoolError(f"--fix {item}: give NAME=VALUE, e.g. --fix mu=0.3") from None
        if not math.isfinite(x):
            raise IdtoolError(f"--fix {item}: the value must be a finite number")
        out.append(
            ParameterSetting(name.strip(), estimate=False, nominal=x, source=f"--fix {item}")
        )
    return tuple(out)


def parameter_template(params: Iterable[Param]) -> str:
    """A parameter table (TSV) of ``params`` with idtool's defaults, to edit: every row
    estimated, the default bounds and scale; the unit column for the reader."""
    lines = ["\t".join(["parameterId", "unit", *COLUMNS[1:]])]
    for p in params:
        scale = "log" if p.kind == "log" else "lin"
        lines.append("\t".join([p.name, p.unit, "1", "", f"{p.lo:g}", f"{p.hi:g}", scale, "", ""]))
    return "\n".join(lines) + "\n"
