"""The posterior on disk: ``fits/NAME/posterior.nc``, ArviZ ``InferenceData`` as netCDF.

Groups: ``posterior`` (kept draws, one variable per sampled parameter in physical units,
dims ``chain`` = walker and ``draw`` = step), ``sample_stats`` (``lp``, the
log-posterior), and the burn-in as ``warmup_posterior`` / ``warmup_sample_stats``. The
``posterior`` group's attribute ``idtool`` is a JSON document: noise model, priors,
seed, law, coupling, diagnostics, timing, the fit it came from. Read it back with
``arviz.from_netcdf`` or :func:`load_posterior`.
"""

from __future__ import annotations

import dataclasses
import json
import os
import warnings
from pathlib import Path

import numpy as np

from idtool._atomic import atomic_file
from idtool._errors import IdtoolError
from idtool._posterior._diagnostics import import_arviz
from idtool._posterior._sample import Posterior

__all__ = [
    "POSTERIOR_FILE",
    "PosteriorDraws",
    "inference_data",
    "load_posterior",
    "write_posterior",
]

POSTERIOR_FILE = "posterior.nc"


def inference_data(post: Posterior, extra: dict | None = None):
    """``post`` as ArviZ ``InferenceData`` (module docstring); ``extra`` joins the
    metadata document."""
    from idtool._version import (
        __version__,  # here: idtool/__init__ imports this module before defining it
    )

    az = import_arviz()
    burn = post.diagnostics.burn

    def walker_major(x: np.ndarray) -> np.ndarray:
        return np.ascontiguousarray(np.swapaxes(x, 0, 1))

    kept = {n: walker_major(post.values[burn:, :, i]) for i, n in enumerate(post.names)}
    warm = {n: walker_major(post.values[:burn, :, i]) for i, n in enumerate(post.names)}
    with warnings.catch_warnings():
        # walkers are the chains: a short burn-in has more of them than draws, on purpose
        warnings.filterwarnings("ignore", message="More chains", category=UserWarning)
        idata = az.from_dict(
            posterior=kept,
            sample_stats={"lp": walker_major(post.log_prob[burn:])},
            warmup_posterior=warm if burn else None,
            warmup_sample_stats={"lp": walker_major(post.log_prob[:burn])} if burn else None,
            save_warmup=bool(burn),
        )
    meta = {
        "noise": post.noise,
        "priors": {n: p.to_dict() for n, p in post.priors.items()},
        "units": {p.name: p.unit for p in post.params},
        "seed": post.seed,
        "law": post.law,
        "coupling": post.coupling,
        "diagnostics": post.diagnostics.to_dict(),
        "timing": post.timing,
        "idtool_version": __version__,
    } | (extra or {})
    idata.posterior.attrs["idtool"] = json.dumps(meta)
    for p in post.params:
        idata.posterior[p.name].attrs["units"] = p.unit
    return idata


def write_posterior(post: Posterior, path: str | os.PathLike, extra: dict | None = None) -> Path:
    """Write ``post`` as netCDF at ``path``, atomically (temporary file, then rename)."""
    idata = inference_data(post, extra)
    path = Path(path)
    with atomic_file(path) as tmp:
        idata.to_netcdf(str(tmp))
    return path


@dataclasses.dataclass(frozen=True)
class PosteriorDraws:
    """Kept posterior draws read back: flat arrays in physical units, and the metadata."""

    values: dict[str, np.ndarray]
    meta: dict

    @property
    def n_draws(self) -> int:
        return int(next(iter(self.values.values())).size)


def load_posterior(path: str | os.PathLike) -> PosteriorDraws:
    """Read ``posterior.nc`` (a file, or the fit folder holding it)."""
    az = import_arviz()
    path = Path(path)
    if path.is_dir():
        path = path / POSTERIOR_FILE
    if not path.is_file():
        raise IdtoolError(f"{path}: not found; run 'idtool sample' first")
    try:
        idata = az.from_netcdf(str(path))
        post = idata.posterior
        meta = json.loads(post.attrs["idtool"])
        values = {n: np.asarray(post[n].values, float).ravel() for n in meta["units"]}
    except (OSError, KeyError, ValueError) as err:
        raise IdtoolError(f"{path}: unreadable posterior ({err}); sample again") from None
    return PosteriorDraws(values, meta)
