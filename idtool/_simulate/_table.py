"""Simulated steady-state friction tables, for tests, studies and trying ``fit_levels``.

A tribometer's table (``kind: levels``): loads x amplitudes x speeds, ``repeats`` rows
per condition. The friction ratio is the registered friction and coupling laws' (Dahl
and the power limit, :func:`idtool.on_friction_ratio`) in a registered direction of
vibration; each row's OFF level is ``mu N`` with log-normal pull-to-pull scatter, its
ON level the OFF level times FR with a log-normal discrepancy per condition and
scatter per row: the error structure the table fit assumes
(:mod:`idtool._levels._estimate`).

``departure`` makes a bench the fit does not assume (issue 30's recovery study,
``benchmarks/study_benches.py``):

* ``"heavy-tails"``: the scatter from Student's t with 3 degrees of freedom, scaled to
  the same standard deviation (a pull now and then far off);
* ``"sublinear-coupling"``: the contact amplitude grows as the command to the power 0.6
  (a horn that loses efficiency as it is driven harder), a law no coupling has;
* ``"load-coupling"``: the coupling's gain falling with the load as
  ``exp(-N / 60 N)`` below the power limit (the trace simulator's ``coupling``
  departure: a clamped webbing damps the horn), a shape the power limit has not;
* ``"gain-drift"``: the rows measured in a random order while the horn's coupling falls
  linearly by 15% over the campaign (wear of the sonotrode face): the rows' FR drift
  with the order, which no table column records unless ``record_times`` writes each
  row's measurement time (the fit then fits the drift, :mod:`idtool._levels._model`).

:func:`table_friction_ratio` is the truth at any condition (for ``"gain-drift"`` at the
campaign's middle), for checking a prediction's band.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np

from idtool._data._levels import LevelsTable
from idtool._model._bench import on_friction_ratio
from idtool._model._coupling_power_limited import PowerLimitedCoupling
from idtool._model._directions import DIRECTIONS
from idtool._model._laws import Dahl

__all__ = ["TABLE_DEPARTURES", "TABLE_TRUTH", "simulate_table", "table_friction_ratio"]

# Kt [N/m], mu [-], the power limit's gain [-] and load [N]: a webbing-like contact
TABLE_TRUTH: dict[str, float] = {
    "Kt": 2e6,
    "mu": 0.3,
    "coupling_gain": 0.3,
    "power_load_n": 300.0,
}
TABLE_DEPARTURES = ("heavy-tails", "sublinear-coupling", "load-coupling", "gain-drift")
SUBLINEAR_EXPONENT = 0.6  # "sublinear-coupling": contact amplitude ~ command ** 0.6
GAIN_DRIFT = 0.15  # "gain-drift": the coupling's fall over the campaign, relative
ROW_INTERVAL_S = 300.0  # record_times: one row measured every 5 minutes
T_DOF = 3  # "heavy-tails": Student's t degrees of freedom
LOAD_SCALE_N = 60.0  # "load-coupling": the gain's e-folding load [N]


def table_friction_ratio(
    load_n: float,
    amplitude_m: float,
    speed_m_s: float,
    *,
    truth: Mapping[str, float] | None = None,
    direction: str = "along",
    departure: str | None = None,
    gain_scale: float | None = None,
    frequency_hz: float = 22e3,
    max_amplitude_m: float = 6e-6,
) -> float:
    """The simulated bench's true FR [-] at one condition (no scatter, no discrepancy).

    ``gain_scale`` multiplies the coupling's gain (default 1, or the campaign's middle,
    ``1 - GAIN_DRIFT / 2``, for ``"gain-drift"``)."""
    t = dict(TABLE_TRUTH if truth is None else truth)
    if gain_scale is None:
        gain_scale = 1.0 - 0.5 * GAIN_DRIFT if departure == "gain-drift" else 1.0
    fraction = amplitude_m / max_amplitude_m
    if departure == "load-coupling":
        gain_scale = gain_scale * float(np.exp(-load_n / LOAD_SCALE_N))
    if departure == "sublinear-coupling":
        fraction = fraction**SUBLINEAR_EXPONENT
    coupling = PowerLimitedCoupling(
        gain=t["coupling_gain"] * gain_scale, power_load_n=t["power_load_n"]
    )
    return float(
        on_friction_ratio(
            Dahl.at_load(t, load_n),
            coupling,
            load_n,
            fraction,
            speed_m_s,
            frequency_hz,
            max_amplitude_m,
            DIRECTIONS.get(direction),
        )
    )


def simulate_table(
    seed: int,
    *,
    truth: Mapping[str, float] | None = None,
    direction: str = "along",
    departure: str | None = None,
    loads_n: Sequence[float] = (20.0, 50.0, 100.0),
    amplitudes_m: Sequence[float] = (2e-6, 4e-6, 6e-6),
    speeds_m_s: Sequence[float] = (0.02, 0.08),
    repeats: int = 3,
    scatter_fr: float = 0.03,
    discrepancy: float = 0.02,
    scatter_mu: float = 0.02,
    frequency_hz: float = 22e3,
    max_amplitude_m: float = 6e-6,
    name: str | None = None,
    record_times: bool = False,
) -> LevelsTable:
    """A simulated table (module docstring), friction as forces [N].

    Args:
        seed: of every random draw.
        truth: ``Kt`` [N/m], ``mu``, ``coupling_gain``, ``power_load_n`` [N]
            (default :data:`TABLE_TRUTH`).
        direction: of the vibration (:data:`idtool.DIRECTIONS`).
        departure: None (the fit's own error model) or one of :data:`TABLE_DEPARTURES`.
        loads_n: the grid's normal loads [N].
        amplitudes_m: its vibration amplitudes [m].
        speeds_m_s: its sliding speeds [m/s].
        repeats: rows per condition.
        scatter_fr: sd of the log ON/OFF per row (pull-to-pull scatter).
        discrepancy: sd of log FR per condition (model discrepancy).
        scatter_mu: sd of log OFF per row.
        frequency_hz: the vibration's frequency [Hz].
        max_amplitude_m: the rig's amplitude at full command [m].
        name: the table's (default ``simulated-<seed>``).
        record_times: write each row's measurement time (``time_s``, one row every
            :data:`ROW_INTERVAL_S` in a random order: for ``"gain-drift"`` the order the
            gain falls along; otherwise drawn from a stream of its own, so that the
            table's numbers are those without the times).
    """
    if departure is not None and departure not in TABLE_DEPARTURES:
        raise ValueError(f"departure {departure!r}: None or one of {TABLE_DEPARTURES}")
    t = dict(TABLE_TRUTH if truth is None else truth)
    rng = np.random.default_rng(seed)
    grid = np.array([(n, a, v) for n in loads_n for a in amplitudes_m for v in speeds_m_s])
    rows = np.repeat(grid, repeats, axis=0)
    condition = np.repeat(np.arange(len(grid)), repeats)

    def ratio(load_n: float, amplitude_m: float, speed_m_s: float, scale=None) -> float:
        return table_friction_ratio(
            load_n, amplitude_m, speed_m_s, truth=t, direction=direction,
            departure=departure, gain_scale=scale, frequency_hz=frequency_hz,
            max_amplitude_m=max_amplitude_m,
        )  # fmt: skip

    # the place of each row in the measuring order (the rows' order, unless drawn)
    order = np.random.default_rng([seed, 1]).permutation(len(rows))
    if departure == "gain-drift":
        # the order the rows were measured in; the gain falls linearly along it
        order = rng.permutation(len(rows))
        scale = np.empty(len(rows))
        scale[order] = 1.0 - GAIN_DRIFT * np.arange(len(rows)) / max(len(rows) - 1, 1)
        fr = np.array([ratio(n, a, v, s) for (n, a, v), s in zip(rows, scale, strict=True)])
    else:
        fr = np.array([ratio(*g) for g in grid])[condition]
    d = rng.normal(0.0, discrepancy, len(grid))[condition]
    if departure == "heavy-tails":
        unit = rng.standard_t(T_DOF, (2, len(rows))) / np.sqrt(T_DOF / (T_DOF - 2))
        noise_mu, noise_fr = scatter_mu * unit[0], scatter_fr * unit[1]
    else:
        noise_mu = rng.normal(0.0, scatter_mu, len(rows))
        noise_fr = rng.normal(0.0, scatter_fr, len(rows))
    off = t["mu"] * rows[:, 0] * np.exp(noise_mu)
    on = off * fr * np.exp(d + noise_fr)
    nan = np.full(len(rows), np.nan)
    time_s = np.empty(len(rows))
    time_s[order] = ROW_INTERVAL_S * np.arange(len(rows))
    return LevelsTable(
        name=name or f"simulated-{seed}",
        material="simulated",
        friction="force",
        normal_load_n=rows[:, 0],
        amplitude_m=rows[:, 1],
        amplitude_fraction=nan,
        vibration_frequency_hz=np.full(len(rows), frequency_hz),
        sliding_speed_m_s=rows[:, 2],
        off=off,
        on=on,
        off_se=nan,
        on_se=nan,
        repeat=tuple(str(i % repeats) for i in range(len(rows))),
        time_s=time_s if record_times else nan,
        max_amplitude_m=max_amplitude_m,
    )
