"""The entry points of the public workflow: :func:`fit` a dataset into a
:class:`~idtool.Fit`, :func:`load_fit` one saved by :meth:`Fit.save`, and
:func:`compare_fits` fits or their folders. The top of the library, below only the
command line: the report stage below reads fits through interfaces of its own
(:class:`~idtool._report._comparison.FitToCompare`), never this module or the
:class:`Fit` class."""

from __future__ import annotations

import os
import time
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING

from idtool._data._dataset import Dataset, load_dataset
from idtool._data._select import select_traces
from idtool._errors import IdtoolError
from idtool._fit._parameter_table import parse_fix, read_parameter_table
from idtool._fit._run import fit_dataset
from idtool._fit._store import load_artefact
from idtool._model._names import BY_DESIGN, DEFAULT_DIRECTION
from idtool._model._noise import DEFAULT_NOISE
from idtool._model._settings import ParameterSetting
from idtool._report._compare import TARGETS, Comparison, compare, compare_request
from idtool._workflow import Fit

if TYPE_CHECKING:
    from idtool._levels._compare import TableComparison
    from idtool._levels._result import LevelsFit

__all__ = ["compare_fits", "fit", "load_fit"]


def fit(
    dataset: Dataset | str | os.PathLike,
    *,
    law: str = "dahl",
    coupling: str = BY_DESIGN,
    noise: str = DEFAULT_NOISE,
    seed: int = 0,
    starts: int = 8,
    compare_laws: bool = False,
    profile: bool = False,
    mains_hz: float | None = None,
    variability: bool = True,
    actuator: str = "auto",
    offset: str = "auto",
    level: str = "auto",
    progress: Callable[[str], None] | None = None,
    traces: str | Sequence[str] | None = None,
    fix: Mapping[str, float] | None = None,
    parameters: str | os.PathLike | Sequence[ParameterSetting] | None = None,
    direction: str = DEFAULT_DIRECTION,
) -> Fit:
    """Identify Kt, mu and the coupling from every trace of ``dataset`` (or those
    ``traces`` selects) at once.

    Args:
        dataset: a :class:`~idtool.Dataset` or the path of a v1 dataset folder.
        law: friction law, a name of :data:`idtool.FRICTION_LAWS` ("dahl", "lugre").
        coupling: a name of :data:`idtool.COUPLINGS`, "auto" (fit every coupling law,
            keep the lowest BIC) or "by-design" (default): "power-limited", the paper's
            finding, on a dataset pulled at one speed; where some load and amplitude
            were pulled at two or more speeds (which pin Kt whatever the law),
            "power-limited" and "load-power", the lower BIC kept.
        noise: a name of :data:`idtool.NOISE_MODELS` (default "ar1").
        seed: seeds the multi-start points; the same seed gives the same fit.
        starts: multi-start points.
        compare_laws: also fit every other friction law and rank them by BIC.
        profile: profile-likelihood intervals of the physical parameters.
        mains_hz: mains frequency [Hz]: block means span whole mains periods. None
            (default): ``rig.mains_frequency_hz`` of the dataset, else the hum found in
            the traces, else 50 Hz; the choice and its source are in ``fit.json``
            (``noise.mains_hz``, ``noise.mains_source``), a doubt in ``Fit.warnings``.
        variability: pull-to-pull scatter (of mu and of the friction ratio) and the
            physical model's discrepancy across operating points in every interval and
            band (default; estimated by REML, reported in ``fit.json``'s
            ``variability``). False gives the noise-only model, for comparison.
        actuator: how the pull force follows its target, a name of
            :data:`idtool.ACTUATORS` ("slope": constant slopes; "lag": a first-order lag
            with a rate limit), or "auto" (default: both, the lower BIC kept).
        offset: the load-cell offset within a trace, a name of :data:`idtool.OFFSETS`
            ("constant"; "drift": a linear drift per trace), or "auto" (default: both,
            the lower BIC kept).
        level: how the friction levels move within their plateaus, a name of
            :data:`idtool.LEVEL_MODELS` ("steady"; "relaxing": the ON level relaxes
            from its cold-horn value with a time constant, FR then reported at the
            window's start and at steady state; "creeping": the friction grows in
            proportion to itself through the pull), or "auto" (default: steady, and
            the others tried, nested in it, only where its plateaus drift; the lower
            BIC kept).
        progress: called with a line of text as each stage of the fit starts (each
            candidate model, the interval checks, the levels model); ``print`` shows
            them.
        traces: fit only the traces whose ids match these shell patterns (a list, or
            comma-separated; ``!`` excludes: ``"*,!*_T2.5"``), to hold the others out
            for :meth:`Fit.validate`; ``fit.json`` lists the fitted traces.
        fix: shared parameters held at a value, by name, physical units
            (``{"mu": 0.3}``): not estimated, not sampled, not counted in AIC/BIC.
        parameters: a PEtab-like parameter table (path; :func:`idtool.read_parameter_table`)
            or its settings (:class:`idtool.ParameterSetting`): fixed values, bounds,
            scales, starts and the sampler's priors. ``fit.json`` records them, so
            :func:`load_fit` and :meth:`Fit.sample` use them too.
        direction: the direction of vibration the contact model assumes, a name of
            :data:`idtool.DIRECTIONS`: "along" the sliding (default, the seed paper's
            model), "transverse" (in the contact plane, across the sliding) or "normal"
            (out of plane: the indentation oscillates). Every candidate model shares
            it; ``fit.json`` records it (``direction``). Not with the "sdof" coupling.
            "auto": every direction, each with every coupling law fitted, compared by
            BIC as the coupling laws are (``fit.json``'s ``directions``; predictions
            average the directions kept by their BIC weights, ``model_weights``); it
            costs a fit per direction, the transverse and normal ones slower.
    """
    if starts < 1:
        raise IdtoolError(f"starts = {starts}: give at least 1")
    started = time.perf_counter()
    if not isinstance(dataset, Dataset):
        dataset = load_dataset(Path(dataset))
    if traces is not None:
        dataset = select_traces(dataset, traces)
    settings: tuple[ParameterSetting, ...] = ()
    if isinstance(parameters, str | os.PathLike):
        settings = read_parameter_table(parameters)
    elif parameters is not None:
        settings = tuple(parameters)
    if fix:
        settings += parse_fix(f"{name}={value}" for name, value in fix.items())
    run = fit_dataset(
        dataset,
        law=law,
        coupling=coupling,
        seed=seed,
        n_starts=starts,
        compare_laws=compare_laws,
        profile=profile,
        mains_hz=mains_hz,
        noise=noise,
        variability=variability,
        actuator=actuator,
        offset=offset,
        level=level,
        progress=progress,
        settings=settings,
        direction=direction,
    )
    return Fit.from_run(dataset, run, seconds=time.perf_counter() - started)


