"""A friction-ratio band from a mixture of Gaussians in log FR.

The linearised model (:mod:`idtool._plan._linear`) gives, per coupling law ``l`` (BIC
weight ``w_l``) and per draw ``s`` of the sds, the mean log FR at a target ``m_l`` and
its variance ``v_ls``. What predictions draw is then the mixture

    log FR ~ sum_l w_l (1/S) sum_s N(m_l, v_ls)                                   (B1)

and its 95% band the mixture's 2.5% and 97.5% quantiles ``q``, in FR ``exp(q)`` (capped
at 1, as predictions cap every draw). The half-width in FR units is half the band's
width: ``(min(e^q_hi, 1) - min(e^q_lo, 1)) / 2``.
"""

from __future__ import annotations

import numpy as np

__all__ = ["mixture_half_width", "mixture_quantiles"]


def mixture_quantiles(
    means: np.ndarray, variances: np.ndarray, weights: np.ndarray, probs=(0.025, 0.975)
) -> np.ndarray:
    """Quantiles of the mixture of ``N(means[i], variances[i])`` with ``weights[i]``
    (flat arrays, weights summing to 1; eq. B1) at ``probs``, by bisection (60 halvings:
    to round-off). A zero variance is a point mass."""
    # here, not at the top: the fit's import path (idtool._entry -> Fit.plan) stays
    # without scipy.special, which idtool fit imports in the background
    # (test_scipy_special_is_off_the_fits_import_path_and_imported_in_the_background)
    from scipy.special import ndtr

    m = np.ravel(means)
    sd = np.sqrt(np.maximum(np.ravel(variances), 1e-300))
    w = np.ravel(weights) / np.sum(weights)
    spread = 10.0 * float(np.max(sd)) + 1e-12
    out = []
    for p in probs:
        lo, hi = float(m.min()) - spread, float(m.max()) + spread
        for _ in range(60):
            mid = 0.5 * (lo + hi)
            if float(w @ ndtr((mid - m) / sd)) < p:
                lo = mid
            else:
                hi = mid
        out.append(0.5 * (lo + hi))
    return np.asarray(out)


def mixture_half_width(means, variances, weights) -> float:
    """Half the 95% band's width in FR units (eq. B1) of the mixture in log FR."""
    q = mixture_quantiles(means, variances, weights)
    fr = np.minimum(np.exp(q), 1.0)
    return float(0.5 * (fr[1] - fr[0]))
