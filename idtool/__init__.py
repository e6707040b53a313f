"""idtool: identify friction-model parameters of ultrasonically lubricated contacts.

The public API, in the order of the pipeline (data -> model -> fit -> posterior ->
predict -> report); every name is documented in the README's "Python API" section and
``tests/test_api.py`` checks ``__all__`` against that list.

Importing idtool switches JAX to 64-bit floats: the cycle averages and the fits need
double precision (gradients are checked against finite differences at 1e-4).
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

from idtool._version import __version__

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
    "write_report": "idtool._report._html",
    "Comparison": "idtool._report._compare",
    "compare_fits": "idtool._entry",
    "BenchParams": "idtool._simulate._params",
    "load_bench_params": "idtool._simulate._params",
    "BenchTruth": "idtool._simulate._truth",
    "simulate_bench": "idtool._simulate._simulate",
    "write_simulation": "idtool._simulate._simulate",
    "Fit": "idtool._workflow",
    "fit": "idtool._entry",
    "load_fit": "idtool._entry",
}

__all__ = [
    "ACTUATORS",
    "COUPLINGS",
    "FRICTION_LAWS",
    "LEVEL_MODELS",
    "NOISE_MODELS",
    "OFFSETS",
    "SEED_FIGURES",
    "AbstractActuator",
    "AbstractCoupling",
    "AbstractFrictionLaw",
    "AbstractLevelModel",
    "AbstractNoise",
    "AbstractOffset",
    "AmplitudeFor",
    "Amplitudes",
    "BenchModel",
    "BenchParams",
    "BenchTruth",
    "Comparison",
    "ConstantCoupling",
    "ConstantOffset",
    "Coulomb",
    "CreepingLevel",
    "CycleAverage",
    "Dahl",
    "Dataset",
    "DriftingOffset",
    "EnergyBalance",
    "Estimate",
    "ExponentialCoupling",
    "Fit",
    "IdtoolError",
    "LagActuator",
    "LoadPowerCoupling",
    "LuGre",
    "Param",
    "ParameterSetting",
    "Posterior",
    "PowerLimitedCoupling",
    "Prediction",
    "Predictions",
    "Prior",
    "RelaxingOnLevel",
    "Rig",
    "SdofCoupling",
    "SlopeActuator",
    "SteadyLevel",
    "Trace",
    "Transducer",
    "TransducerSpec",
    "TransducerSteadyState",
    "Validation",
    "__version__",
    "bench_model",
    "compare_fits",
    "coulomb_friction_ratio",
    "cycle_average_curve",
    "dahl_small_lambda_friction_ratio",
    "example_dataset_path",
    "example_params_path",
    "fit",
    "import_daq",
    "load_bench_params",
    "load_dataset",
    "load_fit",
    "on_friction_ratio",
    "plot_seed_study",
    "prescribed_cycle_average",
    "read_parameter_table",
    "sdof_detuning_n_m",
    "sdof_loss_stiffness_n_m",
    "seed_study",
    "simulate_bench",
    "simulate_transducer",
    "table2",
    "transducer_steady_state",
    "write_dataset",
    "write_report",
    "write_simulation",
]


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


if TYPE_CHECKING:  # for type checkers and IDEs: the same names, imported eagerly
    from idtool._data._dataset import Dataset, Rig, Trace, TransducerSpec, load_dataset
    from idtool._data._example import example_dataset_path, example_params_path
    from idtool._data._import import import_daq
    from idtool._data._write import write_dataset
    from idtool._entry import compare_fits, fit, load_fit
    from idtool._errors import IdtoolError
    from idtool._fit._parameter_table import read_parameter_table
    from idtool._fit._result import Estimate
    from idtool._model._actuator import ACTUATORS, AbstractActuator, LagActuator, SlopeActuator
    from idtool._model._bench import on_friction_ratio
    from idtool._model._benchmodel import BenchModel, bench_model
    from idtool._model._contact import CycleAverage, cycle_average_curve, prescribed_cycle_average
    from idtool._model._coupling import (
        COUPLINGS,
        AbstractCoupling,
        ConstantCoupling,
        ExponentialCoupling,
        LoadPowerCoupling,
        PowerLimitedCoupling,
        SdofCoupling,
    )
    from idtool._model._coupling_sdof import sdof_detuning_n_m, sdof_loss_stiffness_n_m
    from idtool._model._laws import FRICTION_LAWS, AbstractFrictionLaw, Coulomb, Dahl, LuGre
    from idtool._model._level_model import (
        LEVEL_MODELS,
        AbstractLevelModel,
        CreepingLevel,
        RelaxingOnLevel,
        SteadyLevel,
    )
    from idtool._model._limits import coulomb_friction_ratio, dahl_small_lambda_friction_ratio
    from idtool._model._noise import NOISE_MODELS, AbstractNoise
    from idtool._model._offset import OFFSETS, AbstractOffset, ConstantOffset, DriftingOffset
    from idtool._model._params import Param
    from idtool._model._seed_study import SEED_FIGURES, plot_seed_study, seed_study
    from idtool._model._settings import ParameterSetting
    from idtool._model._transducer import (
        EnergyBalance,
        Transducer,
        TransducerSteadyState,
        simulate_transducer,
        table2,
        transducer_steady_state,
    )
    from idtool._posterior._posterior import Posterior
    from idtool._posterior._prior import Prior
    from idtool._predict._amplitude import AmplitudeFor
    from idtool._predict._predict import Prediction
    from idtool._predict._tables import Amplitudes, Predictions
    from idtool._predict._validation import Validation
    from idtool._report._compare import Comparison
    from idtool._report._html import write_report
    from idtool._simulate._params import BenchParams, load_bench_params
    from idtool._simulate._simulate import simulate_bench, write_simulation
    from idtool._simulate._truth import BenchTruth
    from idtool._workflow import Fit
