"""The format's JSON Schema files (``datasets_schema/``) and their errors as located problems.

The schemas are the single source of truth for the field names and ranges: the loader
validates ``dataset.json`` against them and takes the trace table's column names from
them, so the published schema and the code cannot drift apart.
"""

from __future__ import annotations

import difflib
import functools
import importlib.resources
import json
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any

import jsonschema
import referencing
import referencing.jsonschema

from idtool._errors import Problem

__all__ = [
    "DATASET_SCHEMA",
    "FIT_SCHEMA",
    "LEVELS_FIT_SCHEMA",
    "LEVELS_SCHEMA",
    "SAMPLE_SCHEMA",
    "SIMULATOR_PARAMS_SCHEMA",
    "TRACE_TABLE_SCHEMA",
    "VALIDATION_SCHEMA",
    "closest_name",
    "json_path",
    "load_schema",
    "schema_problems",
    "schema_validator",
    "trace_columns",
]

DATASET_SCHEMA = "dataset.schema.json"
TRACE_TABLE_SCHEMA = "trace_table.schema.json"
SIMULATOR_PARAMS_SCHEMA = "simulator_params.schema.json"
FIT_SCHEMA = "fit.schema.json"  # fit.json (idtool._fit._folder.FIT_JSON)
SAMPLE_SCHEMA = "sample.schema.json"  # sample.json (idtool._fit._folder.SAMPLE_JSON)
VALIDATION_SCHEMA = "validation.schema.json"  # validation.json (_folder.VALIDATION_JSON)
LEVELS_SCHEMA = "levels_table.schema.json"  # dataset.json of kind "levels" (._levels)
LEVELS_FIT_SCHEMA = "levels_fit.schema.json"  # fit.json of a levels fit (idtool._levels)
_ALL = (
    DATASET_SCHEMA,
    TRACE_TABLE_SCHEMA,
    SIMULATOR_PARAMS_SCHEMA,
    FIT_SCHEMA,
    SAMPLE_SCHEMA,
    VALIDATION_SCHEMA,
    LEVELS_SCHEMA,
    LEVELS_FIT_SCHEMA,
)


def _schema_text(name: str) -> str:
    """Text of one schema file: the source tree's beside this package when there is one
    (a git worktree's own schemas, not those of the checkout the editable install maps
    ``idtool.datasets_schema`` to), else the installed package's."""
    source = Path(__file__).resolve().parents[2] / "datasets_schema" / name
    if source.is_file():
        return source.read_text("utf-8")
    return importlib.resources.files("idtool.datasets_schema").joinpath(name).read_text("utf-8")


@functools.cache
def load_schema(name: str) -> Mapping[str, Any]:
    """The parsed schema file ``name`` (one of the ``*_SCHEMA`` constants)."""
    return json.loads(_schema_text(name))


@functools.cache
def _registry() -> referencing.Registry:
    resources = [
        (load_schema(n)["$id"], referencing.Resource.from_contents(load_schema(n))) for n in _ALL
    ]
    return referencing.Registry().with_resources(resources)


@functools.cache
def schema_validator(name: str) -> jsonschema.Draft202012Validator:
    """The validator of the schema file ``name``, its references resolved."""
    return jsonschema.Draft202012Validator(load_schema(name), registry=_registry())


def trace_columns() -> tuple[str, ...]:
    """The required trace-table columns, in the schema's order."""
    return tuple(load_schema(TRACE_TABLE_SCHEMA)["required"])


def closest_name(name: str, candidates: Iterable[str]) -> str | None:
    """The candidate ``name`` is most likely a misspelling of, if any (case-insensitive)."""
    options = {c.lower(): c for c in candidates}
    match = difflib.get_close_matches(name.lower(), list(options), n=1, cutoff=0.6)
    return options[match[0]] if match else None


def json_path(parts: Sequence[str | int]) -> str:
    """``['traces', 2, 'file']`` -> ``'traces[2].file'``; ``'(top level)'`` for none."""
    out = ""
    for part in parts:
        out += f"[{part}]" if isinstance(part, int) else (f".{part}" if out else str(part))
    return out or "(top level)"


