"""One task of a simulation study: simulate a drawn truth, fit it, score it.

:func:`run_task` is what a Dask worker runs (a top-level function of plain arguments,
so any worker process can import it): the truth's bench simulated on the design with the
task's seed, fitted with the defaults (``idtool.fit``'s, or the study's fit options),
optionally sampled with the defaults (until converged; minutes a task), then scored:

* each physical parameter's estimate, 95% interval and whether the truth is inside;
  its SBC rank, the number of the fit's draws (:data:`RANK_DRAWS` of them: the
  posterior's after sampling, else Gaussian on the covariance) below the truth
  (Talts et al. 2018, arXiv:1804.06788: uniform on 0..L for calibrated draws);
* the FR band (median, 95% interval, half-width [FR]) at each target and whether the
  true FR (:func:`idtool._simulate._simulate.true_friction_ratio`, without scatter) is
  inside;
* the chosen coupling law and each law's weight; with ``before`` (a study of a plan for
  the goal ``laws``) also each law's weight from the fit of the design's existing pulls
  alone (the same simulated traces without the planned ones): whether the pulls moved
  the weight towards the truth's law;
* the seconds each stage took.

A failure raises out of the task; the study records the error text (:mod:`idtool.
_study._study`). Same task, same record, but for its timings: the simulation takes the
task's seed, the fit ``seed=0`` (the default), the draws the task's seed.
"""

from __future__ import annotations

import time
import warnings
from typing import Any

import numpy as np

__all__ = ["RANK_DRAWS", "TIMING_KEYS", "run_task"]

RANK_DRAWS = 99  # draws the truth is ranked among: ranks 0..99, 100 equally likely values
TIMING_KEYS = (
    "simulate_s",
    "fit_s",
    "before_fit_s",
    "sample_s",
    "predict_s",
    "task_s",
    "worker",
    "finished_s",
)


def _configure(jax_config: dict[str, Any]) -> None:
    """The study's JAX settings (the compilation cache) in this worker process."""
    if not jax_config:
        return
    import jax

    for name, value in jax_config.items():
        jax.config.update(name, value)


def run_task(task: dict[str, Any]) -> dict[str, Any]:
    """Simulate, fit (and sample), score one truth: the task's record (module docstring).

    ``task`` holds ``task_id``, ``seed``, ``truth`` (:meth:`~idtool._study._truths.Truth.
    to_dict`), ``base`` (a simulator document), ``rig``, ``friction_law``, ``departure``,
    ``points`` (rows load [N], amplitude, speed [m/s], ON [s]), ``targets`` (load [N],
    amplitude, speed [m/s]), ``fit_options``, ``sample``, ``jax_config`` and ``before``
    (0, or the number of existing pulls, the first of ``points``, to fit alone too).
    """
    import os
    import socket

    started = time.perf_counter()
    _configure(task.get("jax_config") or {})
    from idtool._fit._run import fit_dataset
    from idtool._simulate._params import BenchParams
    from idtool._simulate._simulate import simulate_bench
    from idtool._study._truths import Truth, design_points, truth_params
    from idtool._workflow import Fit

    seed = int(task["seed"])
    truth = Truth.from_dict(task["truth"])
    doc = truth_params(truth, task["base"], task["rig"], task["friction_law"], task["departure"])
    params = BenchParams.from_dict(doc, f"study task {task['task_id']} truth")
    points = design_points(task["points"])
    t0 = time.perf_counter()
    dataset, _ = simulate_bench(params, seed, points)
    t1 = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the fit's warnings are its own report's
        run = fit_dataset(dataset, seed=0, **task.get("fit_options", {}))
    fit = Fit.from_run(dataset, run)
    t2 = time.perf_counter()
    record: dict[str, Any] = {
        "task_id": int(task["task_id"]),
        "seed": seed,
        "truth": truth.to_dict(),
        "departure": task["departure"],
        "simulate_s": t1 - t0,
        "fit_s": t2 - t1,
        "law": fit.model.coupling.name,
        "law_weights": {
            name: float(doc_["bic_weight"]) for name, doc_ in fit.coupling_laws.items()
        },
        "warnings": sorted({getattr(w, "code", str(w)) for w in fit.warnings}),
    }
    if task.get("before"):
        record["law_weights_before"] = _law_weights_before(
            dataset, int(task["before"]), task.get("fit_options", {})
        )
        record["before_fit_s"] = time.perf_counter() - t2
        t2 = time.perf_counter()
    record["sampled"] = False
    if task.get("sample"):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            post = fit.sample(seed=seed)
        record["sampled"] = True
        record["converged"] = bool(post.diagnostics.converged)
        record["steps"] = int(post.diagnostics.steps)
        record["sample_s"] = time.perf_counter() - t2
    t3 = time.perf_counter()
    draws = fit.draws(max_draws=RANK_DRAWS, seed=seed)
    record["draws_source"] = draws.source
    record["parameters"] = _parameters(fit, draws, truth)
    record["targets"] = _targets(fit, params, task["targets"], seed)
    record["predict_s"] = time.perf_counter() - t3
    record["task_s"] = time.perf_counter() - started
    record["worker"] = f"{socket.gethostname()}:{os.getpid()}"
    return record


