"""Parameters of the bench simulator (``datasets_schema/simulator_params.schema.json``).

The dataclasses mirror the JSON file one to one, so ``BenchParams.from_dict(p.to_dict())``
is ``p`` and the schema's descriptions (with units) document every field.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from idtool._data._dataset import Rig
from idtool._data._schema import SIMULATOR_PARAMS_SCHEMA, schema_problems
from idtool._errors import IdtoolError
from idtool._jsonio import parse_json
from idtool._model._coupling import COUPLINGS, AbstractCoupling

__all__ = [
    "ActuatorParams",
    "BenchParams",
    "ContactParams",
    "CouplingParams",
    "ExperimentParams",
    "LoadCellParams",
    "OutputParams",
    "SwitchingParams",
    "load_bench_params",
]

PARAMS_VERSION = "1"


@dataclasses.dataclass(frozen=True)
class ContactParams:
    """The true contact: Dahl with coefficient mu [-] and stiffness Kt [N/m]."""

    friction_law: str
    friction_coefficient: float
    contact_stiffness_n_m: float


@dataclasses.dataclass(frozen=True)
class CouplingParams:
    """Horn amplitude -> slip amplitude: ``law`` 'constant' or 'power_limited' (P [N])."""

    law: str
    gain: float
    power_load_n: float | None = None

    def model(self) -> AbstractCoupling:
        """The registered coupling law of this name (``power_limited`` in the file is
        the registry's ``power-limited``)."""
        values: dict[str, Any] = {"coupling_gain": self.gain, "power_load_n": self.power_load_n}
        return COUPLINGS.get(self.law.replace("_", "-")).from_values(values)


@dataclasses.dataclass(frozen=True)
class ActuatorParams:
    """Pull start [s], start-up and ON/OFF slopes [N/s], corner rounding [N]."""

    pull_start_s: float
    startup_slope_n_s: float
    slope_n_s: float
    corner_n: float


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


@dataclasses.dataclass(frozen=True)
class ExperimentParams:
    """The matrix (loads [N] x amplitude fractions x ON durations [s] x repeats) and timing."""

    normal_loads_n: tuple[float, ...]
    amplitude_fractions: tuple[float, ...]
    on_durations_s: tuple[float, ...]
    pull_speed_m_s: float
    sliding_before_s: float
    sliding_after_s: float
    sample_rate_hz: float
    repeats: int


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

    @classmethod
    def from_dict(cls, document: Mapping[str, Any], file: str = "params") -> BenchParams:
        """Check ``document`` against the schema and build the parameters.

        Raises:
            IdtoolError: listing every schema violation, located by field.
        """
        problems = schema_problems(document, SIMULATOR_PARAMS_SCHEMA, file)
        if problems:
            raise IdtoolError(f"{file}: invalid simulator parameters", problems)
        d = document
        return cls(
            name=d["name"],
            material=d["material"],
            rig=Rig(
                vibration_frequency_hz=float(d["rig"]["vibration_frequency_hz"]),
                max_amplitude_m=float(d["rig"]["max_amplitude_m"]),
            ),
            contact=ContactParams(
                friction_law=d["contact"]["friction_law"],
                friction_coefficient=float(d["contact"]["friction_coefficient"]),
                contact_stiffness_n_m=float(d["contact"]["contact_stiffness_n_m"]),
            ),
            coupling=CouplingParams(
                law=d["coupling"]["law"],
                gain=float(d["coupling"]["gain"]),
                power_load_n=_optional_float(d["coupling"].get("power_load_n")),
            ),
            actuator=ActuatorParams(**_floats(d["actuator"])),
            horn_switching=SwitchingParams(**_floats(d["horn_switching"])),
            load_cell=LoadCellParams(**_floats(d["load_cell"])),
            experiments=_experiments(d["experiments"]),
            output=OutputParams(**d["output"]),
            description=d.get("description"),
        )

    def to_dict(self) -> dict[str, Any]:
        """The JSON document of these parameters (lists for tuples)."""
        out: dict[str, Any] = {"params_version": PARAMS_VERSION}
        for field in dataclasses.fields(self):
            value = getattr(self, field.name)
            if value is None:
                continue
            if dataclasses.is_dataclass(value) and not isinstance(value, type):
                value = {k: v for k, v in dataclasses.asdict(value).items() if v is not None}
                value = {k: list(v) if isinstance(v, tuple) else v for k, v in value.items()}
            out[field.name] = value
        return out


def _optional_float(value: Any) -> float | None:
    return None if value is None else float(value)


def _floats(section: Mapping[str, Any]) -> dict[str, float]:
    return {k: float(v) for k, v in section.items()}


def _experiments(section: Mapping[str, Any]) -> ExperimentParams:
    lists = ("normal_loads_n", "amplitude_fractions", "on_durations_s")
    values: dict[str, Any] = {k: tuple(float(x) for x in section[k]) for k in lists}
    values.update({k: float(v) for k, v in section.items() if k not in lists})
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
