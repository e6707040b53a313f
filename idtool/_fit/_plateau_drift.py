"""Do the levels drift within their plateaus? A residual diagnostic of the fitted bench model.

The bench model holds each level constant between switchings. A horn whose amplitude
fades within its ON window (the ON level rises through it) or a friction level that
creeps (the OFF level rises through the pull) leaves a trend in every plateau's
residuals; the AR(1) noise model absorbs it as correlation, and the levels model
(:mod:`idtool._fit._variability`) sees only each trace's mean levels, so neither warns.

Per trace, on the fit's block-mean residuals ``r = data - model`` [N]:

* plateaus, from the fitted timing: OFF after the start-up has settled until the horn's
  switch-on, ON from when the force has settled at its ON level until the switch-off
  (only traces whose ON level is measured, :data:`~idtool._fit._free_levels.MIN_AT_LEVEL_S`),
  OFF again from the recovery until the trace's end; each trimmed by
  :data:`EDGE_S` at both ends (the corners of the actuator's path), kept if at least
  :data:`MIN_BLOCKS` blocks long;
* the ordinary least-squares slope ``b = sum c_i r_i / sum c_i^2`` [N/s], ``c_i = t_i -
  mean(t)``, of the residuals on time, and its standard error under the fitted noise
  model: AR(1) block means with coefficient ``phi`` and innovation sd ``sigma``, so
  ``Cov(r_i, r_j) = sigma^2 phi^|i-j| / (1 - phi^2)`` and exactly
  ``Var(b) = c' R c / (c'c)^2`` with that covariance ``R`` (for a long plateau
  ``sigma^2 / (1 - phi^2) (1 + phi) / (1 - phi) / c'c``: the variance inflation of a
  mean of AR(1) values). Under the model, ``z = b / se(b)`` is standard normal;
* the relative change over the plateau, ``b T / level`` (``T`` its duration [s], the
  fitted OFF or ON level [N]).

Pooled per kind (ON, OFF) over the plateaus of every trace: Stouffer's
``Z = sum z / sqrt(K)``, standard normal under the model if the plateaus' noise is
independent (different traces; the two OFF plateaus of a trace are seconds apart, many
correlation times). A warning needs both ``p = erfc(|Z| / sqrt 2) <`` :data:`P_ALARM`
(so a bench the model describes warns once in a thousand campaigns per kind) and a median
relative change of the same sign at least :data:`MIN_RELATIVE_CHANGE` (a drift too small
to matter for a friction ratio is not reported, however many traces show it). A load-cell
offset drift that the fit models (offset model ``drift``) is in the model, so its
residuals carry none of it.

A creeping friction level is the exception: with the offset model ``drift`` chosen (by
BIC, as it is on such a bench) each trace's fitted offset drift takes up most of it, and
the plateaus' residuals keep little. What tells the two apart is the physics: a load
cell's drift is additive, the same newtons per second whatever the load, while a creeping
friction coefficient moves the force in proportion to it. So the fitted drift rates
``d_i`` [N/s] are regressed on the traces' OFF levels ``L_i`` [N], ``d_i = a + c L_i``
(ordinary least squares with an intercept, so a drift common to every pull stays in
``a``): ``c`` [1/s] is the relative creep rate, tested by its t statistic on ``n - 2``
degrees of freedom (the drift rates' scatter from pull to pull estimated by the
regression itself) at :data:`P_ALARM`, and reported when ``c`` times the median trace
duration reaches the OFF plateau's :data:`MIN_RELATIVE_CHANGE` (:class:`LevelCreep`).

When the fit models the drift (level model ``relaxing`` or ``creeping``,
:mod:`idtool._model._level_model`, chosen by BIC when the steady fit's plateaus drift),
the residuals carry little of it, and the tests above ask only whether the model left
some drift behind (their warnings then say so). The drift itself is still the bench's
and still reported, from the model's own parameters (:class:`ModelledDrift`, code
``drift_modelled``): the ON level's median rise towards its steady state and its time
constant (a fading horn), or the relative creep rate of the friction (a creeping
level), warned of when it reaches :data:`MIN_RELATIVE_CHANGE` (ON: the median rise;
OFF: the creep over the median trace), so a fading or creeping bench warns whichever
level model the fit chose.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from idtool._diagnostic import Diagnostic
from idtool._fit._free_levels import MIN_AT_LEVEL_S, _at_level_s
from idtool._fit._program import run_lm, unwhiten
from idtool._fit._result import FitResult

__all__ = [
    "DRIFT",
    "EDGE_S",
    "MIN_BLOCKS",
    "MIN_RELATIVE_CHANGE",
    "P_ALARM",
    "LevelCreep",
    "ModelledDrift",
    "PlateauDrift",
    "level_creep",
    "plateau_drift",
    "plateau_noise",
    "pooled_drift",
    "slope_and_se",
    "with_plateau_drift",
]

# How every warning that a level drifts within its plateaus begins (the report shows
# them as banners)
DRIFT = "a level drifts within its plateaus"
P_ALARM = 1e-3  # false-alarm rate of the pooled test, per kind (ON, OFF) and fit
# Smallest median relative change over a plateau worth a warning: 2% of an ON level (a
# friction ratio's own pull-to-pull scatter is ~3%), 0.3% of an OFF level (mu's ~0.7%).
MIN_RELATIVE_CHANGE = {"ON": 0.02, "OFF": 0.003}
EDGE_S = 0.1  # [s] trimmed at both ends of a plateau: the actuator's rounded corners
MIN_BLOCKS = 8  # a plateau shorter than this many blocks gives no usable slope


@dataclasses.dataclass(frozen=True)
class PlateauDrift:
    """The pooled trend of one kind of plateau (module docstring).

    ``n_plateaus`` tested, in ``n_traces`` traces; ``n_significant`` of them alone at
    ``|z| > 3.29`` (p < 0.001); ``n_same_sign`` with the sign of the pooled statistic;
    ``median_relative_change`` [-] over a plateau and ``median_duration_s`` [s];
    Stouffer's ``statistic`` and its two-sided ``p_value``; ``flagged`` whether it warns.
    """

    kind: str
    n_plateaus: int
    n_traces: int
    n_significant: int
    n_same_sign: int
    median_relative_change: float
    median_duration_s: float
    statistic: float
    p_value: float
    flagged: bool

    def to_dict(self) -> dict:
        return dataclasses.asdict(self)

    def sentence(self, level_model: str = "steady") -> str:
        """The warning, in physical terms (``level_model``: the fit's, which the last
        sentence names)."""
        level = "ON" if self.kind == "ON" else "OFF"
        verb = "rises" if self.median_relative_change > 0 else "falls"
        why = (
            "the horn may be fading (its amplitude dropping through the window)"
            if self.kind == "ON" and self.median_relative_change > 0
            else "the friction level may be creeping (webbing warming or wearing in)"
            if self.kind == "OFF"
            else "the reduction may be building up through the window"
        )
        message = (
            f"{DRIFT}: the {level} level {verb} by "
            f"{100 * abs(self.median_relative_change):.1f}% over "
            f"{self.median_duration_s:.1f} s (median) in {self.n_same_sign} of "
            f"{self.n_plateaus} {level} plateaus ({self.n_traces} traces; pooled z = "
            f"{self.statistic:+.1f}, p = {self.p_value:.2g}): {why}. "
            + (
                "The fit holds each level constant, so its levels are averages over the "
                "plateau and the friction ratios depend on the window's length"
                if level_model == "steady"
                else f"This is what the {level_model} level model left in the residuals"
            )
        )
        return Diagnostic(f"drift_{self.kind.lower()}", message, **self.to_dict())


@dataclasses.dataclass(frozen=True)
class LevelCreep:
    """The fitted offset drift rates against the OFF levels (module docstring): the
    relative creep rate ``rate_per_s`` [1/s] and its ``se``, the t ``statistic`` on
    ``n_traces - 2`` degrees of freedom and its two-sided ``p_value``, the relative change
    over the median trace duration ``median_duration_s`` [s], ``flagged`` whether it warns."""

    kind: str
    n_traces: int
    rate_per_s: float
    se: float
    statistic: float
    p_value: float
    median_relative_change: float
    median_duration_s: float
    flagged: bool

    def to_dict(self) -> dict:
        return dataclasses.asdict(self)

    def sentence(self) -> str:
        verb = "rises" if self.rate_per_s > 0 else "falls"
        message = (
            f"{DRIFT}: the friction level {verb} by {100 * abs(self.median_relative_change):.1f}% "
            f"over {self.median_duration_s:.1f} s (median trace), in proportion to the load: "
            f"the fitted load-cell offset drifts of the {self.n_traces} traces grow with their "
            f"OFF levels at {100 * self.rate_per_s:+.3f}%/s (t = {self.statistic:+.1f}, p = "
            f"{self.p_value:.2g}), where a load cell's drift would not depend on the load: "
            "the friction may be creeping (webbing warming or wearing in), not the offset"
        )
        return Diagnostic("drift_creep", message, **self.to_dict())


@dataclasses.dataclass(frozen=True)
class ModelledDrift:
    """The drift a level model (not ``steady``) represents, from its parameters (module
    docstring): ``model`` its name; ``kind`` "ON" (relaxing: ``median_rise`` [-] and its
    ``rise_range`` over the traces, ``time_constant_s`` [s] and its ``ci95``) or "OFF"
    (creeping: ``rate_per_s`` [1/s] and its ``ci95``, ``median_relative_change`` over the
    median trace of ``median_duration_s`` [s]); ``flagged`` whether it warns."""

    kind: str
    model: str
    flagged: bool
    median_rise: float = 0.0
    rise_range: tuple[float, float] = (0.0, 0.0)
    time_constant_s: float = 0.0
    rate_per_s: float = 0.0
    ci95: tuple[float, float] = (0.0, 0.0)
    median_relative_change: float = 0.0
    median_duration_s: float = 0.0

    def to_dict(self) -> dict:
        return dataclasses.asdict(self)

    def sentence(self) -> Diagnostic:
        lo, hi = self.ci95
        if self.kind == "ON":
            verb = "rises" if self.median_rise > 0 else "falls"
            why = (
                "the horn may be fading (its amplitude dropping through the window)"
                if self.median_rise > 0
                else "the reduction may be building up through the window"
            )
            message = (
                f"{DRIFT}: the ON level {verb} towards a steady state "
                f"{100 * abs(self.median_rise):.0f}% (median; {100 * self.rise_range[0]:+.0f}% "
                f"to {100 * self.rise_range[1]:+.0f}% over the traces) from its value at the "
                f"horn's switch-on, with time constant {self.time_constant_s:.2g} s [{lo:.2g}, "
                f"{hi:.2g}]: {why}. The {self.model} level model, chosen by BIC, follows it: "
                "the friction ratios the physics model gives are the cold horn's, at the "
                "window's start and the commanded amplitude; each trace's steady-state ratio "
                "is in fit.json (traces: friction_ratio_steady)"
            )
        else:
            verb = "rises" if self.rate_per_s > 0 else "falls"
            message = (
                f"{DRIFT}: the friction level {verb} by {100 * abs(self.rate_per_s):.2f}% of "
                f"itself per second of sliding [{100 * lo:+.2f}, {100 * hi:+.2f}] %/s, "
                f"{100 * abs(self.median_relative_change):.1f}% over the median trace "
                f"({self.median_duration_s:.1f} s): the friction may be creeping (webbing "
                f"warming or wearing in). The {self.model} level model, chosen by BIC, "
                "follows it: mu and the levels are their values at the pull's start, and "
                "the friction ratios (ON over OFF at the same moment) do not creep"
            )
        return Diagnostic("drift_modelled", message, **self.to_dict())


def modelled_drift(result: FitResult) -> ModelledDrift | None:
    """The drift ``result``'s level model represents (None for ``steady``)."""
    model = result.model
    name = model.level.name
    if name == "steady":
        return None
    d = model.data
    v = model.values(np.asarray(result.z, float))
    if "on_rise" in v:  # relaxing: the traces whose ON level is measured
        z = np.asarray(result.z, float)
        levels = np.asarray(run_lm(model, z, np.ones(z.size, bool), result.noise_state, 0).aux[0])
        measured = _at_level_s(model, z, levels) >= MIN_AT_LEVEL_S
        rise = np.asarray(v["on_rise"], float)[measured if measured.any() else slice(None)]
        tau = result.estimates["on_relax_time_s"]
        median = float(np.median(rise))
        return ModelledDrift(
            kind="ON",
            model=name,
            flagged=bool(abs(median) >= MIN_RELATIVE_CHANGE["ON"]),
            median_rise=median,
            rise_range=(float(rise.min()), float(rise.max())),
            time_constant_s=float(tau.estimate),
            ci95=(float(tau.ci95[0]), float(tau.ci95[1])),
        )
    rate = result.estimates["level_creep_per_s"]
    times, block_trace = np.asarray(d.block_time_s), np.asarray(d.block_trace)
    durations = [np.ptp(times[block_trace == i]) + d.block_s for i in range(d.n_traces)]
    duration = float(np.median(durations))
    change = float(rate.estimate) * duration
    return ModelledDrift(
        kind="OFF",
        model=name,
        flagged=bool(abs(change) >= MIN_RELATIVE_CHANGE["OFF"]),
        rate_per_s=float(rate.estimate),
        ci95=(float(rate.ci95[0]), float(rate.ci95[1])),
        median_relative_change=change,
        median_duration_s=duration,
    )