def _law_weights_before(dataset, n_existing: int, fit_options: dict) -> dict[str, float]:
    """Each coupling law's weight from the defaults' fit of ``dataset``'s first
    ``n_existing`` traces (the design's existing pulls, simulated with the same seed as
    the whole: the planned pulls' traces follow them)."""
    from idtool._data._select import first_traces
    from idtool._fit._run import fit_dataset
    from idtool._workflow import Fit

    existing = first_traces(dataset, n_existing)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        run = fit_dataset(existing, seed=0, **fit_options)
    fit = Fit.from_run(existing, run)
    return {name: float(doc["bic_weight"]) for name, doc in fit.coupling_laws.items()}


def _parameters(fit, draws, truth) -> dict[str, dict[str, Any]]:
    """Per physical parameter the fit shares with the truth: the truth, estimate, 95%
    interval, inside, and the SBC rank among the chosen law's draws (the pooled draws
    of every kept law for the contact's parameters, which every law has)."""
    out: dict[str, dict[str, Any]] = {}
    for name, est in fit.estimates.items():
        if name not in truth.values or name not in fit.model.physical_names:
            continue
        value = float(truth.values[name])
        pooled = [c.values[name] for c in draws.components if name in c.values]
        sample = np.concatenate(pooled) if pooled else np.empty(0)
        lo, hi = (float(x) for x in est.ci95)
        out[name] = {
            "truth": value,
            "estimate": float(est.estimate),
            "ci95": [lo, hi],
            "inside": bool(lo <= value <= hi),
            "rank": int(np.sum(sample < value)),
            "draws": int(sample.size),
        }
    return out


def _targets(fit, params, targets, seed: int) -> list[dict[str, Any]]:
    """Per target (load [N], amplitude, speed [m/s]): the true FR, the fit's band and
    half-width [FR], and whether the truth is inside."""
    from idtool._simulate._simulate import true_friction_ratio

    out = []
    for load_n, amp, speed in targets:
        pred = fit.predict(load_n, amp, speed, max_draws=2000, seed=seed).rows[0]
        lo, hi = (float(x) for x in pred.ci95)
        fr = float(true_friction_ratio(params, load_n, amp, speed))
        out.append(
            {
                "normal_load_n": float(load_n),
                "amplitude_fraction": float(amp),
                "pull_speed_m_s": float(speed),
                "true_fr": fr,
                "median": float(pred.median),
                "ci95": [lo, hi],
                "half_width": (hi - lo) / 2.0,
                "inside": bool(lo <= fr <= hi),
            }
        )
    return out
