"""The one compiled Levenberg-Marquardt program every step of a fit runs: each start,
polish, AR(1) round, interval check and profile point, of every dataset of about the
same length and the same laws (its blocks padded to a bucketed count), and the figures'
prediction at the optimum (the program run for no step).
"""

from __future__ import annotations

import functools
import math

import equinox as eqx
import jax
import numpy as np

from idtool._data._blocks import FitData, padded_size
from idtool._fit._lm import LMResult, levenberg_marquardt
from idtool._model._benchmodel import BenchModel

__all__ = ["lm_arguments", "lm_program", "prediction_at", "run_lm", "unwhiten"]

# XLA's newer CPU fusion emitters compile the fit's programs ~30% slower for the same
# run time (2.6 s vs 1.9 s for the LM loop on the example; benchmarks/bench_fit.py);
# LLVM's optimisation level 1 instead of 2 compiles it in 1.19 s instead of 1.35 s and
# runs 20 steps in 83 ms as before (level 0: 0.58 s, but 235 ms).
_COMPILE = {"xla_cpu_use_fusion_emitters": False, "xla_backend_optimization_level": 1}


@functools.partial(jax.jit, compiler_options=_COMPILE)
def lm_program(model: BenchModel, z0, mask, phi, max_steps) -> LMResult:
    """The compiled program of :func:`run_lm` (its model already padded)."""
    return levenberg_marquardt(model.normal_equations, z0, phi, mask, max_steps)


def run_lm(model: BenchModel, z0, mask, phi, max_steps) -> LMResult:
    """Levenberg-Marquardt on the AR(1)-whitened residuals of ``model``
    (:meth:`BenchModel.normal_equations`) over the parameters in ``mask``, returning
    them with the per-trace levels. The model is an argument, not a constant, and its
    blocks are padded to :func:`~idtool._data._blocks.padded_size` (residuals 0 there,
    cut off again here): one compiled program serves every start, polish, AR(1) round,
    profile point and every dataset of about the same length and the same laws."""
    n = model.data.force_n.shape[0]
    out = lm_program(_padded(model), z0, mask, phi, max_steps)
    # cut in NumPy: a JAX slice would be one more program to compile for every n
    return eqx.tree_at(lambda o: o.residuals, out, np.asarray(out.residuals)[:n])


def lm_arguments(model: BenchModel) -> tuple:
    """Arguments of :func:`lm_program` of the types :func:`run_lm`'s calls for ``model``
    give it, its blocks padded (for compiling ahead:
    :class:`~idtool._fit._prefetch.CompileAhead`)."""
    z = np.asarray(model.z0(), float)
    return (_padded(model), z, np.ones(z.size, bool), 0.0, 0)


def _padded(model: BenchModel) -> BenchModel:
    """``model`` on its blocks padded to :func:`~idtool._data._blocks.padded_size`."""
    return model.padded(padded_size(model.data.force_n.shape[0]))


def prediction_at(model: BenchModel, z: np.ndarray, phi: float) -> tuple[np.ndarray, np.ndarray]:
    """The model's block means [N] at ``z`` and their AR(1)-whitened residuals, from the
    fit's own compiled program run for no step (no program of their own to trace,
    compile or load: 0.4 s of a repeated fit's figures)."""
    out = run_lm(model, np.asarray(z, float), np.ones(np.size(z), bool), phi, 0)
    w = np.asarray(out.residuals)
    return np.asarray(model.data.force_n) + unwhiten(w, phi, model.data), w


def unwhiten(w: np.ndarray, phi: float, data: FitData) -> np.ndarray:
    """Residuals ``e`` from AR(1)-whitened ones (inverse of BenchModel.residuals'
    whitening): ``e_1 = w_1 / sqrt(1 - phi^2)``, ``e_t = w_t + phi e_(t-1)``."""
    e = np.array(w, float)
    first = np.asarray(data.first)
    for t in range(e.size):
        if first[t]:
            e[t] = w[t] / math.sqrt(1.0 - phi**2)
        else:
            e[t] = w[t] + phi * e[t - 1]
    return e