def level_creep(rates_n_s: np.ndarray, off_n: np.ndarray, duration_s: np.ndarray) -> LevelCreep:
    """:class:`LevelCreep` from the traces' fitted offset drift rates [N/s], OFF levels [N]
    and durations [s] (module docstring)."""
    from scipy.stats import t as student_t

    n = rates_n_s.size
    x = off_n - off_n.mean()
    sxx = float(x @ x)
    if n < 4 or sxx <= 0.0:  # no leverage: one load, or too few traces
        return LevelCreep("creep", n, 0.0, math.inf, 0.0, 1.0, 0.0, 0.0, False)
    c = float(x @ rates_n_s) / sxx
    e = rates_n_s - rates_n_s.mean() - c * x
    se = math.sqrt(float(e @ e) / (n - 2) / sxx)
    stat = c / se if se > 0.0 else math.inf
    p = float(2.0 * student_t.sf(abs(stat), n - 2))
    duration = float(np.median(duration_s))
    change = c * duration
    flagged = p < P_ALARM and abs(change) >= MIN_RELATIVE_CHANGE["OFF"]
    return LevelCreep("creep", n, c, se, stat, p, change, duration, bool(flagged))


def slope_and_se(time_s: np.ndarray, r: np.ndarray, phi: float, sigma: float):
    """OLS slope [N/s] of ``r`` [N] on ``time_s`` [s] and its standard error under AR(1)
    noise of coefficient ``phi`` and innovation sd ``sigma`` [N] on equally spaced points:
    ``Var(b) = c' R c / (c'c)^2``, ``R_ij = sigma^2 phi^|i-j| / (1 - phi^2)`` (module
    docstring)."""
    c = time_s - time_s.mean()
    cc = float(c @ c)
    b = float(c @ r) / cc
    lag = np.abs(np.subtract.outer(np.arange(c.size), np.arange(c.size)))
    var = sigma**2 / (1.0 - phi**2) * float(c @ (phi**lag) @ c) / cc**2
    return b, math.sqrt(var)


