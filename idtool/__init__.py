"""idtool: identify friction-model parameters of ultrasonically lubricated contacts.

The public API, in the order of the pipeline (data -> model -> fit -> posterior ->
predict -> report); every name is documented in the README's "Python API" section and
``tests/test_api.py`` checks ``__all__`` against that list.

IMPORTING IDTOOL SWITCHES JAX TO 64-BIT FLOATS FOR THE WHOLE PROCESS
(``jax_enable_x64``), for every other user of JAX in it too. It must: the cycle averages,
the fits' normal equations and the likelihoods need double precision (gradients are
checked against finite differences at 1e-4; in 32 bits the Levenberg-Marquardt steps
stall at the float32 resolution of the loss, ~1e-7 of it), and idtool's arrays are made
in many places, by its users too (a ``Dataset`` built by hand, a ``BenchModel`` called
on ``jnp`` arrays, the README's script), before and after any one entry point: switched
on only inside ``idtool.fit`` (``jax.enable_x64`` as a context), an array made outside
it would be float32 and silently truncate the values passed in. A process that needs
JAX in 32 bits should run idtool in a process of its own (its command line, or
``multiprocessing``).
"""

import importlib
import os as _os
import sys as _sys
from typing import TYPE_CHECKING

# Before any module of the package creates an array. JAX itself is not imported here:
# it is most of ``import idtool``'s time (0.9 s of 1.0 s on 2 cores), and commands such
# as ``idtool validate`` or ``idtool --help`` do not need it. JAX reads the variable when
# it is first imported; if it already was, its configuration is switched instead.
_os.environ["JAX_ENABLE_X64"] = "1"
if "jax" in _sys.modules:
    _sys.modules["jax"].config.update("jax_enable_x64", True)

# JAX's CPU backend, when it starts, with one intra-op thread: jaxlib 0.10's batched
# LAPACK kernels deadlock a larger pool (idtool._xla_pool). Runs when JAX is imported.
from idtool import _xla_pool
from idtool._version import __version__

_xla_pool.install()

# Public name -> the private module defining it. Imported on first use (module
# __getattr__, PEP 562): ``import idtool`` costs a few milliseconds, and a command
# loads only what it uses (jax, equinox, pyarrow, pandas, matplotlib, arviz stay out of
# ``idtool --help``).
_LAZY = {
    "Dataset": "idtool._data._dataset",
    "Rig": "idtool._data._dataset",
    "Trace": "idtool._data._dataset",
    "TransducerSpec": "idtool._data._dataset",
    "load_dataset": "idtool._data._dataset",
    "example_dataset_path": "idtool._data._example",
    "example_params_path": "idtool._data._example",
    "import_daq": "idtool._data._import",
    "write_dataset": "idtool._data._write",
    "IdtoolError": "idtool._errors",
    "Estimate": "idtool._fit._result",
    "FitArtefact": "idtool._fit._artefact",
    "LawFit": "idtool._fit._artefact",
    "ModelSpec": "idtool._model._spec",
    "read_parameter_table": "idtool._fit._parameter_table",
    "ParameterSetting": "idtool._model._settings",
    "ACTUATORS": "idtool._model._actuator",
    "AbstractActuator": "idtool._model._actuator",
    "LagActuator": "idtool._model._actuator",
    "SlopeActuator": "idtool._model._actuator",
    "OFFSETS": "idtool._model._offset",
    "LEVEL_MODELS": "idtool._model._level_model",
    "AbstractLevelModel": "idtool._model._level_model",
    "SteadyLevel": "idtool._model._level_model",
    "RelaxingOnLevel": "idtool._model._level_model",
    "CreepingLevel": "idtool._model._level_model",
    "AbstractOffset": "idtool._model._offset",
    "ConstantOffset": "idtool._model._offset",
    "DriftingOffset": "idtool._model._offset",
    "BenchModel": "idtool._model._benchmodel",
    "bench_model": "idtool._model._benchmodel",
    "CycleAverage": "idtool._model._contact",
    "cycle_average_curve": "idtool._model._contact",
    "prescribed_cycle_average": "idtool._model._contact",
    "AbstractDirection": "idtool._model._directions",
    "DIRECTIONS": "idtool._model._directions",
    "transverse_cycle_average": "idtool._model._direction_transverse",
    "normal_friction_ratio": "idtool._model._direction_normal",
    "AbstractCoupling": "idtool._model._coupling",
    "COUPLINGS": "idtool._model._coupling",
    "ConstantCoupling": "idtool._model._coupling",
    "ExponentialCoupling": "idtool._model._coupling",
    "LoadPowerCoupling": "idtool._model._coupling",
    "PowerLimitedCoupling": "idtool._model._coupling",
    "SdofCoupling": "idtool._model._coupling",
    "sdof_detuning_n_m": "idtool._model._coupling_sdof",
    "sdof_loss_stiffness_n_m": "idtool._model._coupling_sdof",
    "on_friction_ratio": "idtool._model._bench",
    "AbstractFrictionLaw": "idtool._model._laws",
    "Coulomb": "idtool._model._laws",
    "Dahl": "idtool._model._laws",
    "FRICTION_LAWS": "idtool._model._laws",
    "LuGre": "idtool._model._laws",
    "coulomb_friction_ratio": "idtool._model._limits",
    "dahl_small_lambda_friction_ratio": "idtool._model._limits",
    "AbstractNoise": "idtool._model._noise",
    "NOISE_MODELS": "idtool._model._noise",
    "Param": "idtool._model._params",
    "SEED_FIGURES": "idtool._model._seed_study",
    "plot_seed_study": "idtool._model._seed_study",
    "seed_study": "idtool._model._seed_study",
    "EnergyBalance": "idtool._model._transducer",
    "Transducer": "idtool._model._transducer",
    "TransducerSteadyState": "idtool._model._transducer",
    "simulate_transducer": "idtool._model._transducer",
    "table2": "idtool._model._transducer",
    "transducer_steady_state": "idtool._model._transducer",
    "Prior": "idtool._posterior._prior",
    "Posterior": "idtool._posterior._posterior",
    "AmplitudeFor": "idtool._predict._amplitude",
    "Prediction": "idtool._predict._predict",
    "Amplitudes": "idtool._predict._tables",
    "Predictions": "idtool._predict._tables",
    "Validation": "idtool._predict._validation",
    "Plan": "idtool._plan._plan",
    "PlannedPull": "idtool._plan._plan",
    "write_report": "idtool._report._html",
    "Comparison": "idtool._report._compare",
    "compare_fits": "idtool._entry",
    "BenchParams": "idtool._simulate._params",
    "load_bench_params": "idtool._simulate._params",
    "BenchTruth": "idtool._simulate._truth",
    "simulate_bench": "idtool._simulate._simulate",
    "write_simulation": "idtool._simulate._simulate",
    "Fit": "idtool._workflow",
    "Study": "idtool._study._study",
    "study": "idtool._study._study",
    "fit": "idtool._entry",
    "load_fit": "idtool._entry",
    "Series": "idtool._data._series",
    "read_series": "idtool._data._series",
    "simulate_series": "idtool._simulate._series",
    "simulate_table": "idtool._simulate._table",
    "fit_law": "idtool._lawfit._api",
    "SeriesFit": "idtool._lawfit._result",
    "LevelsTable": "idtool._data._levels",
    "load_levels": "idtool._data._levels",
    "import_levels": "idtool._data._levels_read",
    "fit_levels": "idtool._levels._api",
    "LevelsFit": "idtool._levels._result",
    "LevelsPrediction": "idtool._levels._result",
    "LevelsPosterior": "idtool._levels._sample",
    "load_levels_fit": "idtool._levels._store",
    "TableComparison": "idtool._levels._compare",
    "LevelsPlan": "idtool._levels._plan",
}

