"""Compile the programs a fit will need next while it runs the ones it has.

A cold ``idtool fit`` spends most of its time in XLA's compiler: one Levenberg-Marquardt
program per candidate model (slope, lag, drifting offset: ~1.7 s each on the example),
then the levels model's two. Compiled one after the other, on one core, while the
other core idles. XLA compiles with Python's lock released, so a thread can lower and
compile the next candidates' programs while the fit computes the current one; the jitted
functions' own caches then hold them (``jit(f).lower(...).compile()`` fills the cache
that ``f(...)`` reads), and the persistent compilation cache too.

A failed compilation ahead only loses its head start: the real call compiles again,
and raises there if the program is wrong.
"""

from __future__ import annotations

import concurrent.futures
import logging
from collections.abc import Callable

__all__ = ["CompileAhead"]

_log = logging.getLogger(__name__)


class CompileAhead:
    """One background thread that lowers and compiles jitted programs in the order
    they are given (the order the fit will need them). Use as a context manager: on
    exit the work not started is dropped and the running compilation awaited."""

    def __init__(self) -> None:
        self._pool = concurrent.futures.ThreadPoolExecutor(1, thread_name_prefix="idtool-compile")

    def call(self, work: Callable[[], object]) -> None:
        """Run ``work`` in the thread (it prepares and compiles programs)."""

        def guarded() -> None:
            try:
                work()
            except Exception:  # a head start lost; the real call will say what is wrong
                _log.debug("compiling ahead failed", exc_info=True)

        self._pool.submit(guarded)

    def __enter__(self) -> CompileAhead:
        return self

    def __exit__(self, *exc: object) -> None:
        self._pool.shutdown(wait=True, cancel_futures=True)
