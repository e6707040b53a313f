"""idtool: identify friction-model parameters of ultrasonically lubricated contacts.

Importing idtool switches JAX to 64-bit floats: the cycle averages and the fits need
double precision (gradients are checked against finite differences at 1e-4).
"""

import jax as _jax

_jax.config.update("jax_enable_x64", True)

from ._contact import (  # noqa: E402
    CycleAverage,
    cycle_average_curve,
    prescribed_cycle_average,
    reversal_phase,
)
from ._dataset import Dataset, Rig, Trace, load_dataset  # noqa: E402
from ._dataset_write import write_dataset  # noqa: E402
from ._example import example_dataset_path, example_params_path  # noqa: E402
from ._laws import AbstractFrictionLaw, Coulomb, Dahl, LuGre  # noqa: E402
from ._likelihood import NOISE_MODELS  # noqa: E402
from ._posterior_store import load_posterior, write_posterior  # noqa: E402
from ._predict import (  # noqa: E402
    AmplitudeFor,
    Prediction,
    amplitude_for_reduction,
    predict_friction_ratio,
    prediction_draws,
)
from ._prior import Prior, read_priors  # noqa: E402
from ._sample import Posterior, sample_posterior  # noqa: E402
from ._sim_params import BenchParams, load_bench_params  # noqa: E402
from ._simulate import BenchTruth, TraceTruth, simulate_bench, write_simulation  # noqa: E402
from ._transducer import (  # noqa: E402
    EnergyBalance,
    Transducer,
    TransducerSteadyState,
    simulate_transducer,
    table2,
    transducer_steady_state,
)

__version__ = "0.1.0"

__all__ = [
    "NOISE_MODELS",
    "AbstractFrictionLaw",
    "AmplitudeFor",
    "BenchParams",
    "BenchTruth",
    "Coulomb",
    "CycleAverage",
    "Dahl",
    "Dataset",
    "EnergyBalance",
    "LuGre",
    "Posterior",
    "Prediction",
    "Prior",
    "Rig",
    "Trace",
    "TraceTruth",
    "Transducer",
    "TransducerSteadyState",
    "__version__",
    "amplitude_for_reduction",
    "cycle_average_curve",
    "example_dataset_path",
    "example_params_path",
    "load_bench_params",
    "load_dataset",
    "load_posterior",
    "predict_friction_ratio",
    "prediction_draws",
    "prescribed_cycle_average",
    "read_priors",
    "reversal_phase",
    "sample_posterior",
    "simulate_bench",
    "simulate_transducer",
    "table2",
    "transducer_steady_state",
    "write_dataset",
    "write_posterior",
    "write_simulation",
]
