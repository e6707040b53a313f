"""The sdof law's detuning where the dataset does not give it: a profile, and what it says.

Without ``rig.transducer`` the sdof coupling (:mod:`idtool._model._coupling_sdof`) takes
the horn as driven at its resonance, ``D = 0``. Whether the traces could tell otherwise
is a question for the likelihood: the chosen fit is refitted with ``D`` held on a grid
of fixed values, every other parameter free (the gain takes up the drive's magnitude),
same noise state (AR(1): ``phi``), each point warm-started from its neighbour's optimum, as
:func:`idtool._fit._intervals.profile_parameter` does. The rise of ``-2 log L`` over
the best point is the profile; its 95% interval is where the rise stays below 3.84,
interpolated linearly between grid points (so no finer than the grid).

The grid is physical, not a multiple of the fitted ``R`` (which runs to its bound
where the friction barely loads the horn): ``D = m (w^2 - wn^2)`` of a 1 kg stack at
20 kHz is 3e7, 3e8 and 3e9 N/m for a natural frequency 0.1%, 1% and 10% off the drive,
so ``0, +-1e7, +-1e8, +-3e8, +-1e9, +-1e10`` N/m span a well-tuned welder to one far
off resonance, either side.

* The profile stays below 3.84 over the whole grid: the data cannot tell the detuning,
  ``D = 0`` stays an assumption, and the fit says so with the interval's reach.
* The profile excludes ``D = 0`` (the best point beats resonance by more than 3.84):
  the data inform the detuning. The model with ``D`` estimated is then polished from
  the profile's best point (:func:`detuned_fit`) and replaces the fit if its BIC is
  lower, with a note of what resonance cost; otherwise the fit warns, and says how to
  lift the assumption (``rig.transducer``, or ``detuning_n_m`` freed in a parameter
  table). Either way ``D`` from bench traces alone rests on the contact model's
  harmonics, which a transducer's datasheet fixes independently: the note says so.

Each grid point is refitted from two starts, its neighbour's optimum and one where the
friction loads the horn (:func:`_loaded_start`), the better kept; all are
Levenberg-Marquardt steps of one compiled program (the model with ``D`` estimated, ``D``
masked).
"""

from __future__ import annotations

import dataclasses

import numpy as np

from idtool._fit._fit import fit_model
from idtool._fit._intervals import Profile, profile_interval
from idtool._fit._program import run_lm
from idtool._fit._result import FitResult
from idtool._model._benchmodel import BenchModel, bench_model
from idtool._model._settings import ParameterSetting

__all__ = [
    "DETUNING",
    "detuned_fit",
    "detuning_assumed",
    "detuning_profile",
    "detuning_sentence",
]

DETUNING = "detuning_n_m"
# D [N/m] on the grid (module docstring)
GRID_N_M = (-1e10, -1e9, -3e8, -1e8, -1e7, 0.0, 1e7, 1e8, 3e8, 1e9, 1e10)
_CHI2_95 = 3.84


def detuning_assumed(result: FitResult) -> bool:
    """Whether ``result``'s model holds ``D`` at an assumption (no ``rig.transducer``
    and no user setting)."""
    return any(
        s.name == DETUNING and not s.estimate and s.source.startswith("assumed")
        for s in result.model.settings
    )


def _free_model(result: FitResult) -> BenchModel:
    """``result``'s model with ``D`` estimated."""
    model = result.model
    settings = tuple(s for s in model.settings if s.name != DETUNING)
    return bench_model(
        model.data,
        law=model.law,
        coupling=model.coupling,
        noise=type(model.noise),
        actuator=model.actuator,
        offset=model.offset,
        level=model.level,
        settings=(*settings, ParameterSetting(DETUNING, source="identified from the traces")),
        direction=model.direction,
    )


def detuning_profile(result: FitResult, grid_n_m=GRID_N_M) -> tuple[Profile, np.ndarray]:
    """Profile likelihood of ``D`` [N/m] over ``grid_n_m`` (ascending, with 0; module
    docstring), ``result`` an sdof fit with ``D`` held at 0; and the best grid point's
    parameters (``z`` of the model with ``D`` estimated)."""
    free = _free_model(result)
    i = free.names.index(DETUNING)
    spec = free.params[i]
    held = dict(zip(result.model.names, np.asarray(result.z), strict=True))
    z0 = np.array([held.get(n, spec.internal(0.0)) for n in free.names])
    mask = np.ones(z0.size, bool)
    mask[i] = False
    values = np.asarray(grid_n_m, float)
    sigma2 = result.rss / (result.n_data - result.z.size)
    delta = np.empty(values.size)
    at = [z0] * values.size
    mid = int(np.argmin(np.abs(values)))
    loaded = _loaded_start(free, z0, result)
    # outwards from D = 0 either side, each point warm-started from its neighbour's
    # optimum; D = 0 is fitted once (the downward pass starts from its optimum, as it
    # would from the same two starts again)
    for order in (range(mid, values.size), range(mid - 1, -1, -1)):
        z = z0 if order.start == mid else at[mid]
        for j in order:
            outs = []
            for start in (z.copy(), loaded.copy()):
                start[i] = spec.internal(float(values[j]))
                outs.append(run_lm(free, start, mask, result.noise_state, 100))
            best = min(outs, key=lambda o: float(o.loss))
            delta[j] = (2.0 * float(best.loss) - result.rss) / sigma2
            z = at[j] = np.asarray(best.z)
    delta = delta - min(float(delta.min()), 0.0)  # from the best point on the grid
    profile = Profile(DETUNING, values, delta, profile_interval(values, delta, _CHI2_95))
    return profile, at[int(np.argmin(delta))]