def pooled_drift(kind: str, z: np.ndarray, relative: np.ndarray, duration_s, n_traces: int):
    """:class:`PlateauDrift` from the plateaus' standardised slopes ``z``, relative changes
    ``relative`` [-] and durations ``duration_s`` [s] (module docstring)."""
    k = z.size
    if k == 0:
        return PlateauDrift(kind, 0, n_traces, 0, 0, 0.0, 0.0, 0.0, 1.0, False)
    stat = float(z.sum() / math.sqrt(k))
    p = float(math.erfc(abs(stat) / math.sqrt(2.0)))
    median = float(np.median(relative))
    sign = 1.0 if stat >= 0 else -1.0
    flagged = p < P_ALARM and np.sign(median) == sign and abs(median) >= MIN_RELATIVE_CHANGE[kind]
    return PlateauDrift(
        kind=kind,
        n_plateaus=k,
        n_traces=n_traces,
        n_significant=int(np.count_nonzero(np.abs(z) > 3.2905)),
        n_same_sign=int(np.count_nonzero(np.sign(z) == sign)),
        median_relative_change=median,
        median_duration_s=float(np.median(duration_s)),
        statistic=stat,
        p_value=p,
        flagged=bool(flagged),
    )


def _plateaus(result: FitResult, levels: np.ndarray) -> list[tuple[int, str, float, float]]:
    """(trace, kind, start [s], end [s]) of each plateau from the fitted timing and the
    levels ``(OFF, ON)`` [N] (module docstring), before trimming."""
    model, z = result.model, np.asarray(result.z, float)
    d = model.data
    v = {k: np.asarray(x) for k, x in model.values(z).items()}
    m = d.n_traces
    off, on = levels[:m], levels[m:]
    actuator = model.actuator_of(v)
    startup = model.actuator_of({**v, "slope_n_s": v["startup_slope_n_s"]})
    settle_up = np.asarray(startup.settle_time_s(off))
    settle = np.asarray(actuator.settle_time_s(np.abs(off - on)))
    measured = _at_level_s(model, z, levels) >= MIN_AT_LEVEL_S
    block_trace = np.asarray(d.block_trace)
    times = np.asarray(d.block_time_s)
    out = []
    for i in range(m):
        t_end = float(times[block_trace == i].max())
        pull = float(np.broadcast_to(v["pull_start_s"], (m,))[i])
        on_start = float(d.on_start_s[i] + np.broadcast_to(v["delay_on_s"], (m,))[i])
        on_end = float(d.on_end_s[i] + np.broadcast_to(v["delay_off_s"], (m,))[i])
        if not np.isfinite(on_start):  # no ON window: one OFF plateau
            out.append((i, "OFF", pull + float(settle_up[i]), t_end))
            continue
        out.append((i, "OFF", pull + float(settle_up[i]), on_start))
        if measured[i]:
            out.append((i, "ON", on_start + float(settle[i]), on_end))
        out.append((i, "OFF", on_end + float(settle[i]), t_end))
    return out


