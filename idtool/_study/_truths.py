"""What a simulation study simulates: truths drawn from a fit, the design, the targets.

A truth is one draw of the fit's physical parameters (Kt [N/m], mu, the coupling law's
parameters), its coupling law picked by the fit's law weights (the draws of the kept
laws are pooled in proportion to their BIC weights, :attr:`idtool._predict._predict.
Draws.components`), with the levels model's pull-to-pull scatter sds of the same draw.
:func:`truth_params` turns it into the simulator's parameter document: the contact and
the coupling from the draw, the rig from the dataset, the load cell, actuator, horn
switching and timing from a base simulator document (default the example's,
``idtool/data/example_params.json``), the scatter sds as the simulator's
``scatter``; then a departure of :mod:`idtool._simulate._departures` on top (its
scatter a floor under the truth's, :func:`truth_params`).

The design is the fit's traces (load [N], amplitude, speed [m/s], ON duration [s]) plus
the plan's pulls; the targets, where the FR band is scored, the plan's operating points
(goal ``band``), else the fit's distinct ones.
"""

from __future__ import annotations

import copy
import dataclasses
import json
import os
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from idtool._errors import IdtoolError
from idtool._model._laws import TRUTH_NAMES
from idtool._predict._predict import Draws
from idtool._simulate._departures import with_departure
from idtool._simulate._records import coupling_laws
from idtool._simulate._truth import OperatingPoint

__all__ = [
    "Truth",
    "design_points",
    "draw_truths",
    "plan_pulls_from_folder",
    "targets_of",
    "truth_params",
]

# The levels model's sds -> the simulator's scatter fields (log-normal sds [-]).
SCATTER_FIELDS = {"scatter_fr": "friction_ratio_sd", "scatter_mu": "friction_coefficient_sd"}


@dataclasses.dataclass(frozen=True)
class Truth:
    """One drawn truth: the coupling ``law`` (the fit's registered name), the physical
    parameters by the fit's names (``Kt`` [N/m], ``mu``, ...) and the scatter sds
    (``scatter_fr``, ``scatter_mu``; log-normal [-])."""

    law: str
    values: dict[str, float]
    sds: dict[str, float]

    def to_dict(self) -> dict[str, Any]:
        return {"law": self.law, "values": dict(self.values), "sds": dict(self.sds)}

    @classmethod
    def from_dict(cls, doc: dict[str, Any]) -> Truth:
        return cls(str(doc["law"]), dict(doc["values"]), dict(doc.get("sds", {})))


def draw_truths(draws: Draws, n: int, seed: int) -> list[Truth]:
    """``n`` truths from ``draws`` (every kept law's, pooled: a law by its weight),
    picked with replacement by ``np.random.default_rng([seed, 29])``: same seed, same
    truths, and the first ``k`` of ``n`` are those of a study of ``k``."""
    pool: list[tuple[str, Draws, int]] = [
        (c.model.coupling.name, c, i) for c in draws.components for i in range(c.n)
    ]
    if not pool:
        raise IdtoolError("the fit has no draws to take truths from")
    rng = np.random.default_rng([seed, 29])
    picks = rng.integers(len(pool), size=n)
    out = []
    for k in picks:
        law, comp, i = pool[int(k)]
        values = {name: float(x[i]) for name, x in comp.values.items()}
        sds = {name: float(x[i]) for name, x in comp.sds.items() if name in SCATTER_FIELDS}
        out.append(Truth(law, values, sds))
    return out


