"""The planning goals' values on the linearised model (:mod:`idtool._plan._linear`).

- ``band``: the 95% band's half-width in FR units at the target operating points (the
  widest of them): the mean FR's band, or the next pull's (its scatter ``scatter_fr``
  added), a mixture over the coupling laws' BIC weights and the sd draws (eq. B1 of
  :mod:`idtool._plan._band`). Lower is better.
- ``parameters``: the largest relative standard error of the physical parameters (Kt,
  mu, the coupling's), ``sd(log value) = sd(z) |d value / d z| / value`` on the chosen
  law, ``sd(z)`` the root of its variance averaged over the sd draws. Lower is better.
- ``laws``: how well the pulls tell the coupling laws apart: for each law ``A`` the
  expected posterior weight it gets if it is the truth,
  ``w_A / sum_B w_B exp(-KL(A || B))``, with ``KL(A || B)`` the Kullback-Leibler
  divergence of the laws' joint predictive distributions of the new pulls' log levels
  (the expected log Bayes factor for A over B when A is true; Chaloner & Verdinelli
  1995, Statist. Sci. 10, §2.2, plug-in at each law's estimate and sds); the goal's value
  is its average over which law is true, by today's weights, ``sum_A w_A E[w_A' | A]``:
  the expected posterior weight of the true law (the Bayesian expected utility of the
  pulls with the posterior probability of the truth as utility; Chaloner & Verdinelli
  §1.4). Higher is better. Not the smallest over the laws: a law kept at weight 0.002
  then set the goal, and the plan spent its pulls on it (the true law's weight rose with
  them on fewer simulated truths than with the weighted average's; issue 29).
"""

from __future__ import annotations

import numpy as np

from idtool._plan._band import mixture_half_width
from idtool._plan._linear import LinearLaw

__all__ = ["GOALS", "band_values", "kl_gaussian", "law_goal", "law_values", "parameter_values"]

GOALS = ("band", "laws", "parameters")


def _mixture(laws: list[LinearLaw], variances: list[np.ndarray], t: int, next_pull: bool):
    """(means, variances, weights) of the mixture (B1) at target ``t``; ``variances``
    per law (S, t)."""
    means, vs, ws = [], [], []
    for law, var in zip(laws, variances, strict=True):
        v = var[:, t] + (law.sds[:, 1] ** 2 if next_pull else 0.0)
        means.append(np.full(v.size, law.target_log_fr[t]))
        vs.append(v)
        ws.append(law.weight * law.sd_weight)
    return np.concatenate(means), np.concatenate(vs), np.concatenate(ws)


def band_values(laws: list[LinearLaw], next_pull: bool, after: bool) -> np.ndarray:
    """The band goal's value (the widest target's half-width [FR]): now (1,), or after
    adding each candidate alone (c,)."""
    if after:
        variances = [law.target_variance_after() for law in laws]  # (S, c, t)
        n_c, n_t = variances[0].shape[1], variances[0].shape[2]
        out = np.empty(n_c)
        for c in range(n_c):
            per = [v[:, c] for v in variances]
            out[c] = max(mixture_half_width(*_mixture(laws, per, t, next_pull)) for t in range(n_t))
        return out
    variances = [law.target_variance() for law in laws]
    n_t = variances[0].shape[1]
    return np.array(
        [max(mixture_half_width(*_mixture(laws, variances, t, next_pull)) for t in range(n_t))]
    )


def relative_sd(law: LinearLaw, var_z: np.ndarray) -> np.ndarray:
    """Relative standard errors (..., k) from the variances of the internal ``z`` (...,
    k): ``sd(z) |d value / d z| / value`` (the delta method)."""
    params = law.model.shared_params[: law.k]
    gain = np.array(
        [p.slope(z) / abs(float(p.value(float(z)))) for p, z in zip(params, law.theta, strict=True)]
    )
    return np.sqrt(np.maximum(var_z, 0.0)) * gain


def parameter_values(law: LinearLaw, after: bool) -> tuple[np.ndarray, np.ndarray]:
    """The parameters goal's value (the largest relative sd) now (1,) or after each
    candidate (c,), and every parameter's relative sd (1 or c, k)."""
    if after:  # (1 + c, k), averaged over the sd draws; now first
        var = np.einsum("s,sck->ck", law.sd_weight, law.param_variance_after())[1:]
    else:  # now alone: the candidates' updates are not needed
        var = np.einsum("s,sk->k", law.sd_weight, law.param_variance())[None]
    rel = relative_sd(law, var)
    return rel.max(axis=1), rel


def kl_gaussian(m0: np.ndarray, s0: np.ndarray, m1: np.ndarray, s1: np.ndarray) -> float:
    """``KL(N(m0, s0) || N(m1, s1))`` [nats]."""
    d = m0.size
    c1 = np.linalg.cholesky(s1)
    c0 = np.linalg.cholesky(s0)
    a = np.linalg.solve(c1, c0)
    r = np.linalg.solve(c1, m1 - m0)
    logdet = 2.0 * (np.sum(np.log(np.diag(c1))) - np.sum(np.log(np.diag(c0))))
    return float(0.5 * (np.sum(a**2) + r @ r - d + logdet))


def law_values(laws: list[LinearLaw], batch: list[int]) -> np.ndarray:
    """Per law, its expected posterior weight if true after the pulls ``batch``
    (candidate indices; module docstring), at each law's first sd draw."""
    w = np.array([law.weight for law in laws])
    if not batch:
        return w
    idx = np.asarray(batch)
    pred = [law.predictive_rows(idx) for law in laws]
    out = np.empty(len(laws))
    for a, (ma, sa) in enumerate(pred):
        kl = np.array(
            [
                0.0 if b == a else kl_gaussian(ma, sa[0], mb, sb[0])
                for b, (mb, sb) in enumerate(pred)
            ]
        )
        out[a] = w[a] / np.sum(w * np.exp(-kl))
    return out


def law_goal(laws: list[LinearLaw], batch: list[int]) -> float:
    """The laws goal's value after the pulls ``batch``: the expected posterior weight of
    the true law, :func:`law_values` averaged over the laws by today's weights
    (module docstring)."""
    w = np.array([law.weight for law in laws])
    return float(np.sum(w * law_values(laws, batch)) / np.sum(w))
