"""A fit's draws for predictions (:class:`~idtool._predict._predict.Draws`), one path for
every consumer (``Fit.draws``, ``Fit.predict``, ``amplitude_for``, ``validate``, the
report, ``compare``, ``Posterior.predict``): :func:`fit_draws`, the chosen law's draws
from its posterior (a chain in memory, :class:`~idtool._posterior._record.PosteriorRecord`,
or ``posterior.nc`` read back) when there is one, else Gaussian on the fit's covariance,
averaged over the coupling laws the fit kept.

The prediction stage (:mod:`idtool._predict`) turns any draws into friction ratios and
knows nothing of chains; the posterior stage, above it, hands it its chain here.
"""

from __future__ import annotations

from pathlib import Path

from idtool._fit._artefact import FitArtefact
from idtool._fit._discrepancy import Conditioning
from idtool._model._benchmodel import BenchModel
from idtool._posterior._record import PosteriorRecord
from idtool._posterior._store import POSTERIOR_FILE, PosteriorDraws, load_posterior
from idtool._predict._mixture import average_over_laws
from idtool._predict._predict import Draws, SdGrids, chain_draws, draws_from_covariance

__all__ = ["draws_from_posterior", "draws_from_stored", "fit_draws", "stored_posterior"]


def draws_from_posterior(
    post: PosteriorRecord,
    model: BenchModel,
    max_draws: int = 2000,
    sd_grids: SdGrids | None = None,
    seed: int = 0,
    conditioning: Conditioning | None = None,
) -> Draws:
    """Prediction draws from an in-memory :class:`~idtool._posterior._posterior.Posterior`
    (the draws ``posterior.nc`` keeps, :meth:`PosteriorRecord.stored_draws`, thinned
    evenly to ``max_draws``: the same as :func:`draws_from_stored` once it is saved);
    the sds from the posterior, else from the fit's ``sd_grids``; the discrepancy
    conditioned on ``conditioning`` (default: the posterior's own)."""
    unconverged = "" if post.diagnostics.converged else "; the chain is NOT converged"
    cond = conditioning or post.conditioning
    chain = post.stored_draws()
    return chain_draws(chain, post.noise, unconverged, model, max_draws, sd_grids, seed, cond)


def draws_from_stored(
    post: PosteriorDraws,
    model: BenchModel,
    max_draws: int = 2000,
    sd_grids: SdGrids | None = None,
    seed: int = 0,
    conditioning: Conditioning | None = None,
) -> Draws:
    """Prediction draws from ``posterior.nc`` read back (:func:`load_posterior`)."""
    unconverged = ""
    if not post.meta["diagnostics"]["converged"]:
        unconverged = "; the chain is NOT converged, see sample.json"
    noise = post.meta["noise"]
    return chain_draws(
        post.values, noise, unconverged, model, max_draws, sd_grids, seed, conditioning
    )


def stored_posterior(folder: Path) -> PosteriorDraws | None:
    """``posterior.nc`` of the fit folder ``folder`` read back, or None without one."""
    path = Path(folder) / POSTERIOR_FILE
    return load_posterior(path) if path.is_file() else None


def fit_draws(
    fit: FitArtefact,
    posterior: PosteriorRecord | PosteriorDraws | None = None,
    max_draws: int = 2000,
    seed: int = 0,
) -> Draws:
    """Draws of ``fit``'s physical parameters: the posterior's (in memory or read back)
    if given, else Gaussian on the chosen fit's covariance; averaged over the coupling
    laws the fit kept by their BIC weights (:mod:`idtool._predict._mixture`)."""
    chosen = fit.chosen
    grids, cond = chosen.sd_grids, chosen.conditioning
    if isinstance(posterior, PosteriorRecord):
        primary = draws_from_posterior(posterior, chosen.model, max_draws, grids, seed, cond)
    elif posterior is not None:
        primary = draws_from_stored(posterior, chosen.model, max_draws, grids, seed, cond)
    else:
        primary = draws_from_covariance(
            chosen.model,
            chosen.z,
            chosen.cov_z,
            max_draws,
            seed,
            grids,
            cond,
            chosen.theta_given_sds,
        )
    return average_over_laws(primary, fit.chosen_weight, fit.alternates, seed, fit.chosen_label)
