"""Predictions averaged over coupling laws (issue 11, item 3).

The coupling law's shape is assumed, and between or beyond the measured loads the laws
can fit the data equally well and still disagree. ``fit --coupling auto`` fits every
registered law; predictions then pool draws of each law in proportion to its BIC
weight ``w_k = exp(-BIC_k / 2) / sum_j exp(-BIC_j / 2)`` (Kass & Raftery 1995: BIC
approximates each law's marginal likelihood, so ``w_k`` is its posterior probability
under equal prior odds; Bayesian model averaging, Hoeting et al. 1999). Stacking
(Yao et al. 2018) would weigh the laws by held-out predictive performance instead; with
one pull per operating point and a few operating points, its leave-one-out weights
rest on too few points to be stable, and BIC's nested-model penalty is the
conservative choice here.

The chosen law's draws are its posterior's when it was sampled, else Gaussian on its
fit's covariance; the other laws' always come from their fits' covariances, each with
its own levels model (scatter and discrepancy), so every law's band is as honest as the
chosen one's. A law below :data:`~idtool._fit._run.MIN_LAW_WEIGHT` is not kept; one
whose share of the draws rounds to zero adds nothing.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from idtool._diagnostic import Diagnostic
from idtool._predict._predict import (
    Draws,
    Prediction,
    _thin,
    draws_from_covariance,
)

__all__ = [
    "DISAGREE_WEIGHT",
    "average_over_laws",
    "law_disagreement_notes",
    "law_medians",
]

# Laws that hold at least this BIC weight count when the laws' curves are compared
DISAGREE_WEIGHT = 0.05


def average_over_laws(
    primary: Draws,
    chosen_weight: float,
    others: Mapping[str, tuple[float, Any]],
    seed: int = 0,
    chosen_label: str | None = None,
) -> Draws:
    """``primary`` (the chosen law's draws) pooled with draws of each other law in
    ``others`` (law -> (BIC weight, its fit: ``model``, ``z``, ``cov_z``, ``sd_grids``,
    ``conditioning``, ``theta_given_sds``)), each law's share of ``primary.n`` draws
    its weight's; the weights renormalised over the laws kept. ``chosen_label``: the
    chosen model's name among them (default its coupling law's; with the directions
    compared, ``others`` names models by direction too, :func:`idtool._fit._run.model_label`)."""
    if not others:
        return primary
    chosen = primary.model.coupling.name if chosen_label is None else chosen_label
    weights = {chosen: chosen_weight} | {law: w for law, (w, _) in others.items()}
    total = sum(weights.values())
    weights = {law: w / total for law, w in weights.items()}
    n = primary.n
    first = dataclasses.replace(
        primary.subset(_thin(n, max(round(n * weights[chosen]), 1))), label=chosen
    )
    parts = []
    for i, (law, (_, fit)) in enumerate(others.items()):
        count = round(n * weights[law])
        if count < 1:
            continue
        part = draws_from_covariance(
            fit.model,
            fit.z,
            fit.cov_z,
            count,
            seed + 1 + i,
            fit.sd_grids,
            fit.conditioning,
            fit.theta_given_sds,
        )
        parts.append(dataclasses.replace(part, label=law))
    shares = ", ".join(
        f"{law} {w:.2f} ({'its fit covariance' if law != chosen else primary.source})"
        for law, w in weights.items()
    )
    note = (
        f"{primary.note}; averaged over {_what(others, primary)} by BIC weight: {shares} "
        f"({sum(d.n for d in (first, *parts))} draws pooled)"
    )
    return dataclasses.replace(first, mixture=tuple(parts), law_weights=weights, note=note)


def _what(others: Mapping[str, tuple[float, Any]], primary: Draws) -> str:
    """What the models averaged over differ in: coupling laws, directions or both."""
    fits = [fit for _, fit in others.values()]
    directions = {primary.model.direction.name, *(f.model.direction.name for f in fits)}
    couplings = {primary.model.coupling.name, *(f.model.coupling.name for f in fits)}
    if len(directions) == 1:
        return "coupling laws"
    return "directions of vibration" if len(couplings) == 1 else "coupling laws and directions"


def law_disagreement_notes(rows: Sequence[Prediction], weights: Mapping[str, float]) -> list[str]:
    """One note for the operating points where the coupling laws that hold at least
    :data:`DISAGREE_WEIGHT` of the weight differ, in median mean FR, by half the
    averaged 95% band or more: there the data do not tell the laws apart, and the band
    carries their spread (worst three points named)."""
    hits = []
    for p in rows:
        medians = {law: m for law, m in p.by_law if weights.get(law, 0.0) >= DISAGREE_WEIGHT}
        if len(medians) < 2:
            continue
        spread = max(medians.values()) - min(medians.values())
        width = p.ci95[1] - p.ci95[0]
        if spread >= 0.5 * width and spread > 0.0:
            hits.append((spread, p, medians))
    if not hits:
        return []
    hits.sort(key=lambda h: -h[0])
    where = "; ".join(
        f"{p.normal_load_n:g} N, amplitude {p.amplitude_fraction:g}: "
        + ", ".join(f"{law} {m:.3f}" for law, m in medians.items())
        + f" (band {p.ci95[0]:.3f}-{p.ci95[1]:.3f})"
        for _, p, medians in hits[:3]
    )
    return [
        Diagnostic(
            "coupling_laws",
            f"the coupling laws disagree at {len(hits)} of {len(rows)} points by half the "
            f"band or more ({where}): the data do not tell the laws apart there, and the band "
            "includes their spread; pulls there would decide",
            points=len(hits),
            of=len(rows),
        )
    ]


def law_medians(rows: Sequence[Prediction]) -> dict[str, np.ndarray]:
    """Each law's median mean FR over ``rows`` (empty without averaging)."""
    laws = [law for law, _ in rows[0].by_law] if rows else []
    return {law: np.array([dict(p.by_law)[law] for p in rows]) for law in laws}