def detuned_fit(result: FitResult, z_best: np.ndarray) -> FitResult:
    """The fit with ``D`` estimated, polished from the profile's best point ``z_best``
    (as a nested model is: :func:`idtool._fit._fit.fit_model`'s ``start_from``)."""
    free = _free_model(result)
    # the multi-start's optima (physical z, reported with the fit) at D = 0, in the
    # free model's order
    held_names = result.model.physical_names
    zero = free.params[free.names.index(DETUNING)].internal(0.0)

    def widened(o: dict) -> dict:
        by_name = dict(zip(held_names, np.asarray(o["z"]), strict=True))
        return o | {"z": np.array([by_name.get(n, zero) for n in free.physical_names])}

    optima = [widened(o) for o in result.optima]
    start = dataclasses.replace(result, model=free, z=np.asarray(z_best), optima=optima)
    m = result.model
    return fit_model(
        m.data,
        m.law.name,
        m.coupling.name,
        noise=m.noise.name,
        actuator=m.actuator.name,
        start_from=start,
        offset=m.offset.name,
        settings=free.settings,
        level=m.level.name,
        direction=m.direction.name,
    )


def _loaded_start(free, z0: np.ndarray, result: FitResult) -> np.ndarray:
    """``z0`` with ``R`` where the friction loads the horn: the friction's fundamental
    per unit amplitude, ``(4 / pi) mu N / a`` at the mean load and the fitted free
    amplitude at the mean command. A fit held at ``D = 0`` on a detuned horn's traces
    can run to ``R -> inf`` (the constant law, where ``D`` no longer matters), and
    warm starts from there would find the profile flat; each point also starts here."""
    data, e = free.data, result.estimates
    amplitude_m = e["coupling_gain"].estimate * float(np.mean(data.op_alpha)) * data.max_amplitude_m
    load_n = float(np.mean(data.normal_load_n))
    r_n_m = 4.0 / np.pi * e["mu"].estimate * load_n / max(amplitude_m, 1e-12)
    j = free.names.index("loss_stiffness_n_m")
    out = z0.copy()
    out[j] = free.params[j].internal(float(np.clip(r_n_m, 1e4, 1e13)))
    return out


def detuning_sentence(
    profile: Profile, held: FitResult, detuned: FitResult | None = None
) -> tuple[str, bool]:
    """What the profile says, and whether it is a warning: the traces exclude ``D = 0``
    and no ``detuned`` fit (``D`` estimated) beat ``held`` (``D = 0``) on BIC."""
    at_zero = float(np.interp(0.0, profile.values, profile.delta))
    lo, hi = profile.ci95
    if detuned is not None:
        e = detuned.estimates[DETUNING]
        return (
            f"the transducer's detuning identified from the traces (no rig.transducer): "
            f"D = {e.estimate:.3g} N/m, 95% [{e.ci95[0]:.3g}, {e.ci95[1]:.3g}] (the "
            f"profile over a grid of D found this basin, best grid point "
            f"{profile.values[int(np.argmin(profile.delta))]:.3g} N/m); driven at "
            f"resonance (D = 0) the fit was worse by "
            f"{at_zero:.1f} in -2 log L and {held.bic - detuned.bic:.1f} in BIC. D rests "
            f"on the contact model's harmonics here; rig.transducer (modal mass, natural "
            f"frequency) would fix it independently",
            False,
        )
    if at_zero >= _CHI2_95:
        best = float(profile.values[int(np.argmin(profile.delta))])
        return (
            f"the traces argue against a horn driven at resonance (the sdof law's "
            f"assumption without rig.transducer): the detuning profile rises "
            f"{at_zero:.1f} in -2 log L from its best point (D = {best:.3g} N/m) to D = 0; "
            f"give rig.transducer (modal mass, natural frequency), or free detuning_n_m "
            f"in a parameter table",
            True,
        )
    if profile.delta[0] < _CHI2_95 and profile.delta[-1] < _CHI2_95:
        return (
            f"the traces cannot tell the transducer's detuning: its profile stays within "
            f"3.84 of its best from D = {profile.values[0]:.3g} to {profile.values[-1]:.3g} "
            f"N/m; D = 0 (driven at resonance) is an assumption that rig.transducer "
            f"would replace",
            False,
        )
    return (
        f"the transducer's detuning from the traces: 95% profile interval "
        f"[{lo:.3g}, {hi:.3g}] N/m, D = 0 (driven at resonance, assumed) inside it",
        False,
    )