def plateau_drift(result: FitResult) -> dict[str, PlateauDrift | LevelCreep]:
    """The pooled ON and OFF plateau trends of ``result`` and, with the offset model
    ``drift``, the creep test on its drift rates (module docstring). NumPy on the host
    plus one run of the fit's compiled program for its block means."""
    model = result.model
    d = model.data
    z = np.asarray(result.z, float)
    # the fit's own program run for no step: whitened residuals (model - data) and levels
    fitted = run_lm(model, z, np.ones(z.size, bool), result.noise_state, 0)
    r = -unwhiten(np.asarray(fitted.residuals), result.noise_state, model)  # data - model [N]
    out = np.asarray(fitted.aux[0])
    times = np.asarray(d.block_time_s)
    block_trace = np.asarray(d.block_trace)
    half = 0.5 * d.block_s  # a block's time is its centre: keep whole blocks inside
    m = d.n_traces
    plateaus = []
    for i, kind, start, end in _plateaus(result, out):
        inside = (block_trace == i) & (times - half >= start + EDGE_S)
        inside &= times + half <= end - EDGE_S
        idx = np.flatnonzero(inside)
        if idx.size >= MIN_BLOCKS:
            plateaus.append((i, kind, idx))
    phi, sigma = plateau_noise([(times[idx], r[idx]) for _, _, idx in plateaus])
    found: dict[str, list[tuple[int, float, float, float]]] = {"ON": [], "OFF": []}
    for i, kind, idx in plateaus:
        t = times[idx]
        b, se = slope_and_se(t, r[idx], phi, sigma)
        level = out[i] if kind == "OFF" else out[m + i]
        duration = float(t[-1] - t[0] + d.block_s)
        found[kind].append((i, b / se, b * duration / level, duration))
    pooled: dict[str, PlateauDrift | LevelCreep] = {}
    for kind, rows in found.items():
        arr = np.array([row[1:] for row in rows]).reshape(-1, 3)
        n_traces = len({row[0] for row in rows})
        pooled[kind] = pooled_drift(kind, arr[:, 0], arr[:, 1], arr[:, 2], n_traces)
    values = model.values(z)
    if "offset_drift_n_s" in values:
        rates = np.broadcast_to(np.asarray(values["offset_drift_n_s"], float), (m,))
        durations = np.array([np.ptp(times[block_trace == i]) + d.block_s for i in range(m)])
        pooled["creep"] = level_creep(rates, out[:m], durations)
    return pooled


