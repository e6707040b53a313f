"""Running an emcee ensemble until its chain has converged, or for a fixed length (issue 26).

Without a fixed length the chain is grown and judged as emcee's documentation advises
(tau re-estimated as the chain grows; stop when the chain is long against tau and tau has
settled), with the rank-normalised split R-hat and bulk ESS thresholds of ArviZ on top:
the whole rule is :data:`idtool._posterior._diagnostics.RULE`. The run is bounded by a
number of steps and a wall-clock budget; what ended it is recorded
(:attr:`Diagnostics.stopped_by`).

The checks cost little: tau alone (two FFTs of the chain) is estimated every tenth of the
chain's length (at least :data:`CHECK_MIN` steps), and no earlier than the length the
current estimate of tau asks for; the full diagnosis (R-hat and ESS through ArviZ) runs
only once tau is long and settled enough.

Checkpointing: every ``checkpoint_s`` seconds the steps run so far are appended to
``chain.h5`` (:mod:`idtool._posterior._chainfile`), so an interrupted run loses at most
that much and ``resume`` continues exactly where it stopped.
"""

from __future__ import annotations

import dataclasses
import math
import time
from pathlib import Path
from typing import Any

import numpy as np

from idtool._posterior._chainfile import append_segment, read_chain
from idtool._posterior._diagnostics import (
    BURN_FACTOR,
    TAU_CHANGE_MAX,
    TAU_FACTOR,
    Diagnostics,
    diagnose,
    kept_tau,
)

__all__ = ["FIRST_CHECK", "MAX_MINUTES", "MAX_STEPS", "ChainStore", "run_chain"]

FIRST_CHECK = 400  # steps before the first check: below it no tau is trustworthy
CHECK_MIN = 100  # steps between checks, at least
MAX_STEPS = 100_000  # default bound of a run to convergence
MAX_MINUTES = 10.0  # default wall-clock bound of a run to convergence


@dataclasses.dataclass
class ChainStore:
    """Where the chain goes: ``chain.h5`` (checkpointed) or memory."""

    chain_file: Path | None
    settings: dict
    z_lin: np.ndarray
    segments: list = dataclasses.field(default_factory=list)

    def append(self, backend: Any, state: Any, new: bool) -> None:
        if self.chain_file is None:
            self.segments.append(backend)
        else:
            append_segment(
                self.chain_file, backend, state.random_state, self.settings, new, self.z_lin
            )

    def read(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Chain (steps, walkers, ndim), log-posterior (steps, walkers), acceptance."""
        if self.chain_file is not None:
            return read_chain(self.chain_file)
        chain = np.concatenate([b.get_chain() for b in self.segments])
        lp = np.concatenate([b.get_log_prob() for b in self.segments])
        return chain, lp, sum(b.accepted for b in self.segments) / chain.shape[0]


def _tau_settled(chain: np.ndarray) -> tuple[bool, float]:
    """Whether tau alone passes the rule (long chain, settled tau), and the chain length
    the current tau asks for."""
    burn, tau, change = kept_tau(chain)
    worst = int(np.argmax(tau))
    needed = (TAU_FACTOR + BURN_FACTOR) * float(tau[worst])
    long_enough = chain.shape[0] - burn >= TAU_FACTOR * float(tau[worst])
    return long_enough and bool(change[worst] < TAU_CHANGE_MAX), needed


def _next_check(done: int, needed: float, limit: int) -> int:
    return min(limit, max(done + max(CHECK_MIN, done // 10), math.ceil(needed)))


def run_chain(
    sampler_for,
    initial: Any,
    store: ChainStore,
    done: int,
    names: tuple[str, ...],
    steps: int | None,
    max_steps: int,
    max_minutes: float,
    checkpoint_s: float,
    bar: Any,
) -> tuple[Diagnostics, float]:
    """Run the ensemble from ``initial`` (``done`` steps already in ``store``) for
    ``steps`` in total, or, with ``steps=None``, until converged (module docstring).

    ``sampler_for(backend)`` makes an ``emcee.EnsembleSampler`` writing to ``backend``;
    ``bar`` shows progress (``update``, and ``total``/``set_postfix_str`` when adaptive).
    Returns the diagnostics of the whole chain and the seconds spent sampling.
    """
    import emcee

    budget = 60.0 * max_minutes if steps is None else math.inf
    deadline = time.perf_counter() + budget
    limit = steps if steps is not None else max_steps
    target = limit if steps is not None else max(done, FIRST_CHECK)
    sample_s = 0.0
    while True:
        if steps is not None and done >= steps:
            stopped_by = "steps"
            break
        if done >= target:  # a check point of a run to convergence
            chain, _, acc = store.read()
            ok, needed = _tau_settled(chain)
            if ok:
                diag = diagnose(chain, acc, names, stopped_by="converged")
                if diag.converged:
                    return diag, sample_s
            if done >= limit:
                stopped_by = "max_steps"
                break
            target = _next_check(done, needed, limit)
            bar.total = max(target, min(limit, math.ceil(needed)))
            bar.set_postfix_str(
                f"chain needs >= {math.ceil(needed)} steps (50 tau)"
                + ("; tau settled, R-hat or ESS not yet" if ok else "")
            )
        if time.perf_counter() > deadline:
            stopped_by = "max_minutes"
            break
        backend = emcee.backends.Backend()
        t0 = time.perf_counter()
        it = sampler_for(backend).sample(
            initial, iterations=target - done, skip_initial_state_check=True
        )
        for _ in it:
            done += 1
            bar.update(1)
            now = time.perf_counter()
            if now > deadline or (store.chain_file is not None and now - t0 > checkpoint_s):
                break
        sample_s += time.perf_counter() - t0
        initial = backend.get_last_sample()
        store.append(backend, initial, new=done == backend.iteration)
    chain, _, acc = store.read()
    return diagnose(chain, acc, names, stopped_by=stopped_by), sample_s
