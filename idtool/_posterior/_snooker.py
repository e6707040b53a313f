"""The differential-evolution snooker move of ter Braak & Vrugt (2008), as emcee's
``DESnookerMove`` means it to be.

emcee 3.1.6 (the latest release) projects onto ``delta / sqrt(|delta|)``, which is not
a unit vector, and weighs the Hastings factor by ``(ndim - 1) / 2``: the step along the
snooker line then grows with the walker's distance from the reference walker, the move
is not reversible, and the chain does not sample its target. On a two-dimensional
target with a peak between two plateaus (tests/test_ridge_jump.py) it put 0.205 of the
mass on the plateaus where quadrature gives 0.275 (0.274 with DE alone). Fixed upstream
after that release (emcee pull request 531: the unit vector ``delta / |delta|`` and the
factor ``ndim - 1``); this is that move, until a release carries it.

The proposal (ter Braak & Vrugt 2008, section 3): for walker ``x`` and three walkers
``z, z1, z2`` of the complementary ensemble, ``e = (x - z) / |x - z|`` and
``x' = x + gamma e (e . (z1 - z2))``, accepted with the factor
``(ndim - 1) log(|x' - z| / |x - z|)``.
"""

from __future__ import annotations

from typing import Any

import numpy as np

__all__ = ["snooker_move"]


def _proposal(gamma: float, s: np.ndarray, c: list[np.ndarray], random: Any):
    ns, ndim = s.shape
    q = np.empty_like(s)
    factor = np.empty(ns, dtype=np.float64)
    for i in range(ns):
        w = np.array([part[random.randint(len(part))] for part in c[:3]])
        random.shuffle(w)
        z, z1, z2 = w
        delta = s[i] - z
        norm = np.linalg.norm(delta)
        e = delta / norm
        q[i] = s[i] + e * gamma * np.dot(e, z1 - z2)
        factor[i] = (ndim - 1.0) * (np.log(np.linalg.norm(q[i] - z)) - np.log(norm))
    return q, factor


def snooker_move(gamma: float = 1.7):
    """An ``emcee.moves.DESnookerMove`` whose proposal is ter Braak & Vrugt's (module
    docstring); ``gamma`` the mean step along the snooker line (1.7, theirs and emcee's
    default)."""
    import emcee

    class Snooker(emcee.moves.DESnookerMove):
        def get_proposal(self, s, c, random):
            return _proposal(self.gammas, s, c, random)

    return Snooker(gammas=gamma)
