"""idtool: identify friction-model parameters of ultrasonically lubricated contacts.

The public API, in the order of the pipeline (data -> model -> fit -> posterior ->
predict -> report); every name is documented in the README's "Python API" section and
``tests/test_api.py`` checks ``__all__`` against that list.

Importing idtool switches JAX to 64-bit floats: the cycle averages and the fits need
double precision (gradients are checked against finite differences at 1e-4).
"""

import jax as _jax

_jax.config.update("jax_enable_x64", True)


from idtool._data._dataset import Dataset, Rig, Trace, load_dataset  # noqa: E402
from idtool._data._example import example_dataset_path, example_params_path  # noqa: E402
from idtool._data._write import write_dataset  # noqa: E402
from idtool._errors import IdtoolError  # noqa: E402
from idtool._fit._fit import Estimate  # noqa: E402
from idtool._model._benchmodel import BenchModel, bench_model  # noqa: E402
from idtool._model._contact import (  # noqa: E402
    CycleAverage,
    cycle_average_curve,
    prescribed_cycle_average,
)
from idtool._model._coupling import (  # noqa: E402
    COUPLINGS,
    AbstractCoupling,
    ConstantCoupling,
    PowerLimitedCoupling,
)
from idtool._model._laws import FRICTION_LAWS, AbstractFrictionLaw, Coulomb, Dahl, LuGre  # noqa: E402
from idtool._model._limits import (  # noqa: E402
    coulomb_friction_ratio,
    dahl_small_lambda_friction_ratio,
)
from idtool._model._noise import NOISE_MODELS, AbstractNoise  # noqa: E402
from idtool._model._params import Param  # noqa: E402
from idtool._model._seed_study import SEED_FIGURES, plot_seed_study, seed_study  # noqa: E402
from idtool._model._transducer import (  # noqa: E402
    EnergyBalance,
    Transducer,
    TransducerSteadyState,
    simulate_transducer,
    table2,
    transducer_steady_state,
)
from idtool._posterior._prior import Prior  # noqa: E402
from idtool._posterior._sample import Posterior  # noqa: E402
from idtool._predict._predict import AmplitudeFor, Prediction  # noqa: E402
from idtool._predict._tables import Amplitudes, Predictions  # noqa: E402
from idtool._report._html import write_report  # noqa: E402
from idtool._simulate._params import BenchParams, load_bench_params  # noqa: E402
from idtool._simulate._simulate import BenchTruth, simulate_bench, write_simulation  # noqa: E402
from idtool._version import __version__  # noqa: E402
from idtool._workflow import Fit, fit, load_fit  # noqa: E402

__all__ = [
    "COUPLINGS",
    "FRICTION_LAWS",
    "NOISE_MODELS",
    "SEED_FIGURES",
    "AbstractCoupling",
    "AbstractFrictionLaw",
    "AbstractNoise",
    "AmplitudeFor",
    "Amplitudes",
    "BenchModel",
    "BenchParams",
    "BenchTruth",
    "ConstantCoupling",
    "Coulomb",
    "CycleAverage",
    "Dahl",
    "Dataset",
    "EnergyBalance",
    "Estimate",
    "Fit",
    "IdtoolError",
    "LuGre",
    "Param",
    "Posterior",
    "PowerLimitedCoupling",
    "Prediction",
    "Predictions",
    "Prior",
    "Rig",
    "Trace",
    "Transducer",
    "TransducerSteadyState",
    "__version__",
    "bench_model",
    "coulomb_friction_ratio",
    "cycle_average_curve",
    "dahl_small_lambda_friction_ratio",
    "example_dataset_path",
    "example_params_path",
    "fit",
    "load_bench_params",
    "load_dataset",
    "load_fit",
    "plot_seed_study",
    "prescribed_cycle_average",
    "seed_study",
    "simulate_bench",
    "simulate_transducer",
    "table2",
    "transducer_steady_state",
    "write_dataset",
    "write_report",
    "write_simulation",
]
