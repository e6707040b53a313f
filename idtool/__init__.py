"""idtool: identify friction-model parameters of ultrasonically lubricated contacts.

Importing idtool switches JAX to 64-bit floats: the cycle averages and the fits need
double precision (gradients are checked against finite differences at 1e-4).
"""

import jax as _jax

_jax.config.update("jax_enable_x64", True)

from ._contact import CycleAverage, prescribed_cycle_average, reversal_phase  # noqa: E402
from ._laws import AbstractFrictionLaw, Coulomb, Dahl, LuGre  # noqa: E402

__version__ = "0.1.0"

__all__ = [
    "AbstractFrictionLaw",
    "Coulomb",
    "CycleAverage",
    "Dahl",
    "LuGre",
    "__version__",
    "prescribed_cycle_average",
    "reversal_phase",
]
