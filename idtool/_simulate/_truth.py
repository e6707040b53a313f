"""The records of what produced a simulated dataset: per trace, per operating point, and
the whole bench's truth (written beside the dataset as ``true_parameters.json``)."""

from __future__ import annotations

import dataclasses
from typing import Any

from idtool._simulate._params import BenchParams
from idtool._version import __version__

__all__ = ["BenchTruth", "OperatingPoint", "OperatingPointTruth", "TraceTruth"]


@dataclasses.dataclass(frozen=True)
class OperatingPoint:
    """One trace of the matrix: its id, load [N], amplitude fraction, ON duration [s],
    pull speed [m/s]."""

    id: str
    normal_load_n: float
    amplitude_fraction: float
    on_duration_s: float
    pull_speed_m_s: float


@dataclasses.dataclass(frozen=True)
class TraceTruth:
    """What produced one simulated trace.

    Attributes:
        friction_ratio: this trace's FR = ON level / OFF level, with its pull-to-pull
            scatter (without scatter, ``operating_point_friction_ratio``).
        off_force_n, on_force_n: this trace's ``mu N`` and ``FR mu N`` [N], with scatter,
            without the offset.
        slip_amplitude_m: effective slip amplitude a from the coupling [m].
        velocity_ratio: VR = v / (a w) (None without vibration).
        dimensionless_stiffness: Lambda = Kt a / (mu N), at the nominal mu (None for a
            rigid law: Coulomb's Kt is infinite).
        load_cell_offset_n: this trace's offset at time 0 [N].
        startup_s: pull start [s].
        logged_on_s, horn_on_s: ON window of the logged flag and of the horn [s]
            (None without ON).
        mains_phase_rad: phase of the hum.
        reaches_on_level: whether the force gets down to the ON level before OFF (lag
            actuator: to within ``idtool._model._actuator.REACH_FRACTION`` of the ON-OFF depth).
        friction_coefficient: this trace's mu [-], with scatter.
        operating_point_friction_ratio: FR of the operating point without scatter.
        offset_drift_n_s: this trace's offset drift rate [N/s]: the offset at time t is
            ``load_cell_offset_n + offset_drift_n_s * t``.
        startup_end_s: end of the start-up rise [s]; the steady OFF sliding follows.
        on_force_end_n: the ON level [N] at the horn's switch-off, without the offset
            (None without ON): above ``on_force_n`` (the level at switch-on) when the horn
            fades (:mod:`idtool._simulate._plateau_drift`), else equal to it.
        level_creep_per_s: relative creep of mu with sliding time [1/s]: the levels are
            ``off_force_n`` and ``on_force_n`` times ``1 + level_creep_per_s * (t -
            startup_s)``.
        pull_speed_m_s: this trace's pull speed [m/s].
    """

    id: str
    normal_load_n: float
    amplitude_fraction: float
    on_duration_s: float
    friction_ratio: float
    off_force_n: float
    on_force_n: float
    slip_amplitude_m: float
    velocity_ratio: float | None
    dimensionless_stiffness: float | None
    load_cell_offset_n: float
    startup_s: float
    logged_on_s: tuple[float, float] | None
    horn_on_s: tuple[float, float] | None
    mains_phase_rad: float
    reaches_on_level: bool
    friction_coefficient: float
    operating_point_friction_ratio: float
    offset_drift_n_s: float
    startup_end_s: float
    on_force_end_n: float | None = None
    level_creep_per_s: float = 0.0
    pull_speed_m_s: float = 0.0


@dataclasses.dataclass(frozen=True)
class OperatingPointTruth:
    """The contact model at one operating point, without pull-to-pull scatter.

    Attributes:
        friction_ratio: FR [-], the median of the traces' FR under scatter (their mean is
            ``exp(friction_ratio_sd^2 / 2)`` times larger, before the cap at 1): the
            curve a fit should recover.
        slip_amplitude_m: effective slip amplitude a [m].
        velocity_ratio: VR = v / (a w) (None without vibration).
        dimensionless_stiffness: Lambda = Kt a / (mu N) (None for a rigid law).
    """

    normal_load_n: float
    amplitude_fraction: float
    pull_speed_m_s: float
    friction_ratio: float
    slip_amplitude_m: float
    velocity_ratio: float | None
    dimensionless_stiffness: float | None


@dataclasses.dataclass(frozen=True)
class BenchTruth:
    """The truth behind a simulated dataset (written as ``true_parameters.json``)."""

    seed: int
    params: BenchParams
    traces: tuple[TraceTruth, ...]
    dataset_sha256: str
    operating_points: tuple[OperatingPointTruth, ...] = ()

    def to_dict(self) -> dict[str, Any]:
        """The JSON document: the identifiable parameters first, then per operating point
        and per trace, then all parameters.

        ``coupling_in_fit`` is false for a truth-only coupling law: the fit cannot
        represent the truth, so its coupling parameters have no true value to cover.
        """
        contact = self.params.contact
        return {
            "seed": self.seed,
            "idtool_version": __version__,
            "dataset_sha256": self.dataset_sha256,
            "friction_law": contact.friction_law,
            **contact.values(),  # mu and the law's own parameters, by their file names
            "coupling": self.params.to_dict()["coupling"],
            "coupling_in_fit": self.params.coupling.in_fit,
            # the direction of vibration simulated (idtool.DIRECTIONS; 'idtool fit
            # --direction' names the model that can represent it)
            "direction": contact.direction,
            "operating_points": [dataclasses.asdict(o) for o in self.operating_points],
            "traces": [dataclasses.asdict(t) for t in self.traces],
            "params": self.params.to_dict(),
        }
