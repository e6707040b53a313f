"""Parameters of the bench simulator (``datasets_schema/simulator_params.schema.json``).

The dataclasses mirror the JSON file one to one, so ``BenchParams.from_dict(p.to_dict())``
is ``p`` and the schema's descriptions (with units) document every field.

The ``contact``, ``coupling`` and ``actuator`` sections, and the optional
``block_mean_noise``, are the typed records of the registered part they name
(:mod:`idtool._simulate._records`), checked against the schema made from the registries
(:mod:`idtool._simulate._schema`).

The optional fields describe departures of the bench from the fit's model (pull-to-pull
scatter, a lagging actuator, offset drift, a coupling law the fit does not ship, a horn
fading within its ON windows, a creeping friction level) and block-mean noise drawn
from a registered noise model (:mod:`idtool._simulate._block_noise`). Their
defaults are "no departure" and reproduce the simulator's earlier output bit for bit;
:meth:`BenchParams.to_dict` leaves out optional fields at their defaults, so a file
without them reads and writes back unchanged.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from idtool._data._dataset import Rig, TransducerSpec
from idtool._data._schema import schema_problems
from idtool._errors import IdtoolError, Problem
from idtool._jsonio import parse_json
from idtool._model._coupling import reacts_on_vibration
from idtool._model._names import DEFAULT_DIRECTION
from idtool._simulate._block_noise import block_noise_problems
from idtool._simulate._records import (
    ActuatorParams,
    BlockNoiseParams,
    ContactParams,
    CouplingParams,
    actuator_record,
    contact_record,
    coupling_record,
    noise_record,
)
from idtool._simulate._schema import simulator_params_schema

__all__ = [
    "ActuatorParams",
    "BenchParams",
    "BlockNoiseParams",
    "ContactParams",
    "CouplingParams",
    "ExperimentParams",
    "FadingParams",
    "LoadCellParams",
    "OutputParams",
    "ScatterParams",
    "SwitchingParams",
    "load_bench_params",
]

PARAMS_VERSION = "1"


@dataclasses.dataclass(frozen=True)
class SwitchingParams:
    """Lag of the horn behind the logged ON flag: mean and standard deviation [s]."""

    delay_mean_s: float
    delay_std_s: float


@dataclasses.dataclass(frozen=True)
class LoadCellParams:
    """Offset, white and AR(1) noise, mains hum [N]; correlation time [s]; ADC step [N]."""

    offset_mean_n: float
    offset_std_n: float
    white_noise_std_n: float
    correlated_noise_std_n: float
    correlated_noise_time_s: float
    mains_frequency_hz: float
    mains_amplitude_n: float
    adc_lsb_n: float
    offset_drift_sd_n_s: float = 0.0


@dataclasses.dataclass(frozen=True)
class ScatterParams:
    """Pull-to-pull scatter of the contact: log-normal multipliers' sd [-] per trace.

    A trace's friction ratio is the operating point's FR times ``exp(N(0,
    friction_ratio_sd))``, capped at 1; its mu is mu times ``exp(N(0,
    friction_coefficient_sd))``, which scatters its OFF level ``mu N``.
    """

    friction_ratio_sd: float = 0.0
    friction_coefficient_sd: float = 0.0


@dataclasses.dataclass(frozen=True)
class FadingParams:
    """A horn whose slip amplitude fades within each ON window (truth only):
    ``a(t_on) = a0 (1 - fade_fraction (1 - exp(-t_on / fade_time_constant_s)))``, with
    ``t_on`` [s] the time since the horn switched on (:mod:`idtool._simulate._plateau_drift`).
    """

    fade_fraction: float = 0.0
    fade_time_constant_s: float = 1.0


@dataclasses.dataclass(frozen=True)
class ExperimentParams:
    """The matrix (loads [N] x amplitude fractions x ON durations [s] x pull speeds [m/s]
    x repeats) and timing. ``pull_speed_m_s`` is one speed or several: pulls at two or
    more speeds at each load and amplitude pin Kt whatever the coupling law (docs/model.md,
    "What Kt rests on")."""

    normal_loads_n: tuple[float, ...]
    amplitude_fractions: tuple[float, ...]
    on_durations_s: tuple[float, ...]
    pull_speed_m_s: float | tuple[float, ...]
    sliding_before_s: float
    sliding_after_s: float
    sample_rate_hz: float
    repeats: int

    @property
    def pull_speeds_m_s(self) -> tuple[float, ...]:
        """The pull speeds [m/s] of the matrix, the first the reference speed (of
        :func:`idtool._simulate._simulate.true_friction_ratio` without a speed)."""
        v = self.pull_speed_m_s
        return v if isinstance(v, tuple) else (v,)


@dataclasses.dataclass(frozen=True)
class OutputParams:
    """Trace file format: 'csv' or 'parquet'."""

    trace_format: str


@dataclasses.dataclass(frozen=True)
class BenchParams:
    """Everything the simulator needs (see the schema for each field's meaning and unit)."""

    name: str
    material: str
    rig: Rig
    contact: ContactParams
    coupling: CouplingParams
    actuator: ActuatorParams
    horn_switching: SwitchingParams
    load_cell: LoadCellParams
    experiments: ExperimentParams
    output: OutputParams
    description: str | None = None
    scatter: ScatterParams = ScatterParams()
    horn_fading: FadingParams = FadingParams()
    block_mean_noise: BlockNoiseParams | None = None

    @classmethod
    def from_dict(cls, document: Mapping[str, Any], file: str = "params") -> BenchParams:
        """Check ``document`` against the schema and build the parameters.

        Raises:
            IdtoolError: listing every schema violation, located by field; a
                ``block_mean_noise`` whose parameters give the model no finite noise.
        """
        # the schema of the parts registered now (a part registered after import included)
        problems = schema_problems(document, simulator_params_schema(), file)
        if problems:
            raise IdtoolError(f"{file}: invalid simulator parameters", problems)
        d = document
        noise = noise_record(d["block_mean_noise"]) if "block_mean_noise" in d else None
        if noise is not None and (problems := block_noise_problems(noise, file)):
            raise IdtoolError(f"{file}: invalid simulator parameters", problems)
        contact, coupling = contact_record(d["contact"]), coupling_record(d["coupling"])
        if contact.direction != DEFAULT_DIRECTION and reacts_on_vibration(coupling.part):
            raise IdtoolError(
                f"{file}: invalid simulator parameters",
                [
                    Problem(
                        f"the {coupling.law!r} coupling law solves the horn's balance with "
                        "the vibration along the sliding; with direction "
                        f"{contact.direction!r} choose another coupling law",
                        file,
                        column="contact.direction",
                    )
                ],
            )
        return cls(
            name=d["name"],
            material=d["material"],
            # Every rig field the dataset schema knows (its optional ones included), so a
            # field the file gives reaches dataset.json and to_dict; 'x_' ones are ignored.
            rig=Rig(
                **_floats(
                    {
                        k: v
                        for k, v in d["rig"].items()
                        if not k.startswith("x_") and k != "transducer"
                    }
                ),
                transducer=TransducerSpec.from_dict(d["rig"].get("transducer")),
            ),
            contact=contact,
            coupling=coupling,
            actuator=actuator_record(d["actuator"]),
            horn_switching=SwitchingParams(**_floats(d["horn_switching"])),
            load_cell=LoadCellParams(**_floats(d["load_cell"])),
            experiments=_experiments(d["experiments"]),
            output=OutputParams(**d["output"]),
            description=d.get("description"),
            scatter=ScatterParams(**_floats(d.get("scatter", {}))),
            horn_fading=FadingParams(**_floats(d.get("horn_fading", {}))),
            block_mean_noise=noise,
        )

    def to_dict(self) -> dict[str, Any]:
        """The JSON document of these parameters (lists for tuples).

        Unset fields (None) and optional fields at their defaults are left out, so the
        document of parameters without departures is the same as before they existed.
        """
        out: dict[str, Any] = {"params_version": PARAMS_VERSION}
        for field in dataclasses.fields(self):
            value = getattr(self, field.name)
            if value is None or _is_default(field, value):
                continue
            if dataclasses.is_dataclass(value) and not isinstance(value, type):
                value = {
                    f.name: list(v) if isinstance(v, tuple) else _plain(v)
                    for f in dataclasses.fields(value)
                    if (v := getattr(value, f.name)) is not None and not _is_default(f, v)
                }
            out[field.name] = value
        return out


def _is_default(field: dataclasses.Field[Any], value: Any) -> bool:
    """Whether ``value`` is the declared (non-None) default of an optional field."""
    if field.default is not dataclasses.MISSING and field.default is not None:
        return bool(value == field.default)
    return False


def _plain(value: Any) -> Any:
    """A nested record (the rig's transducer) as its JSON object."""
    return value.to_dict() if hasattr(value, "to_dict") else value


def _optional_float(value: Any) -> float | None:
    return None if value is None else float(value)


def _floats(section: Mapping[str, Any]) -> dict[str, float]:
    return {k: float(v) for k, v in section.items()}


def _experiments(section: Mapping[str, Any]) -> ExperimentParams:
    lists = ("normal_loads_n", "amplitude_fractions", "on_durations_s")
    values: dict[str, Any] = {k: tuple(float(x) for x in section[k]) for k in lists}
    values.update({k: float(v) for k, v in section.items() if k not in (*lists, "pull_speed_m_s")})
    speed = section["pull_speed_m_s"]
    values["pull_speed_m_s"] = (
        tuple(float(x) for x in speed) if isinstance(speed, list | tuple) else float(speed)
    )
    values["repeats"] = int(section["repeats"])
    return ExperimentParams(**values)


def load_bench_params(path: str | Path) -> BenchParams:
    """Read and check a simulator parameter file.

    Raises:
        IdtoolError: the file is missing, not JSON, or breaks the schema.
    """
    path = Path(path)
    try:
        data = path.read_bytes()
    except OSError as err:
        raise IdtoolError(
            f"cannot read {path} ({err.strerror or err}): give --params FILE"
        ) from None
    document, problems = parse_json(data, str(path))
    if problems:
        raise IdtoolError(f"{path}: not valid JSON", problems)
    return BenchParams.from_dict(document, str(path))
