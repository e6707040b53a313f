"""The study's one contact with Dask (``dask.distributed``): a client, the tasks
submitted, their results streamed back as they finish.

:func:`open_client` starts a :class:`~distributed.LocalCluster` of ``workers`` processes
with one thread each (and one OpenBLAS/OpenMP thread: two workers on two cores do not
oversubscribe them), or connects to the scheduler at ``scheduler`` (``tcp://host:8786``:
a lab's workstation pool started with ``dask scheduler`` and ``dask worker``, or a
cloud cluster). :func:`run_tasks` submits one future per task and hands each result to
``on_record`` in the order they finish (:func:`distributed.as_completed`); a task that
raises is handed on as ``{"task_id", "seed", "error"}``, and the others go on.
"""

from __future__ import annotations

import contextlib
import logging
import uuid
from collections.abc import Callable, Iterator, Sequence
from typing import Any

from idtool._errors import IdtoolError

__all__ = ["open_client", "run_tasks"]

# Each worker process's environment, before NumPy and JAX load (Dask's own defaults
# already set these three to 1; said here so a changed default does not oversubscribe).
WORKER_ENVIRON = {"OPENBLAS_NUM_THREADS": 1, "OMP_NUM_THREADS": 1, "MKL_NUM_THREADS": 1}


@contextlib.contextmanager
def open_client(workers: int = 2, scheduler: str | None = None) -> Iterator[Any]:
    """A Dask client: on a new local cluster of ``workers`` processes (one thread each),
    or on the cluster whose scheduler is at ``scheduler``; closed (the local cluster
    shut down) on leaving.

    Raises:
        IdtoolError: ``workers`` < 1, or no scheduler answers at ``scheduler``.
    """
    import dask
    from distributed import Client, LocalCluster

    if scheduler is not None:
        try:
            client = Client(scheduler, timeout="20s")
        except (OSError, TimeoutError, ValueError) as err:
            raise IdtoolError(
                f"--scheduler {scheduler}: no Dask scheduler answers there ({err}); start "
                "one with 'dask scheduler' (and workers with 'dask worker ADDRESS') or "
                "leave --scheduler out for a local cluster"
            ) from None
        with client:
            yield client
        return
    if workers < 1:
        raise IdtoolError(f"--workers {workers}: give at least 1")
    environ = dict(dask.config.get("distributed.nanny.pre-spawn-environ", {}))
    with dask.config.set({"distributed.nanny.pre-spawn-environ": environ | WORKER_ENVIRON}):
        cluster = LocalCluster(
            n_workers=workers,
            threads_per_worker=1,
            processes=True,
            dashboard_address=":0",  # any free port: two studies at once do not collide
            silence_logs=logging.CRITICAL,
        )
    with cluster, Client(cluster) as client:
        yield client


def run_tasks(
    client: Any,
    func: Callable[[dict[str, Any]], dict[str, Any]],
    tasks: Sequence[dict[str, Any]],
    on_record: Callable[[dict[str, Any]], None],
    *,
    progress: bool = True,
    stop_after: int | None = None,
) -> int:
    """Run ``func`` on every task on ``client``'s cluster; ``on_record`` gets each
    record as it finishes (an error's record when a task raises). ``stop_after``: stop
    (cancelling the rest) once that many have finished, as an interruption would.
    Returns the number of records handed on."""
    from distributed import CancelledError, as_completed
    from tqdm.auto import tqdm

    if not tasks:
        return 0
    # Keys unique to this call: a resumed study resubmits the tasks an interrupted call
    # cancelled, and a key reused while the scheduler still forgets the cancelled one
    # comes back cancelled ("cancelled for reason: unknown", seen in CI)
    run = uuid.uuid4().hex[:8]
    futures = {
        client.submit(
            func, t, key=f"idtool-study-{t['study_key']}-{t['task_id']}-{run}", pure=False
        ): t
        for t in tasks
    }
    done = 0
    bar = tqdm(total=len(tasks), desc="study", unit="fit", disable=not progress)
    try:
        for future in as_completed(futures):
            task = futures[future]
            try:
                record = future.result()
            except CancelledError:  # not the fit's failure: left unrecorded, so resumed
                continue
            except Exception as err:  # a failed fit is a record, not the study's end
                record = {
                    "task_id": task["task_id"],
                    "seed": task["seed"],
                    "truth": task["truth"],
                    "error": f"{type(err).__name__}: {err}",
                }
            on_record(record)
            done += 1
            bar.update()
            if stop_after is not None and done >= stop_after:
                break
    finally:
        bar.close()
        client.cancel(list(futures))
    return done
