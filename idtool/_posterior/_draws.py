"""A posterior's draws for predictions (:class:`~idtool._predict._predict.Draws`): from a
chain in memory (:class:`~idtool._posterior._record.PosteriorRecord`), from
``posterior.nc`` read back, or for a stored fit whichever it has (its covariance's
without a posterior), averaged over the coupling laws it kept.

The prediction stage (:mod:`idtool._predict`) turns any draws into friction ratios and
knows nothing of chains; the posterior stage, above it, hands it its chain here.
"""

from __future__ import annotations

from pathlib import Path

from idtool._fit._discrepancy import Conditioning
from idtool._fit._store import StoredFit
from idtool._model._benchmodel import BenchModel
from idtool._posterior._record import PosteriorRecord
from idtool._posterior._store import POSTERIOR_FILE, PosteriorDraws, load_posterior
from idtool._predict._mixture import average_over_laws, chosen_law_weight
from idtool._predict._predict import Draws, SdGrids, chain_draws, draws_from_covariance

__all__ = ["draws_from_posterior", "draws_from_stored", "prediction_draws"]


def draws_from_posterior(
    post: PosteriorRecord,
    model: BenchModel,
    max_draws: int = 2000,
    sd_grids: SdGrids | None = None,
    seed: int = 0,
    conditioning: Conditioning | None = None,
) -> Draws:
    """Prediction draws from an in-memory :class:`~idtool._posterior._posterior.Posterior`
    (kept draws, thinned evenly to ``max_draws``); the sds from the posterior, else
    from the fit's ``sd_grids``; the discrepancy conditioned on ``conditioning`` (default:
    the posterior's own)."""
    unconverged = "" if post.diagnostics.converged else "; the chain is NOT converged"
    cond = conditioning or post.conditioning
    chain = post.draws()
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


def prediction_draws(fit: StoredFit, max_draws: int = 2000, seed: int = 0) -> Draws:
    """Draws of a stored fit: its posterior's (``posterior.nc`` beside it), else
    Gaussian on its covariance; averaged over the coupling laws it kept."""
    path = Path(fit.folder) / POSTERIOR_FILE
    cond = fit.conditioning
    if path.is_file():
        stored = load_posterior(path)
        primary = draws_from_stored(stored, fit.model, max_draws, fit.sd_grids, seed, cond)
    else:
        primary = draws_from_covariance(
            fit.model, fit.z, fit.cov_z, max_draws, seed, fit.sd_grids, cond
        )
    weight = chosen_law_weight(fit.doc, fit.model.coupling.name)
    return average_over_laws(primary, weight, fit.alternates, seed)
