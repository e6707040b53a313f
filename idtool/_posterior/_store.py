"""The posterior on disk: ``fits/NAME/posterior.nc``, ArviZ ``InferenceData`` as netCDF.

Groups: ``posterior`` (kept draws, one variable per sampled parameter in physical units
with its ``units`` and ``description`` attributes, dims ``chain`` = walker and ``draw`` =
step after burn-in), ``sample_stats`` (``lp``, the log-posterior), the burn-in as
``warmup_posterior`` / ``warmup_sample_stats``, and, as ``idtool sample`` writes it,
``log_likelihood`` (per trace), ``observed_data``, ``constant_data`` (each trace's
operating point) and ``posterior_predictive`` (:mod:`idtool._posterior._groups`), so
``az.loo``, ``az.compare`` and ``az.plot_ppc`` run on it. The kept draws are thinned to
at most 4000 (every k-th step of every walker: :func:`~idtool._posterior._groups.
thinned_steps`; the ``draw`` coordinate gives each step's number); ``chain.h5`` keeps
every step. The ``posterior`` group's attribute ``idtool`` is a JSON document: noise
model, priors, seed, law, coupling, diagnostics (computed on the whole chain), timing,
the thinning, the fit it came from. Read it back with ``arviz.from_netcdf`` or
:func:`load_posterior`.
"""

from __future__ import annotations

import dataclasses
import json
import os
import warnings
from pathlib import Path

import numpy as np

from idtool._atomic import atomic_file
from idtool._diagnostic import records
from idtool._errors import IdtoolError
from idtool._fit._folder import POSTERIOR_NC
from idtool._posterior._diagnostics import import_arviz
from idtool._posterior._record import PosteriorRecord, thinned_steps
from idtool._version import __version__

__all__ = [
    "POSTERIOR_FILE",
    "PosteriorDraws",
    "inference_data",
    "load_posterior",
    "write_posterior",
]

POSTERIOR_FILE = POSTERIOR_NC.name


def inference_data(
    post: PosteriorRecord,
    extra: dict | None = None,
    groups: dict | None = None,
    steps: np.ndarray | None = None,
):
    """``post`` as ArviZ ``InferenceData`` (module docstring); ``extra`` joins the
    metadata document; ``groups`` (:func:`~idtool._posterior._groups.levels_groups` or
    ``noise_groups``) were computed at the kept ``steps`` (default: thinned_steps)."""
    import xarray as xr

    az = import_arviz()
    burn = post.diagnostics.burn

    def walker_major(x: np.ndarray) -> np.ndarray:
        return np.ascontiguousarray(np.swapaxes(x, 0, 1))

    walkers = post.values.shape[1]
    if steps is None:
        steps = thinned_steps(post.values.shape[0] - burn, walkers)
    values = post.values[burn:][steps]
    kept = {n: walker_major(values[:, :, i]) for i, n in enumerate(post.names)}
    warm = {n: walker_major(post.values[:burn, :, i]) for i, n in enumerate(post.names)}
    with warnings.catch_warnings():
        # walkers are the chains: a short burn-in has more of them than draws, on purpose
        warnings.filterwarnings("ignore", message="More chains", category=UserWarning)
        idata = az.from_dict(
            posterior=kept,
            sample_stats={"lp": walker_major(post.log_prob[burn:][steps])},
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
        "diagnostic_records": records([*post.warnings, *post.diagnostics.records()]),
        # the sides the data alone bound, where the sampler profiled (its report's "> lo")
        "one_sided": dict(post.one_sided),
        "timing": post.timing,
        "idtool_version": __version__,
        "thinning": {
            "kept_steps": int(post.values.shape[0] - burn),
            "stored_steps": int(steps.size),
            "every": int(steps[1] - steps[0]) if steps.size > 1 else 1,
        },
    } | (extra or {})
    for name in ("posterior", "sample_stats"):
        idata[name] = idata[name].assign_coords(draw=steps)
    idata.posterior.attrs["idtool"] = json.dumps(meta)
    for p in post.params:
        idata.posterior[p.name].attrs["units"] = p.unit
        idata.posterior[p.name].attrs["description"] = p.description
    if groups:
        coords = groups["coords"]
        chain = idata.posterior.coords["chain"].values

        def dataset(variables: dict, draws: np.ndarray | None) -> xr.Dataset:
            data = {}
            for var, (dims, arr) in variables.items():
                full = dims if draws is None else ("chain", "draw", *dims)
                data[var] = xr.DataArray(arr, dims=full)
                data[var].attrs["description"] = groups["attrs"].get(var, "")
            c = {d: coords[d] for dims, _ in variables.values() for d in dims if d in coords}
            if draws is not None:
                c |= {"chain": chain, "draw": draws}
            return xr.Dataset(data, coords=c)

        pp_steps = steps[groups["predictive_steps"]] if "predictive_steps" in groups else steps
        idata.add_groups(
            log_likelihood=dataset(groups["log_likelihood"], steps),
            posterior_predictive=dataset(groups["posterior_predictive"], pp_steps),
            observed_data=dataset(groups["observed_data"], None),
            constant_data=dataset(groups["constant_data"], None),
        )
        idata.log_likelihood.attrs["description"] = groups["attrs"]["log_likelihood"]
    return idata


def write_posterior(
    post: PosteriorRecord,
    path: str | os.PathLike,
    extra: dict | None = None,
    groups: dict | None = None,
    steps: np.ndarray | None = None,
) -> Path:
    """Write ``post`` (and the model-check ``groups`` computed at the kept ``steps``) as
    netCDF at ``path``, atomically (temporary file, then rename)."""
    idata = inference_data(post, extra, groups, steps)
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