def load_fit(path: str | os.PathLike) -> Fit:
    """Read a fit folder written by :meth:`Fit.save` (or ``idtool fit``), with its
    posterior if ``posterior.nc`` is beside it. The dataset must still be where the fit
    found it, unchanged (its sha256 is checked)."""
    return Fit(load_artefact(Path(path)), None, Path(path))


def compare_fits(
    fits: Sequence[Fit | LevelsFit | str | os.PathLike],
    load_n: float | Sequence[float] | None = None,
    amplitude: float | Sequence[float] | None = None,
    *,
    speed_m_s: float | None = None,
    targets: Sequence[float] = TARGETS,
    max_draws: int = 2000,
    seed: int = 0,
) -> Comparison | TableComparison:
    """Compare two or more fits (fit folders or :class:`~idtool.Fit`) at the loads
    ``load_n`` [N] x commanded amplitude fractions ``amplitude`` (default: the values
    every fit tested, else the first fit's) and ``speed_m_s`` [m/s] (default: the fits'
    common pull speed). The first fit is the reference: the probability that it reduces
    friction more than each other fit, from ``max_draws`` independent draws of each
    (posterior, else the fit's covariance: flagged), and the amplitude each needs for
    ``targets`` [% reduction]. Fits from different rigs are refused (IdtoolError).

    Fits of friction tables (:class:`~idtool.LevelsFit` or their folders, all of them)
    are compared at the conditions every table measured (:func:`~idtool._levels.
    _compare.compare_tables`; ``load_n`` and ``speed_m_s`` replace the tables' loads or
    speeds; ``amplitude`` and ``targets`` do not apply): a :class:`TableComparison`."""
    # the table kind's modules load here, not with this one: they import SciPy's
    # optimisers and scipy.special, which a fit's import path leaves to its background
    # thread (tests/test_cli_model.py)
    from idtool._levels._result import LevelsFit
    from idtool._levels._store import is_levels_fit

    tables = [
        isinstance(f, LevelsFit) or (not isinstance(f, Fit) and is_levels_fit(Path(f)))
        for f in fits
    ]
    if any(tables):
        return _compare_tables(fits, tables, load_n, amplitude, speed_m_s, targets, max_draws, seed)
    traces = [f for f in fits if not isinstance(f, LevelsFit)]
    labels, checked = compare_request(traces, targets, max_draws)
    loaded = [f if isinstance(f, Fit) else load_fit(f) for f in traces]
    return compare(
        loaded,
        labels,
        load_n,
        amplitude,
        speed_m_s=speed_m_s,
        targets=checked,
        max_draws=max_draws,
        seed=seed,
    )


def _compare_tables(fits, tables, load_n, amplitude, speed_m_s, targets, max_draws, seed):
    """:func:`compare_fits` of table fits: every one a table's, no trace-only option."""
    from idtool._levels._compare import compare_tables
    from idtool._levels._result import LevelsFit
    from idtool._levels._store import load_levels_fit

    if not all(tables):
        raise IdtoolError(
            "compare fits of one kind: "
            + ", ".join(str(f) for f, t in zip(fits, tables, strict=True) if not t)
            + " fitted bench traces, the others friction tables (kind: levels)"
        )
    if amplitude is not None or tuple(targets) != tuple(TARGETS):
        raise IdtoolError(
            "--amplitude and --targets apply to fits of bench traces: a table fit is compared "
            "at its tables' amplitudes [m] (give --load or --speed to move the conditions)"
        )
    loaded = [f if isinstance(f, LevelsFit) else load_levels_fit(f) for f in fits]
    labels = [f.table.name if isinstance(f, LevelsFit) else Path(f).resolve().name for f in fits]
    loads = None if load_n is None else list(_as_list(load_n))
    speeds = None if speed_m_s is None else list(_as_list(speed_m_s))
    return compare_tables(
        loaded, labels, load_n=loads, speed_m_s=speeds, max_draws=max_draws, seed=seed
    )


def _as_list(x) -> list[float]:
    return [float(v) for v in (x if isinstance(x, (list, tuple)) else [x])]
