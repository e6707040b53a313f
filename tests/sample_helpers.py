"""Small simulated fits shared by the posterior and prediction tests (fitted once per run).

The design: loads 270 and 670 N (450 N is held out), amplitudes 50% and 70%, ON times
1 s and 2 s, 1.5 s of sliding before and after: 8 traces, about 1100 block means. And
:func:`random_arrow`, the arrowhead normal equations of a random block-sparse Jacobian
(the solver's and the covariance's tests).
"""

from __future__ import annotations

import functools
import json

import numpy as np

import idtool
from idtool._fit._arrow import Arrow
from idtool._fit._run import FitRun, fit_dataset
from idtool._simulate._params import BenchParams
from idtool._simulate._simulate import operating_point

COVERAGE_SEEDS = tuple(range(6))
HELD_OUT_LOAD = 450.0
AMPLITUDES = (0.5, 0.7)


def small_params() -> dict:
    params = json.loads(idtool.example_params_path().read_text())
    e = params["experiments"]
    e["normal_loads_n"] = [270.0, 670.0]
    e["amplitude_fractions"] = list(AMPLITUDES)
    e["on_durations_s"] = [1.0, 2.0]
    e["sliding_before_s"] = 1.5
    e["sliding_after_s"] = 1.5
    return params


def truth() -> dict[str, float]:
    p = small_params()
    return {
        "Kt": p["contact"]["contact_stiffness_n_m"],
        "mu": p["contact"]["friction_coefficient"],
        "coupling_gain": p["coupling"]["gain"],
        "power_load_n": p["coupling"]["power_load_n"],
        "slope_n_s": p["actuator"]["slope_n_s"],
        "startup_slope_n_s": p["actuator"]["startup_slope_n_s"],
    }


def true_friction_ratio(load_n: float, alpha: float) -> float:
    bp = BenchParams.from_dict(small_params())
    return operating_point(bp, load_n, alpha)["friction_ratio"]


@functools.cache
def small_fit(seed: int) -> tuple[idtool.Dataset, FitRun]:
    """The simulated dataset of ``seed`` and its fit (cached for the whole session)."""
    dataset, _ = idtool.simulate_bench(small_params(), seed=seed)
    # the traces' own likelihood (noise models, nuisances) is what these tests check
    return dataset, fit_dataset(dataset, seed=0, variability=False)


def two_trace_data():
    """Block means of two short traces at one operating point (450 N, 50%; ON 0.5 s and
    1 s): small enough for dense-matrix checks of the likelihood algebra."""
    from idtool._data._blocks import prepare_fit_data

    params = json.loads(idtool.example_params_path().read_text())
    e = params["experiments"]
    e.update(normal_loads_n=[450.0], amplitude_fractions=[0.5], on_durations_s=[0.5, 1.0])
    e.update(sliding_before_s=1.0, sliding_after_s=1.0)
    dataset, _ = idtool.simulate_bench(params, seed=2)
    return prepare_fit_data(dataset, periods_per_block=2)


def random_arrow(
    seed: int = 0,
    s: int = 3,
    m: int = 5,
    nb: int = 4,
    rows: int = 12,
    zero: tuple[int, int] | None = None,
) -> Arrow:
    """Normal equations (NumPy) of a random block-sparse J: ``s`` shared parameters and
    ``m`` traces of ``rows`` residuals and ``nb`` nuisances each, well conditioned
    unless ``zero`` = (trace, slot) names a nuisance that moves no residual (a zero
    column, as a parameter the data do not move)."""
    rng = np.random.default_rng(seed)
    js, jb = rng.standard_normal((m, rows, s)), rng.standard_normal((m, rows, nb))
    if zero is not None:
        jb[zero[0], :, zero[1]] = 0.0
    r = rng.standard_normal((m, rows))
    return Arrow(
        a=np.einsum("mns,mnt->st", js, js),
        b=np.einsum("mns,mnb->msb", js, jb),
        d=np.einsum("mnb,mnc->mbc", jb, jb),
        gs=np.einsum("mns,mn->s", js, r),
        gb=np.einsum("mnb,mn->mb", jb, r),
    )