def truth_params(
    truth: Truth,
    base: dict[str, Any],
    rig: dict[str, Any],
    friction_law: str,
    departure: str = "clean",
) -> dict[str, Any]:
    """The simulator's parameter document of ``truth`` (module docstring) on ``base``
    (a simulator document: load cell, actuator, switching, timing), with the dataset's
    ``rig`` and the ``departure`` switched on (``"clean"``: none, the fit's model with
    its scatter). The truth's drawn scatter sds are the simulator's; a departure with
    pull-to-pull scatter (``"scatter"``, ``"all"``) raises each to at least the
    departure's (:data:`idtool._simulate._departures.SCATTER`), never lowers it.

    Raises:
        IdtoolError: a coupling law the simulator cannot set from its fit parameters.
    """
    p = copy.deepcopy(base)
    p["rig"] = dict(rig)
    values = dict(truth.values)
    contact: dict[str, Any] = {"friction_law": friction_law}
    if "level_creep_per_s" in p.get("contact", {}):
        contact["level_creep_per_s"] = p["contact"]["level_creep_per_s"]
    file_law = truth.law.replace("-", "_")
    laws = coupling_laws()
    if file_law not in laws:
        raise IdtoolError(f"coupling law {truth.law!r}: the simulator has no such law")
    part = laws[file_law]
    gain = getattr(part, "gain_param", None)
    coupling: dict[str, Any] = {"law": file_law}
    for field in part.truth_fields():
        name = gain if field.name == "gain" else field.name
        if name not in values:
            raise IdtoolError(
                f"coupling law {truth.law!r}: the simulator needs {field.name!r}, which the "
                "fit does not estimate; a study cannot simulate this law"
            )
        coupling[field.name] = values.pop(name)
    for name, value in values.items():
        contact[TRUTH_NAMES.get(name, name)] = value
    p["contact"], p["coupling"] = contact, coupling
    p.pop("scatter", None)
    with_departure(p, departure)
    # The truth's own scatter, drawn with its parameters; a departure's scatter is a
    # floor under it, not a replacement: a truth that scatters 4.8% (the posterior's draw)
    # simulated at the preset 3% made the study's bands 30% narrower than the plan that
    # expected the posterior's scatter (issue 29); a fit that saw no scatter still meets
    # the departure's.
    floor = p.pop("scatter", {})
    drawn = {SCATTER_FIELDS[k]: float(v) for k, v in truth.sds.items() if k in SCATTER_FIELDS}
    scatter = {f: max(drawn.get(f, 0.0), floor.get(f, 0.0)) for f in (*drawn, *floor)}
    scatter = {f: v for f, v in scatter.items() if v > 0.0}
    if scatter:
        p["scatter"] = scatter
    p["name"] = f"study-{departure}"
    return p


def design_points(rows: Iterable[Sequence[float]], prefix: str = "t") -> list[OperatingPoint]:
    """One simulated trace per row (load [N], amplitude fraction, speed [m/s], ON
    duration [s]; 0 or not finite: no ON window), ids ``{prefix}000``, ..."""
    out = []
    for i, (n, a, v, t) in enumerate(rows):
        on_s = float(t) if np.isfinite(t) and t > 0 else 0.0
        out.append(OperatingPoint(f"{prefix}{i:03d}", float(n), float(a), on_s, float(v)))
    return out


def plan_pulls_from_folder(
    folder: str | os.PathLike, uniform: bool = False
) -> tuple[list[OperatingPoint], dict[str, Any]]:
    """The planned pulls of an ``idtool plan`` folder (``plan.json``) as simulated
    traces (ids ``p000``, ...), or with ``uniform`` the uniform grid of as many pulls
    it is compared with, and the plan's document.

    Raises:
        IdtoolError: no readable ``plan.json`` in ``folder``.
    """
    path = Path(folder) / "plan.json"
    try:
        doc = json.loads(path.read_text())
        pulls = doc["uniform_pulls" if uniform else "pulls"]
        rows = [
            (p["normal_load_n"], p["amplitude_fraction"], p["pull_speed_m_s"], p["on_time_s"])
            for p in pulls
        ]
    except KeyError as err:
        raise IdtoolError(
            f"--plan {folder}: {path} has no {err}; plan again with this idtool"
        ) from None
    except (OSError, ValueError, TypeError) as err:
        raise IdtoolError(
            f"--plan {folder}: cannot read {path} ({err}); give a folder 'idtool plan' wrote"
        ) from None
    return design_points(rows, prefix="p"), doc


def targets_of(
    plan_doc: dict[str, Any] | None, loads_n, amplitudes, speeds_m_s
) -> list[tuple[float, float, float]]:
    """Where the FR band is scored: the plan's ``at`` (load [N], amplitude, speed [m/s])
    for goal ``band``, else the fit's distinct operating points (in order)."""
    if plan_doc is not None and plan_doc.get("at"):
        return [(float(n), float(a), float(v)) for n, a, v in plan_doc["at"]]
    rows = zip(loads_n, amplitudes, speeds_m_s, strict=True)
    return list(dict.fromkeys((float(n), float(a), float(v)) for n, a, v in rows))
