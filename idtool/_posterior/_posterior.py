"""The posterior the public API hands out (:class:`Posterior`): the sampler's record of
a chain (:class:`~idtool._posterior._record.PosteriorRecord`: its draws, diagnostics and
summary) with what it is for: predictions (the prediction stage, below this one, from
its draws) and its ArviZ ``InferenceData`` (the store and the model-check groups, which
read the record)."""

from __future__ import annotations

import dataclasses

from idtool._fit._artefact import FitArtefact
from idtool._posterior._draws import draws_from_posterior, fit_draws
from idtool._posterior._groups import model_check_groups
from idtool._posterior._record import LEVELS, FitLike, PosteriorRecord
from idtool._posterior._store import inference_data
from idtool._predict._tables import amplitude_table, predict_table

__all__ = ["LEVELS", "FitLike", "Posterior"]


@dataclasses.dataclass(frozen=True)
class Posterior(PosteriorRecord):
    """An ensemble chain and what it says, and what it predicts.

    ``chain`` (steps, walkers, ndim) is on the internal scale, ``values`` the same in
    physical units; the first ``diagnostics.burn`` steps are burn-in. ``fit``: the fit
    sampled (set by :meth:`idtool.Fit.sample`), whose other coupling laws its predictions
    average over, as the fit's own do (:func:`~idtool._posterior._draws.fit_draws`).
    """

    fit: FitArtefact | None = dataclasses.field(default=None, repr=False, compare=False)

    def _draws(self, max_draws: int, seed: int = 0):
        """The prediction draws: the fit's path when the posterior knows its fit."""
        if self.fit is not None:
            return fit_draws(self.fit, self, max_draws, seed)
        return draws_from_posterior(self, self._model(), max_draws, seed=seed)

    def predict(self, load_n, amplitude, speed_m_s=None, *, max_draws: int = 2000, seed: int = 0):
        """Friction ratio (median, 95% band) over loads [N] x amplitude fractions x
        speeds [m/s] from the kept draws: :class:`idtool.Predictions`. ``seed`` seeds
        the discrepancy's and scatter's draws (as ``Fit.predict``'s)."""
        draws = self._draws(max_draws, seed)
        return predict_table(draws, self._model().data, load_n, amplitude, speed_m_s)

    def amplitude_for(
        self, reduction_percent: float, load_n, speed_m_s=None, *, max_draws=2000, seed: int = 0
    ):
        """The amplitude fraction for a target reduction [%]: :class:`idtool.Amplitudes`;
        ``seed`` as in :meth:`predict`."""
        draws = self._draws(max_draws, seed)
        data = self._model().data
        return amplitude_table(draws, data, reduction_percent, load_n, speed_m_s)

    def to_arviz(self):
        """The chain as ArviZ ``InferenceData``: the content of ``posterior.nc``, with
        the groups ``az.loo``, ``az.compare`` and ``az.plot_ppc`` need when the
        posterior carries its model (README, "posterior.nc in ArviZ")."""
        if self.model is None:
            return inference_data(self)
        groups, steps = model_check_groups(self)
        return inference_data(self, None, groups, steps)