def _field_description(error: jsonschema.ValidationError) -> str:
    description = error.schema.get("description", "") if isinstance(error.schema, dict) else ""
    return f" ({description.rstrip('.')})" if description else ""


def _explain(error: jsonschema.ValidationError) -> list[tuple[str, str | None]]:
    """What is wrong and what to do; with the field it concerns when that is deeper.

    One ``required`` error per missing field and one ``additionalProperties`` error for
    all unknown fields are both turned into one message per field.
    """
    kind, value, limit = error.validator, error.instance, error.validator_value
    here = _field_description(error)
    known = list(error.schema.get("properties", {})) if isinstance(error.schema, dict) else []
    if kind == "required":
        extra = [k for k in value if k not in known]
        out = []
        for name in (f for f in limit if f not in value):
            guess = closest_name(name, extra)
            hint = f"; is '{guess}' a misspelling of it? rename it" if guess else ""
            out.append((f"missing required field '{name}'{hint}", name))
        return out
    if kind == "additionalProperties":
        extra = [k for k in value if k not in known and not str(k).startswith("x_")]
        out = []
        for name in extra:
            guess = closest_name(name, known)
            hint = f"did you mean '{guess}'?" if guess else f"known fields: {', '.join(known)}"
            text = f"unknown field '{name}': {hint} (prefix your own fields with 'x_' to keep them)"
            out.append((text, name))
        return out
    if kind == "type":
        return [(f"{value!r} is not of type {limit}{here}; write a {limit}", None)]
    if kind in ("exclusiveMinimum", "minimum", "exclusiveMaximum", "maximum"):
        sign = {"exclusiveMinimum": ">", "minimum": ">=", "exclusiveMaximum": "<"}.get(kind, "<=")
        return [(f"{value!r} is out of range: must be {sign} {limit}{here}", None)]
    if kind in ("const", "enum"):
        allowed = ", ".join(map(repr, [limit] if kind == "const" else limit))
        return [(f"{value!r} is not allowed: use one of {allowed}{here}", None)]
    if kind == "minLength":
        return [(f"must not be empty{here}", None)]
    if kind == "uniqueItems":
        return [(f"values repeat: list each value once{here}", None)]
    if kind == "minItems":
        return [(f"needs at least {limit} item(s){here}", None)]
    if kind == "not" and isinstance(limit, dict) and "required" in limit:
        fields = ", ".join(limit["required"])
        return [(f"remove field(s) {fields}: not used with these settings", None)]
    return [(f"{error.message}{here}", None)]


def _sort_key(error: jsonschema.ValidationError) -> list[tuple[int, int, str]]:
    """Document order: array items by index, object fields by name."""
    return [(0, p, "") if isinstance(p, int) else (1, 0, str(p)) for p in error.absolute_path]


def schema_problems(
    document: object, schema_name: str | Mapping[str, Any], file: str
) -> list[Problem]:
    """Every way ``document`` breaks the schema, as problems located by JSON field path.

    ``schema_name`` is one of the ``*_SCHEMA`` files, or a schema itself (one made at run
    time, its references resolved among the files).

    Amplitudes given in percent (a value in (1, 100] for a ``*fraction*`` field) get the
    hint "divide by 100".
    """
    problems = []
    done_required: set[tuple[str | int, ...]] = set()
    validator = (
        schema_validator(schema_name)
        if isinstance(schema_name, str)
        else jsonschema.Draft202012Validator(schema_name, registry=_registry())
    )
    for error in sorted(validator.iter_errors(document), key=_sort_key):
        where = tuple(error.absolute_path)
        if error.validator == "required":
            if where in done_required:
                continue  # _explain reported every missing field of this object
            done_required.add(where)
        value = error.instance
        is_number = isinstance(value, int | float) and not isinstance(value, bool)
        for message, field in _explain(error):
            parts = [*where, field] if field is not None else list(where)
            name = next((p for p in reversed(parts) if isinstance(p, str)), "")
            if "fraction" in name and is_number and 1 < value <= 100:
                message += f"; it looks like a percentage: divide by 100 (write {value / 100:g})"
            problems.append(Problem(message, file=file, column=json_path(parts)))
    return problems
