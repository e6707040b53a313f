"""What the sampler takes and gives, as data: a fit (:class:`FitLike`) in, a
:class:`PosteriorRecord` out (:func:`idtool._posterior._sample.sample_posterior` between
them; it returns the public :class:`~idtool._posterior._posterior.Posterior`, this
record with its predictions and ArviZ view). The modules that store, check and draw
from a chain read this record, below the :class:`Posterior` that uses them."""

from __future__ import annotations

import dataclasses
import math
from typing import Any, Protocol

import numpy as np

from idtool._errors import IdtoolError
from idtool._fit._cov import Covariance
from idtool._fit._discrepancy import Conditioning
from idtool._fit._free_levels import FreeLevels
from idtool._fit._result import weakly_identified
from idtool._model._benchmodel import BenchModel
from idtool._model._params import Param
from idtool._posterior._diagnostics import Diagnostics
from idtool._posterior._prior import Prior

__all__ = ["LEVELS", "MAX_DRAWS", "FitLike", "PosteriorRecord", "thinned_steps"]

LEVELS = "levels"  # the 'noise' of a chain sampled on the levels model
MAX_DRAWS = 4000  # as many as Stan keeps by default; PSIS-LOO needs a few thousand


def thinned_steps(kept_steps: int, walkers: int, max_draws: int = MAX_DRAWS) -> np.ndarray:
    """Indices into the kept steps: every k-th, k the smallest step so that walkers x
    steps <= ``max_draws``, ending at the last step."""
    k = max(1, math.ceil(kept_steps * walkers / max_draws))
    return np.arange(kept_steps - 1, -1, -k)[::-1]


class FitLike(Protocol):
    """What sampling needs from a fit (``FitResult``, ``LawFit`` and ``idtool.Fit`` have it)."""

    @property
    def model(self) -> BenchModel: ...
    @property
    def z(self) -> np.ndarray: ...
    @property
    def cov_z(self) -> Covariance: ...
    @property
    def phi(self) -> float: ...
    @property
    def noise_state(self) -> np.ndarray: ...
    @property
    def sigma_n(self) -> float: ...
    @property
    def levels(self) -> Any: ...
    @property
    def conditioning(self) -> Conditioning | None: ...


@dataclasses.dataclass(frozen=True)
class PosteriorRecord:
    """An ensemble chain and what it says.

    ``chain`` (steps, walkers, ndim) is on the internal scale, ``values`` the same in
    physical units; the first ``diagnostics.burn`` steps are burn-in.
    """

    params: tuple[Param, ...]
    chain: np.ndarray
    values: np.ndarray
    log_prob: np.ndarray
    acceptance: np.ndarray
    diagnostics: Diagnostics
    noise: str
    priors: dict[str, Prior]
    seed: int
    law: str
    coupling: str
    timing: dict[str, float]
    z_lin: np.ndarray  # BenchModel vector where the nuisances are linearised
    warnings: tuple[str, ...] = ()
    model: BenchModel | None = None  # the model sampled (for predictions)
    conditioning: Conditioning | None = None  # the data the discrepancy is conditioned on
    free_levels: FreeLevels | None = None  # the levels model's data (its noise is LEVELS)
    # per parameter the data bound on one side only ("lower": below only, "upper": above
    # only; idtool._posterior._ridge.open_sides): its interval is stated "> lo" or "< hi"
    one_sided: dict[str, str] = dataclasses.field(default_factory=dict)

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(p.name for p in self.params)

    def draws(self) -> dict[str, np.ndarray]:
        """Kept draws (burn-in dropped) of every parameter, flat, physical units."""
        kept = self.values[self.diagnostics.burn :]
        return {n: kept[:, :, i].ravel() for i, n in enumerate(self.names)}

    def stored_draws(self) -> dict[str, np.ndarray]:
        """The draws ``posterior.nc`` keeps, in the order it reads back: the kept steps
        thinned to at most :data:`MAX_DRAWS` draws (:func:`thinned_steps`), walker by
        walker, physical units. The predictions' draws
        (:func:`idtool._posterior._draws.draws_from_posterior`), so a sampled fit
        predicts the same before it is saved and after it is read back."""
        burn = self.diagnostics.burn
        kept = self.values[burn:][thinned_steps(self.values.shape[0] - burn, self.values.shape[1])]
        return {n: np.swapaxes(kept[:, :, i], 0, 1).ravel() for i, n in enumerate(self.names)}

    def _model(self) -> BenchModel:
        if self.model is None:
            raise IdtoolError("this posterior does not carry its model; predict from the Fit")
        return self.model

    def summary(self) -> dict[str, dict[str, Any]]:
        out = {}
        for p, (name, x) in zip(self.params, self.draws().items(), strict=True):
            lo, med, hi = np.percentile(x, [2.5, 50.0, 97.5])
            out[name] = {
                "median": float(med),
                "ci95": [float(lo), float(hi)],
                "mean": float(np.mean(x)),
                "sd": float(np.std(x)),
                "unit": p.unit,
                "one_sided": self.one_sided.get(name, ""),
                # the contact's and coupling's (an sd's interval reaching towards zero
                # is its spike, not a weak identification)
                "weakly_identified": p.physical
                and weakly_identified(float(lo), float(hi), self.one_sided.get(name, "")),
            }
        return out