def plateau_noise(plateaus: list[tuple[np.ndarray, np.ndarray]]) -> tuple[float, float]:
    """AR(1) coefficient and innovation sd [N] of the residuals ``(times [s], r [N])`` of
    the plateaus, each with its own straight line removed, pooled (lag-1 products over
    squares). Not the fit's own ``phi``: the fit whitens the data a drift has left in its
    residuals, so a strong drift raises its ``phi`` towards 1 (0.99 on the simulated
    fading bench) and would hide itself in the slopes' standard errors. Within the
    plateaus, with their trends removed, the residuals are the load cell's noise."""
    num = den = ss = 0.0
    n = 0
    for t, r in plateaus:
        e = r - np.polyval(np.polyfit(t, r, 1), t)
        num += float(e[1:] @ e[:-1])
        den += float(e @ e)
        n += e.size - 2  # two parameters per line
    if den <= 0.0 or n <= 0:
        return 0.0, 0.0
    # Removing each line biases the lag-1 estimate low, by about (2 + 4 phi) / n for a
    # plateau of n blocks (Kendall's (1 + 3 phi) / n for a removed mean, plus a slope's
    # share); left in, the slopes' z came out 15% too wide (sd 1.15 on AR(1) noise of
    # phi 0.5 in 60-block plateaus), the false-alarm rate at p < 0.001 four times its level.
    mean_n = n / len(plateaus) + 2.0
    raw = num / den
    phi = min(max(raw + (2.0 + 4.0 * raw) / mean_n, 0.0), 0.95)
    for t, r in plateaus:
        e = r - np.polyval(np.polyfit(t, r, 1), t)
        ss += float(np.sum((e[1:] - phi * e[:-1]) ** 2))
    return phi, math.sqrt(ss / n)


def with_plateau_drift(result: FitResult) -> FitResult:
    """``result`` with :attr:`FitResult.plateau_drift` set and a warning (beginning with
    :data:`DRIFT`) for each kind of plateau whose level drifts, and for the drift its
    level model represents (``modelled``, :class:`ModelledDrift`)."""
    pooled: dict[str, PlateauDrift | LevelCreep | ModelledDrift] = {**plateau_drift(result)}
    level = result.model.level.name
    warnings = [
        p.sentence(level) if isinstance(p, PlateauDrift) else p.sentence()
        for p in pooled.values()
        if p.flagged
    ]
    modelled = modelled_drift(result)
    if modelled is not None:
        pooled["modelled"] = modelled
        if modelled.flagged:
            warnings.insert(0, modelled.sentence())
    return dataclasses.replace(result, plateau_drift=pooled, warnings=[*result.warnings, *warnings])
