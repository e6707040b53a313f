"""The checkpoint of a sampling run: ``fits/NAME/chain.h5``.

The layout is emcee's ``HDFBackend`` (group ``mcmc``: ``chain``, ``log_prob``,
``accepted``, the random state and the iteration count as attributes), so
``emcee.backends.HDFBackend("chain.h5", read_only=True)`` reads it; the file's own
attribute ``idtool_settings`` (JSON) records what was sampled, to refuse resuming a
chain under other settings, and, under ``transforms``, how each column of the chain
(internal scale ``z``) maps to physical units: a formula in ``z`` and the parameter's
``lo``/``hi`` (or ``centre``/``scale``), with its unit (:meth:`idtool.Param.transform`),
after the walkers' own coordinates are mapped to that internal scale: under ``ridge``
(sampled along a profile, :mod:`idtool._posterior._ridge`) or ``funnel`` (the
discrepancy's funnel opened, :mod:`idtool._posterior._funnel`), each with its formula;
and its dataset ``idtool_linearisation`` the parameter vector at which the nuisances
were linearised (:mod:`idtool._posterior._start`), so a resumed chain
samples exactly the same target.

The sampler runs in memory; every run segment is appended to a copy of ``chain.h5``
(``chain.h5.partial``), which is synced and renamed over ``chain.h5``. A crash or an
interrupt therefore leaves the last complete ``chain.h5`` untouched (and at most a
``.partial`` file, which is never read and is removed by the next run).
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path
from typing import Any

import numpy as np

from idtool._atomic import atomic_file
from idtool._errors import IdtoolError

__all__ = ["append_segment", "last_state", "read_chain", "read_linearisation", "read_settings"]

_GROUP = "mcmc"
_LIN = "idtool_linearisation"


def read_settings(chain_file: Path) -> tuple[dict, int]:
    """The settings a chain was sampled with, and its length in steps."""
    import h5py

    try:
        with h5py.File(chain_file, "r") as f:
            return json.loads(f.attrs["idtool_settings"]), int(f[_GROUP].attrs["iteration"])
    except (OSError, KeyError, ValueError) as err:
        raise IdtoolError(
            f"{chain_file}: unreadable chain ({err}); start over with --force"
        ) from None


def last_state(chain_file: Path) -> Any:
    """The ensemble's last state (positions, log-probabilities, random state)."""
    import emcee

    return emcee.backends.HDFBackend(str(chain_file), read_only=True).get_last_sample()


def read_chain(chain_file: Path) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Chain (steps, walkers, ndim), log-posterior (steps, walkers), acceptance fractions."""
    import emcee

    b = emcee.backends.HDFBackend(str(chain_file), read_only=True)
    return b.get_chain(), b.get_log_prob(), b.accepted / max(b.iteration, 1)


def read_linearisation(chain_file: Path) -> np.ndarray:
    """The FitModel vector at which the chain's nuisances were linearised."""
    import h5py

    try:
        with h5py.File(chain_file, "r") as f:
            return np.asarray(f[_LIN][()], float)
    except (OSError, KeyError) as err:
        raise IdtoolError(
            f"{chain_file}: unreadable chain ({err}); start over with --force"
        ) from None


def append_segment(
    chain_file: Path,
    segment: Any,
    random_state: tuple,
    settings: dict,
    new: bool,
    z_lin: np.ndarray,
) -> None:
    """Append an in-memory emcee ``Backend`` segment to ``chain_file``, atomically.

    ``new`` starts the file afresh (a new chain, recording ``settings`` and the
    linearisation point ``z_lin``); otherwise the segment continues it.
    """
    import emcee
    import h5py

    chain, log_prob = segment.get_chain(), segment.get_log_prob()
    steps, walkers, ndim = chain.shape
    with atomic_file(chain_file, sync=True) as partial:
        if new:
            emcee.backends.HDFBackend(str(partial)).reset(walkers, ndim)
        else:
            shutil.copyfile(chain_file, partial)
        with h5py.File(partial, "a") as f:
            if new:
                f.attrs["idtool_settings"] = json.dumps(settings)
                f.create_dataset(_LIN, data=np.asarray(z_lin, float))
            g = f[_GROUP]
            it = int(g.attrs["iteration"])
            g["chain"].resize(it + steps, axis=0)
            g["log_prob"].resize(it + steps, axis=0)
            g["chain"][it:] = chain
            g["log_prob"][it:] = log_prob
            g["accepted"][:] += segment.accepted
            for i, v in enumerate(random_state):
                g.attrs[f"random_state_{i}"] = v
            g.attrs["iteration"] = it + steps
