"""``idtool study`` / :func:`idtool.study`: simulation-based checks of a bench design.

Draw ``truths`` truths from a fit (its posterior if sampled, else its covariance; the
coupling laws by their weights: :mod:`idtool._study._truths`), simulate for each the
fit's design plus a plan's pulls, fit (and optionally sample) as the defaults do, and
score the bands, the intervals and the chosen law (:mod:`idtool._study._task`); then
summarise (:mod:`idtool._study._summary`). The tasks run on Dask
(:mod:`idtool._study._dask`): a local cluster of processes, or any cluster.

Task ``i``'s seed is ``SeedSequence(seed, spawn_key=(i,))``'s first word: the records
(but their timings) depend on the study's seed alone, not on the worker count or the
order tasks finish in.

Resuming: the records are appended, one JSON line each and flushed as each task
finishes, to ``OUT.partial/records.jsonl`` beside ``study.json`` (the study's settings).
Run the same command again and the tasks with a record are skipped; once every task has
one, the summary is written and ``OUT.partial`` renamed to ``OUT``. A different study
into the same ``OUT`` is refused (``--force`` starts it anew), and so is an ``OUT``
that exists.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import os
import shutil
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from idtool._data._example import example_params_path
from idtool._errors import IdtoolError
from idtool._simulate._departures import DEPARTURE_KINDS, DRIFT_KINDS, SHAPE_KINDS
from idtool._study._summary import plot_study, summarise, summary_text
from idtool._study._truths import (
    draw_truths,
    plan_pulls_from_folder,
    targets_of,
)
from idtool._workflow import Fit

__all__ = ["RECORDS", "Study", "partial_folder", "read_records", "study", "task_seed"]

RECORDS = "records.jsonl"
SETTINGS = "study.json"
TRUTH_POOL = 2000  # the fit's draws the truths are picked from (with replacement)
DEPARTURES = ("clean", *[k for k in DEPARTURE_KINDS + DRIFT_KINDS + SHAPE_KINDS if k != "clean"])


@dataclasses.dataclass(frozen=True)
class Study:
    """A study's outcome: its ``records`` (one per task, by task id), the ``summary``
    (:func:`idtool._study._summary.summarise`), and the folder it was written to
    (``None`` while unfinished: ``stop_after`` stopped it)."""

    records: tuple[dict, ...]
    summary: dict | None
    folder: Path | None
    text: str = ""


def task_seed(seed: int, task_id: int) -> int:
    """Task ``task_id``'s seed: the first word of ``SeedSequence(seed, spawn_key=(task_id,))``
    (the ``task_id``-th child of the study's seed)."""
    return int(np.random.SeedSequence(seed, spawn_key=(task_id,)).generate_state(1)[0])


def partial_folder(out: str | os.PathLike) -> Path:
    """Where an unfinished study keeps its records: ``OUT.partial`` beside ``OUT``."""
    out = Path(out)
    return out.with_name(out.name + ".partial")


def read_records(path: str | os.PathLike) -> list[dict]:
    """The records of a ``records.jsonl`` (the first per task id; a last line cut short
    by an interruption is dropped)."""
    path = Path(path)
    if not path.exists():
        return []
    out: dict[int, dict] = {}
    for line in path.read_text().splitlines():
        try:
            record = json.loads(line)
        except ValueError:
            continue  # a line cut short when the study was stopped
        out.setdefault(int(record["task_id"]), record)
    return [out[k] for k in sorted(out)]


def _base_params(params: str | os.PathLike | dict | None) -> dict:
    if isinstance(params, dict):
        return json.loads(json.dumps(params))
    path = example_params_path() if params is None else Path(params)
    try:
        return json.loads(Path(path).read_text())
    except (OSError, ValueError) as err:
        raise IdtoolError(
            f"--params {path}: cannot read a simulator parameter file ({err})"
        ) from None


def study(
    fit: Fit,
    truths: int,
    out: str | os.PathLike,
    *,
    plan: str | os.PathLike | None = None,
    uniform: bool = False,
    departure: str = "clean",
    sample: bool = False,
    workers: int = 2,
    scheduler: str | None = None,
    client: Any = None,
    seed: int = 0,
    force: bool = False,
    params: str | os.PathLike | dict | None = None,
    fit_options: dict | None = None,
    progress: bool = True,
    stop_after: int | None = None,
    jax_config: dict | None = None,
    bad_truths: Sequence[int] = (),
) -> Study:
    """Simulation-based check of ``fit``'s design (module docstring).

    Args:
        fit: the fit whose draws are the truths and whose traces are the design.
        truths: how many truths (tasks, each a simulated bench and its fit).
        out: the output folder (``summary.json``, ``summary.txt``, ``study.png``,
            ``records.jsonl``, ``study.json``); unfinished, ``OUT.partial``.
        plan: an ``idtool plan`` folder: its pulls are simulated too, its ``at`` are the
            targets and its expected half-width is what the study checks.
        uniform: simulate the uniform grid of as many pulls the plan is compared with
            (``plan.json``'s ``uniform_pulls``) instead of its planned pulls.
        departure: the simulated bench's departure from the fit's model
            (:mod:`idtool._simulate._departures`; ``clean``: none, the fit's own
            assumptions with its scatter).
        sample: sample each fit's posterior with the defaults too (until converged: 1-10
            minutes a task on the example, against seconds for a fit).
        workers: processes of the local cluster (without ``scheduler`` or ``client``).
        scheduler: a Dask scheduler's address (``tcp://host:8786``) to run on instead.
        client: a :class:`distributed.Client` already open to run on instead.
        progress: show a progress bar.
        seed: the study's seed (truths and each task's seed).
        force: replace an existing ``out``; start anew over another study's partial one.
        params: the simulator document (or its path) giving the load cell, actuator,
            switching and timing (default the example's).
        fit_options: keyword arguments of each fit (default: the defaults, with
            ``coupling="auto"`` when ``fit`` kept several coupling laws).
        stop_after: stop once this many tasks have finished (an interruption; resumable).
        jax_config: JAX settings for the workers (the CLI's compilation cache).
        bad_truths: task ids whose truth is made invalid (a negative Kt): tests of the
            failure path.

    Raises:
        IdtoolError: bad options, an existing ``out`` without ``force``, or a partial
            study of other settings in ``OUT.partial``.
    """
    from idtool._study._dask import open_client, run_tasks
    from idtool._study._task import run_task

    if isinstance(truths, bool) or not isinstance(truths, int) or truths < 1:
        raise IdtoolError(f"--truths {truths!r}: give at least 1")
    if departure not in DEPARTURES:
        raise IdtoolError(f"--departure {departure!r}: use one of {', '.join(DEPARTURES)}")
    out = Path(out)
    if out.exists() and not force:
        raise IdtoolError(f"{out} already exists; pass --force to replace it")
    data = fit.model.data
    loads = np.asarray(data.normal_load_n, float)
    amps = np.asarray(data.amplitude_fraction, float)
    speeds = np.asarray(data.pull_speed_m_s, float)
    on_s = np.asarray(data.on_end_s, float) - np.asarray(data.on_start_s, float)
    points = [list(r) for r in zip(loads, amps, speeds, on_s, strict=True)]
    n_existing = len(points)
    plan_doc = None
    if plan is not None:
        pulls, plan_doc = plan_pulls_from_folder(plan, uniform)
        points += [
            [p.normal_load_n, p.amplitude_fraction, p.pull_speed_m_s, p.on_duration_s]
            for p in pulls
        ]
    points = [[float(x) if np.isfinite(x) else 0.0 for x in row] for row in points]
    targets = targets_of(plan_doc, loads, amps, speeds)
    # a plan to tell the laws apart is checked by the weights it moves: each task fits the
    # existing pulls alone too (a second fit a task)
    before = n_existing if plan_doc is not None and plan_doc.get("goal") == "laws" else 0
    options = dict(fit_options or {})
    if len(fit.coupling_laws) > 1:
        options.setdefault("coupling", "auto")
    options.setdefault("law", fit.model.law.name)
    base = _base_params(params)
    rig = _rig(fit)
    base_sha = hashlib.sha256(json.dumps(base, sort_keys=True).encode()).hexdigest()
    settings: dict[str, Any] = {
        "dataset_sha256": fit.dataset.sha256,
        "fit": repr(fit),
        "plan": None
        if plan_doc is None
        else hashlib.sha256(json.dumps(plan_doc, sort_keys=True).encode()).hexdigest(),
        "uniform": bool(uniform),
        "truths": truths,
        "seed": seed,
        "departure": departure,
        "sample": bool(sample),
        "fit_options": options,
        "params_sha256": base_sha,
        "bad_truths": sorted(int(i) for i in bad_truths),
    }
    bad = set(settings["bad_truths"])
    partial = partial_folder(out)
    if partial.exists():
        try:
            old = json.loads((partial / SETTINGS).read_text())
        except (OSError, ValueError):
            old = None
        if old != settings:
            if not force:
                raise IdtoolError(
                    f"{partial} holds an unfinished study of other settings (or no "
                    f"{SETTINGS}); pass --force to start this one anew, or another --out"
                )
            shutil.rmtree(partial)
    partial.mkdir(parents=True, exist_ok=True)
    (partial / SETTINGS).write_text(json.dumps(settings, indent=1) + "\n")
    records_path = partial / RECORDS
    finished = {r["task_id"] for r in read_records(records_path)}

    key = (
        settings["params_sha256"][:8]
        + hashlib.sha256(json.dumps(settings, sort_keys=True).encode()).hexdigest()[:8]
    )
    drawn = draw_truths(fit.draws(max_draws=TRUTH_POOL, seed=seed), truths, seed)
    tasks = []
    for i, truth in enumerate(drawn):
        if i in finished:
            continue
        doc = truth.to_dict()
        if i in bad:
            doc["values"]["Kt"] = -1.0  # the simulator's schema refuses it
        tasks.append(
            {
                "study_key": key,
                "task_id": i,
                "seed": task_seed(seed, i),
                "truth": doc,
                "base": base,
                "rig": rig,
                "friction_law": fit.model.law.name,
                "departure": departure,
                "points": points,
                "targets": targets,
                "fit_options": options,
                "sample": bool(sample),
                "jax_config": dict(jax_config or {}),
                "before": before,
            }
        )

    started = time.perf_counter()
    with open(records_path, "a") as fh:

        def on_record(record: dict) -> None:
            record["finished_s"] = time.perf_counter() - started
            fh.write(json.dumps(record, default=float) + "\n")
            fh.flush()
            os.fsync(fh.fileno())

        if client is not None:
            run_tasks(client, run_task, tasks, on_record, progress=progress, stop_after=stop_after)
        elif tasks:
            with open_client(workers, scheduler) as own:
                run_tasks(own, run_task, tasks, on_record, progress=progress, stop_after=stop_after)
    wall_s = time.perf_counter() - started
    records = read_records(records_path)
    if len(records) < truths:
        return Study(tuple(records), None, None)
    expected = _expected(fit, plan_doc, targets, uniform)
    summary = summarise(records, expected, wall_s)
    summary["settings"] = settings
    summary["expected"] = expected
    summary["fits_per_minute"] = len(tasks) / (wall_s / 60.0) if tasks and wall_s > 0 else None
    text = summary_text(summary)
    (partial / "summary.json").write_text(json.dumps(summary, indent=1, default=float) + "\n")
    (partial / "summary.txt").write_text(text + "\n")
    plot_study(summary, records, partial / "study.png")
    if out.exists():
        shutil.rmtree(out)
    os.replace(partial, out)
    return Study(tuple(records), summary, out, text)


def _rig(fit: Fit) -> dict[str, Any]:
    """The dataset's rig as the simulator document's ``rig``."""
    r = fit.dataset.rig
    out: dict[str, Any] = {
        "vibration_frequency_hz": float(r.vibration_frequency_hz),
        "max_amplitude_m": float(r.max_amplitude_m),
    }
    if r.mains_frequency_hz is not None:
        out["mains_frequency_hz"] = float(r.mains_frequency_hz)
    if r.transducer is not None:
        out["transducer"] = r.transducer.to_dict()
    return out


def _expected(fit: Fit, plan_doc: dict | None, targets, uniform: bool) -> dict[str, Any]:
    """The expected half-widths [FR] at the targets: the plan's value after its pulls
    (goal band: the largest of the targets'; ``uniform``: the uniform grid's), else
    today's linearised band (:func:`idtool._plan._plan.band_half_widths`)."""
    if plan_doc is not None and plan_doc.get("goal") == "band":
        value = float(plan_doc["uniform" if uniform else "values"][-1])
        return {
            "half_width": [value] * len(targets),
            "now": float(plan_doc["values"][0]),
            "uniform": float(plan_doc["uniform"][-1]),
            "source": f"the plan's after its {len(plan_doc['pulls'])} "
            + ("uniform pulls" if uniform else "pulls"),
        }
    from idtool._plan._linear import Points
    from idtool._plan._plan import band_half_widths

    if fit.levels is None:
        return {"half_width": [], "source": "none (the fit has no levels model)"}
    pts = Points(*(np.array(col, float) for col in zip(*targets, strict=True)))
    hw = band_half_widths(fit.artefact, pts)
    return {"half_width": [float(x) for x in hw], "source": "today's linearised band"}
