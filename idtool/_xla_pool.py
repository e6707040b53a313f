"""JAX's CPU backend started with one intra-op thread, so batched LAPACK calls cannot
deadlock it (jaxlib 0.10).

jaxlib 0.10's CPU LAPACK kernels (LU, Cholesky, eigh, triangular solves: every
``jnp.linalg`` call on a batch) split a batch whose work exceeds about 2e5 FLOP into
chunks, schedule the chunks on XLA's intra-op thread pool and block the calling thread
until they are done (``ParallelBatchMap`` in ``jaxlib/cpu/lapack_kernels.cc``). The
calling thread is itself one of that pool's threads, and XLA runs independent
operations of a program concurrently: when as many batched LAPACK calls run at once as
the pool has threads, every thread waits for chunks that no thread is left to run, and
the program never finishes. On 2 cores (a pool of 2) the REML grid of the levels model
(241 batched 12 x 12 factorisations, several at once) hung a CI worker for good; a
program of four such solves hung 4 to 5 runs of 6 (300 calls each), and 0 of 6 with
this module. XLA's ``--xla_cpu_multi_thread_eigen=false`` does not help (5 of 6 hung):
the pool is handed to the kernels regardless.

The kernels run a batch inline when the pool has one thread, and XLA sizes the pool
from the process's CPU affinity when the backend starts. So the backend is started
with the calling thread pinned to one CPU, and every thread created meanwhile (the
pool's) is given the original affinity back: idtool's programs lose XLA's splitting
of large element-wise loops over the cores (they are small; the fit's compilation
still runs beside them on the other core, :mod:`idtool._fit._prefetch`). jaxlib 0.11
compiles the parallel LAPACK path out of open-source builds; with it this module can
go (``constraints.txt`` pins 0.10.2, the newest on PyPI here).

It runs once, when JAX is first imported in the process (a post-import hook that
``import idtool`` installs, so ``idtool validate`` and ``idtool --help`` still never
import JAX), or at ``import idtool`` when JAX is imported already and its backend not
yet started. A backend that already started keeps its pool (nothing can shrink it).
"""

from __future__ import annotations

import contextlib
import importlib.abc
import importlib.util
import os
import sys
from types import ModuleType

__all__ = ["install", "start_backend"]

_started = False


def _tasks() -> set[int]:
    """This process's thread ids (Linux), else the empty set."""
    try:
        return {int(t) for t in os.listdir("/proc/self/task")}
    except OSError:
        return set()


def start_backend(jax: ModuleType) -> None:
    """Start ``jax``'s backends with a one-thread intra-op pool (module docstring);
    nothing if they started already or this is its second call. Where the CPU affinity
    cannot be set (not Linux) or holds one CPU, the backends are left to start as JAX
    starts them, when first used."""
    global _started
    if _started:
        return
    _started = True
    from jax._src import xla_bridge  # JAX has no public "has the backend started"

    if xla_bridge.backends_are_initialized():
        return
    affinity = getattr(os, "sched_getaffinity", None)
    full = affinity(0) if affinity is not None else set()
    if len(full) <= 1:  # one CPU: a pool of one anyway, started when first used
        return
    before = _tasks()
    os.sched_setaffinity(0, {min(full)})  # this thread only; new threads inherit it
    try:
        jax.devices()
    except Exception:
        # a backend that cannot start (JAX_PLATFORMS naming a missing plugin raises an
        # AssertionError in jax 0.10) fails again where it is first used, as it would
        # without idtool, not at the import of JAX
        pass
    finally:
        for tid in (_tasks() - before) | {0}:
            with contextlib.suppress(OSError):  # a thread that ended meanwhile
                os.sched_setaffinity(tid, full)


class _AfterJax(importlib.abc.MetaPathFinder):
    """Finds nothing itself: when ``jax`` is first imported, it steps aside, finds
    JAX's own spec and wraps that loader's ``exec_module`` (on the instance) so that
    :func:`start_backend` runs once the package has executed."""

    def find_spec(self, fullname, path=None, target=None):
        if fullname != "jax":
            return None
        sys.meta_path.remove(self)
        spec = importlib.util.find_spec(fullname)
        loader = spec.loader if spec is not None else None
        if loader is None or not hasattr(loader, "exec_module"):
            return spec
        execute = loader.exec_module

        def exec_module(module: ModuleType) -> None:
            execute(module)
            start_backend(module)

        loader.exec_module = exec_module  # type: ignore[method-assign]
        return spec


def install() -> None:
    """Arrange for :func:`start_backend` to run when JAX is imported (now, if it is
    imported already)."""
    if "jax" in sys.modules:
        start_backend(sys.modules["jax"])
    elif not any(isinstance(f, _AfterJax) for f in sys.meta_path):
        sys.meta_path.insert(0, _AfterJax())