# The one list of public names: __all__ is read from it, and the TYPE_CHECKING block
# below (for type checkers and IDEs) is checked against it by tests/test_api.py.
__all__ = ["__version__", *_LAZY]


def __getattr__(name: str):
    try:
        module = _LAZY[name]
    except KeyError:
        raise AttributeError(f"module 'idtool' has no attribute {name!r}") from None
    value = getattr(importlib.import_module(module), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_LAZY))


# For type checkers and IDEs: the names of _LAZY, imported eagerly, each as itself (an
# explicit re-export; __all__ is not a literal they can read). tests/test_api.py checks
# that it imports exactly _LAZY's names from their modules, and prints the block to
# paste when they differ. Kept out of isort, which splits aliased imports one a line.
# isort: off
if TYPE_CHECKING:
    from idtool._data._dataset import (
        Dataset as Dataset,
        load_dataset as load_dataset,
        Rig as Rig,
        Trace as Trace,
        TransducerSpec as TransducerSpec,
    )
    from idtool._data._example import (
        example_dataset_path as example_dataset_path,
        example_params_path as example_params_path,
    )
    from idtool._data._import import (
        import_daq as import_daq,
    )
    from idtool._data._levels import (
        LevelsTable as LevelsTable,
        load_levels as load_levels,
    )
    from idtool._data._levels_read import (
        import_levels as import_levels,
    )
    from idtool._data._series import (
        read_series as read_series,
        Series as Series,
    )
    from idtool._data._write import (
        write_dataset as write_dataset,
    )
    from idtool._entry import (
        compare_fits as compare_fits,
        fit as fit,
        load_fit as load_fit,
    )
    from idtool._errors import (
        IdtoolError as IdtoolError,
    )
    from idtool._fit._artefact import (
        FitArtefact as FitArtefact,
        LawFit as LawFit,
    )
    from idtool._fit._parameter_table import (
        read_parameter_table as read_parameter_table,
    )
    from idtool._fit._result import (
        Estimate as Estimate,
    )
    from idtool._lawfit._api import (
        fit_law as fit_law,
    )
    from idtool._lawfit._result import (
        SeriesFit as SeriesFit,
    )
    from idtool._levels._api import (
        fit_levels as fit_levels,
    )
    from idtool._levels._compare import (
        TableComparison as TableComparison,
    )
    from idtool._levels._plan import (
        LevelsPlan as LevelsPlan,
    )
    from idtool._levels._result import (
        LevelsFit as LevelsFit,
        LevelsPrediction as LevelsPrediction,
    )
    from idtool._levels._sample import (
        LevelsPosterior as LevelsPosterior,
    )
    from idtool._levels._store import (
        load_levels_fit as load_levels_fit,
    )
    from idtool._model._actuator import (
        AbstractActuator as AbstractActuator,
        ACTUATORS as ACTUATORS,
        LagActuator as LagActuator,
        SlopeActuator as SlopeActuator,
    )
    from idtool._model._bench import (
        on_friction_ratio as on_friction_ratio,
    )
    from idtool._model._benchmodel import (
        bench_model as bench_model,
        BenchModel as BenchModel,
    )
    from idtool._model._contact import (
        cycle_average_curve as cycle_average_curve,
        CycleAverage as CycleAverage,
        prescribed_cycle_average as prescribed_cycle_average,
    )
    from idtool._model._coupling import (
        AbstractCoupling as AbstractCoupling,
        ConstantCoupling as ConstantCoupling,
        COUPLINGS as COUPLINGS,
        ExponentialCoupling as ExponentialCoupling,
        LoadPowerCoupling as LoadPowerCoupling,
        PowerLimitedCoupling as PowerLimitedCoupling,
        SdofCoupling as SdofCoupling,
    )
    from idtool._model._direction_normal import (
        normal_friction_ratio as normal_friction_ratio,
    )
    from idtool._model._direction_transverse import (
        transverse_cycle_average as transverse_cycle_average,
    )
    from idtool._model._directions import (
        AbstractDirection as AbstractDirection,
        DIRECTIONS as DIRECTIONS,
    )
    from idtool._model._coupling_sdof import (
        sdof_detuning_n_m as sdof_detuning_n_m,
        sdof_loss_stiffness_n_m as sdof_loss_stiffness_n_m,
    )
    from idtool._model._laws import (
        AbstractFrictionLaw as AbstractFrictionLaw,
        Coulomb as Coulomb,
        Dahl as Dahl,
        FRICTION_LAWS as FRICTION_LAWS,
        LuGre as LuGre,
    )
    from idtool._model._level_model import (
        AbstractLevelModel as AbstractLevelModel,
        CreepingLevel as CreepingLevel,
        LEVEL_MODELS as LEVEL_MODELS,
        RelaxingOnLevel as RelaxingOnLevel,
        SteadyLevel as SteadyLevel,
    )
    from idtool._model._limits import (
        coulomb_friction_ratio as coulomb_friction_ratio,
        dahl_small_lambda_friction_ratio as dahl_small_lambda_friction_ratio,
    )
    from idtool._model._noise import (
        AbstractNoise as AbstractNoise,
        NOISE_MODELS as NOISE_MODELS,
    )
    from idtool._model._offset import (
        AbstractOffset as AbstractOffset,
        ConstantOffset as ConstantOffset,
        DriftingOffset as DriftingOffset,
        OFFSETS as OFFSETS,
    )
    from idtool._model._params import (
        Param as Param,
    )
    from idtool._model._seed_study import (
        plot_seed_study as plot_seed_study,
        SEED_FIGURES as SEED_FIGURES,
        seed_study as seed_study,
    )
    from idtool._model._settings import (
        ParameterSetting as ParameterSetting,
    )
    from idtool._model._spec import (
        ModelSpec as ModelSpec,
    )
    from idtool._model._transducer import (
        EnergyBalance as EnergyBalance,
        simulate_transducer as simulate_transducer,
        table2 as table2,
        Transducer as Transducer,
        transducer_steady_state as transducer_steady_state,
        TransducerSteadyState as TransducerSteadyState,
    )
    from idtool._plan._plan import (
        Plan as Plan,
        PlannedPull as PlannedPull,
    )
    from idtool._posterior._posterior import (
        Posterior as Posterior,
    )
    from idtool._posterior._prior import (
        Prior as Prior,
    )
    from idtool._predict._amplitude import (
        AmplitudeFor as AmplitudeFor,
    )
    from idtool._predict._predict import (
        Prediction as Prediction,
    )
    from idtool._predict._tables import (
        Amplitudes as Amplitudes,
        Predictions as Predictions,
    )
    from idtool._predict._validation import (
        Validation as Validation,
    )
    from idtool._report._compare import (
        Comparison as Comparison,
    )
    from idtool._report._html import (
        write_report as write_report,
    )
    from idtool._simulate._params import (
        BenchParams as BenchParams,
        load_bench_params as load_bench_params,
    )
    from idtool._simulate._series import (
        simulate_series as simulate_series,
    )
    from idtool._simulate._table import (
        simulate_table as simulate_table,
    )
    from idtool._simulate._simulate import (
        simulate_bench as simulate_bench,
        write_simulation as write_simulation,
    )
    from idtool._simulate._truth import (
        BenchTruth as BenchTruth,
    )
    from idtool._study._study import (
        Study as Study,
        study as study,
    )
    from idtool._workflow import (
        Fit as Fit,
    )
# isort: on
