"""The JSON Schema of the simulator's parameter file, made from the registries.

The ``contact``, ``coupling``, ``actuator`` and ``block_mean_noise`` sections list the
registered friction laws, coupling laws (the fit's and the simulator's truth-only ones),
actuator models and noise models, each with its own fields (its ``truth_fields``): one
``if``/``then`` block per part requires its fields and refuses every other part's, so a
bad file gets located messages (:func:`idtool._data._schema.schema_problems`). The other
sections are fixed here. ``datasets_schema/simulator_params.schema.json`` is this
function's output for the shipped parts (``tests/test_simulator_schema.py`` checks they
are equal; ``python -m idtool._simulate._schema`` rewrites the file).
"""

from __future__ import annotations

import copy
import json
import sys
from collections.abc import Callable, Mapping
from typing import Any

from idtool._model._directions import DIRECTIONS
from idtool._model._names import DEFAULT_ACTUATOR, DEFAULT_DIRECTION
from idtool._simulate._records import actuator_models, coupling_laws, friction_laws, noise_models
from idtool._simulate._schema_fixed import DIRECTION, FIXED, LEVEL_CREEP, PULL_START

__all__ = ["schema_text", "simulator_params_schema"]


def _summary(part: type[Any]) -> str:
    """The first paragraph of a part's docstring, on one line, without RST quoting."""
    doc = (part.__doc__ or part.__name__).strip().split("\n\n")[0]
    return " ".join(doc.replace("``", "").split()).rstrip(".")


def _noise_summary(model: type[Any]) -> str:
    """A noise model's words: its ``description`` (the report's), else its docstring's."""
    return str(getattr(model, "description", "")) or _summary(model)


def _section(
    parts: Mapping[str, type[Any]],
    kind: str,
    kind_description: str,
    description: str,
    common: Mapping[str, Any],
    required: tuple[str, ...],
    default: str | None = None,
    summary: Callable[[type[Any]], str] = _summary,
) -> dict[str, Any]:
    """One section: the ``kind`` field naming the part, the ``common`` fields, every
    part's own fields, and per part an ``if``/``then`` requiring its own fields and
    refusing the others' (``default``: the part when the file leaves ``kind`` out;
    ``summary``: a part's words in the ``kind`` field's description)."""
    own = {name: part.truth_fields() for name, part in parts.items()}
    names = " ".join(f"'{name}': {summary(part)}." for name, part in parts.items())
    kind_schema: dict[str, Any] = {
        "enum": list(parts),
        "description": f"{kind_description} {names}",
    }
    if default is not None:
        kind_schema["default"] = default
    properties: dict[str, Any] = {kind: kind_schema, **copy.deepcopy(dict(common))}
    for fields in own.values():
        for field in fields:
            properties.setdefault(field.name, field.schema())
    every = [f for f in properties if f != kind and f not in common]
    blocks = []
    for name, fields in own.items():
        mine = [f.name for f in fields]
        condition: dict[str, Any] = {"properties": {kind: {"const": name}}}
        if name != default:
            condition["required"] = [kind]
        then: dict[str, Any] = {
            "required": [f.name for f in fields if f.default is None],
        }
        others = [{"not": {"required": [f]}} for f in every if f not in mine]
        if others:
            then["allOf"] = others
        blocks.append({"if": condition, "then": then})
    return {
        "type": "object",
        "description": description,
        "required": [*([] if default is not None else [kind]), *required],
        "properties": properties,
        "additionalProperties": False,
        "allOf": blocks,
    }


def _direction() -> dict[str, Any]:
    """The contact's ``direction`` field: the registered directions, each in words."""
    out = copy.deepcopy(DIRECTION)
    out["enum"] = list(DIRECTIONS.names())
    out["default"] = DEFAULT_DIRECTION
    names = " ".join(f"'{n}': {DIRECTIONS.get(n).description}." for n in DIRECTIONS.names())
    out["description"] += f" {names}"
    return out


def simulator_params_schema() -> dict[str, Any]:
    """The schema of the simulator's parameter file for the parts registered now."""
    schema: dict[str, Any] = copy.deepcopy(FIXED)
    properties: dict[str, Any] = schema["properties"]
    properties["contact"] = _section(
        friction_laws(),
        "friction_law",
        "Friction law of the contact (registered in idtool._model._laws.FRICTION_LAWS).",
        "The true contact model (model notes §1): a friction law and its parameters.",
        {"level_creep_per_s": LEVEL_CREEP, "direction": _direction()},
        (),
    )
    properties["coupling"] = _section(
        coupling_laws(),
        "law",
        "Coupling law: those the fit ships (idtool._model._coupling.COUPLINGS, '_' for "
        "'-' in their names), then the simulator's truth-only ones (the fit has no such "
        "law, so a fit of their data is misspecified; idtool._simulate._truth_coupling).",
        "Commanded horn amplitude -> effective slip amplitude of the contact: a coupling "
        "law and its parameters (alpha the commanded amplitude fraction, A_max the "
        "rig's max_amplitude_m, N the normal load).",
        {},
        (),
    )
    properties["actuator"] = _section(
        actuator_models(),
        "model",
        f"Optional, default '{DEFAULT_ACTUATOR}': how the force follows its target (0 "
        "before the pull, then the OFF level, the ON level while the horn is ON, the OFF "
        "level again; idtool._model._actuator.ACTUATORS).",
        "The pneumatic actuator: when the pull starts and how the force follows its target.",
        {"pull_start_s": PULL_START},
        ("pull_start_s",),
        default=DEFAULT_ACTUATOR,
    )
    properties["block_mean_noise"] = _section(
        noise_models(),
        "model",
        "Noise model of the block means (registered in idtool._model._noise.NOISE_MODELS, "
        "named as 'idtool fit --noise' takes it).",
        "Optional: noise added to the block means, drawn from a registered noise model, "
        "on top of the load cell's sample-rate noise. The traces are cut into the fit's "
        "blocks (2 whole periods of the mains the fit would use: rig.mains_frequency_hz, "
        "else the hum found in the traces, else 50 Hz) and each block's drawn value [N] is "
        "added to every sample of the block, so each block mean moves by exactly that "
        "value (after the ADC's quantisation). Its fields are the model's parameters "
        "under the names the fit reports: sigma_n [N] the innovations' scale (the block "
        "means' sd for independent Gaussian noise; for AR(1) their stationary sd is "
        "sigma_n / sqrt(1 - phi^2)), then the model's own. Drawn from a random stream "
        "of the seed's own, after every trace's, so the traces' other noise is unchanged; "
        "omitted, no block-mean noise.",
        {},
        (),
        summary=_noise_summary,
    )
    return schema


def schema_text() -> str:
    """The schema file's text: :func:`simulator_params_schema`, indented by 2."""
    return json.dumps(simulator_params_schema(), indent=2, ensure_ascii=False) + "\n"


if __name__ == "__main__":  # python -m idtool._simulate._schema > datasets_schema/...
    sys.stdout.write(schema_text())
