"""The funnel between the discrepancy sd and the physical parameters, opened (issue 26).

The levels model's friction-ratio rows carry the model discrepancy ``discrepancy_fr``
(:mod:`idtool._posterior._levels`): where it is near zero, the rows pin Kt, the coupling's
parameters and whatever else the friction ratio informs to their measurement's
precision; where it is large, the rows say less and those parameters spread. On the
example (16 walkers x 16,000 steps) Kt's internal sd given the discrepancy grows from
0.0054 (discrepancy below 0.0005) to 0.030 (0.013-0.038) and 0.091 (its top 1%, up to
0.22): a funnel, whose narrow end the walkers leave and whose wide end they enter only
in steps scaled to the ensemble's spread. The slowest parameters were the discrepancy
sd, Kt, the gain and the load scale (tau 100-130).

The walkers therefore hold each such parameter's offset from the fit's estimate divided
by the spread's growth, a non-centred parameterisation (Papaspiliopoulos, Roberts &
Skold 2007):

    theta_j = c_j + f(delta) x_j,    f(delta) = sqrt(1 + (delta / delta0)^2),

``delta`` the discrepancy sd (its own coordinate unchanged), ``c`` the fit's estimate,
``delta0`` where the spread has grown by sqrt(2), measured on the posterior itself
(:func:`funnel_scale`). The density on ``x`` is the target's times the Jacobian
``f(delta)^m`` (``m`` parameters scaled). Measured against the plain coordinates
(16 walkers x 16,000 steps, sampler seeds 0 and 1; emcee's integrated time of the
slowest parameter): the example 82, 72 against 129, 127 (Kt's own 30, 39 against 120,
110); the clean departure bench, seed 1: 68, 80 against 144, 136; Kt's 95% intervals
[8.76e8, 1.16e9] twice against [8.74e8, 1.15e9] twice, and [7.18e8, 9.65e8],
[7.08e8, 9.62e8] against [7.13e8, 9.66e8], [7.16e8, 9.62e8] N/m. The slowest parameter
is now the OFF level's scatter (scatter_mu). Not applied along a ridge
(:mod:`idtool._posterior._ridge`), whose coordinates already follow Kt's profile.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array

from idtool._model._params import Param
from idtool._posterior._reparam import AbstractReparameterised

__all__ = ["FUNNEL_SD", "FunnelTarget", "funnel_scale", "open_funnel"]

FUNNEL_SD = "discrepancy_fr"  # the sd whose size the funnel follows
# The discrepancy sds at which the funnel's widening is measured: near zero (the rows at
# their measurement's precision) and 3% (a third of the sd's prior scale, the tail where
# the walkers were slow on the example)
_NEAR_ZERO, _WIDE = 1e-4, 0.03
# Below this widening (conditional sd at _WIDE over that near zero) there is no funnel
# to open: the coordinates stay as they are
_MIN_WIDENING = 1.2
_FD_STEP = 1e-3  # internal units: the curvatures' second differences


def funnel_scale(
    log_post: Callable[[np.ndarray], np.ndarray],
    params: tuple[Param, ...],
    theta: np.ndarray,
    scaled: tuple[int, ...],
    sd_index: int,
) -> float | None:
    """``delta0`` of :class:`FunnelTarget` for the log-posterior ``log_post`` (batched,
    (n, ndim) -> (n,)) at ``theta`` (internal scale): each ``scaled`` parameter's
    curvature (a central second difference) with the sd at :data:`_NEAR_ZERO` and at
    :data:`_WIDE`; their mean ratio ``r`` is the squared widening of the spread,
    ``r = f(_WIDE)^2 / f(_NEAR_ZERO)^2``, which gives
    ``delta0^2 = (_WIDE^2 - r _NEAR_ZERO^2) / (r - 1)``. None where the spread widens by
    less than :data:`_MIN_WIDENING` or a curvature is not positive."""
    sd = params[sd_index]
    rows = []
    for value in (_NEAR_ZERO, _WIDE):
        at = np.array(theta, float)
        at[sd_index] = sd.internal(value)
        for j in scaled:
            for step in (-_FD_STEP, 0.0, _FD_STEP):
                row = at.copy()
                row[j] += step
                rows.append(row)
    lp = np.asarray(log_post(np.array(rows)), float).reshape(2, len(scaled), 3)
    curvature = -(lp[..., 0] - 2.0 * lp[..., 1] + lp[..., 2]) / _FD_STEP**2
    if not np.all(np.isfinite(curvature)) or not np.all(curvature > 0.0):
        return None
    ratio = float(np.mean(curvature[0] / curvature[1]))
    if ratio < _MIN_WIDENING**2:
        return None
    return math.sqrt((_WIDE**2 - ratio * _NEAR_ZERO**2) / (ratio - 1.0))


class FunnelTarget(AbstractReparameterised):
    """A log-posterior on coordinates where the funnel is opened (module docstring): the
    walkers hold ``x``, ``theta_j = centre_j + f(delta) x_j`` for ``j`` in ``scaled``,
    every other coordinate as it is."""

    base: Any  # the LevelsTarget
    centre: Array  # (len(scaled),) the scaled parameters' centres, internal scale
    scaled: tuple[int, ...] = eqx.field(static=True)
    sd_index: int = eqx.field(static=True)
    delta0: float = eqx.field(static=True)

    def widening(self, x):
        """``f(delta)`` at vectors ``x`` (..., ndim): the spread's growth with the sd."""
        delta = self.base.params[self.sd_index].value(x[..., self.sd_index])
        return jnp.sqrt(1.0 + (delta / self.delta0) ** 2)

    def to_internal(self, x):
        """Internal vectors ``theta`` (..., ndim) of the walkers' ``x``."""
        x = jnp.asarray(x)
        idx = jnp.asarray(self.scaled)
        f = self.widening(x)[..., None]
        return x.at[..., idx].set(self.centre + f * (x[..., idx] - self.centre))

    def from_internal(self, theta):
        """The walkers' ``x`` (..., ndim) of internal vectors ``theta``."""
        theta = jnp.asarray(theta)
        idx = jnp.asarray(self.scaled)
        f = self.widening(theta)[..., None]
        return theta.at[..., idx].set(self.centre + (theta[..., idx] - self.centre) / f)

    def log_posterior_batch(self, x: Array) -> Array:
        """The base's log-posterior at ``theta(x)`` plus ``log |d theta / d x|``."""
        jacobian = len(self.scaled) * jnp.log(self.widening(x))
        return self.base.log_posterior_batch(self.to_internal(x)) + jacobian

    def sheared_start(self, theta: np.ndarray, cov: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """A start's centre ``theta`` (ndim,) and covariance on the walkers' coordinates
        (the scaled rows and columns divided by ``f`` at the centre)."""
        f = float(self.widening(jnp.asarray(theta)))
        scale = np.ones(len(theta))
        scale[list(self.scaled)] = 1.0 / f
        x = np.asarray(self.from_internal(jnp.asarray(theta)))
        return x, np.asarray(cov, float) * np.outer(scale, scale)

    def to_doc(self) -> dict:
        """The transform as data (recorded with the chain, which holds ``x``)."""
        return {
            "kind": "funnel",
            "centre": np.asarray(self.centre).tolist(),
            "scaled": list(self.scaled),
            "sd_index": self.sd_index,
            "delta0": self.delta0,
            "formula": "theta[j] = centre[j] + sqrt(1 + (sd / delta0)^2) x[j], j in scaled",
        }

    @classmethod
    def from_doc(cls, base: Any, doc: dict) -> FunnelTarget:
        """Rebuilt from :meth:`to_doc` (a resumed chain)."""
        return cls(
            base,
            jnp.asarray(doc["centre"]),
            tuple(int(i) for i in doc["scaled"]),
            int(doc["sd_index"]),
            float(doc["delta0"]),
        )


def open_funnel(
    base: Any, log_post: Callable[[np.ndarray], np.ndarray], theta: np.ndarray, n_physical: int
) -> FunnelTarget | None:
    """The funnel target of ``base`` (a LevelsTarget) at the walkers' centre ``theta``:
    every physical parameter but ``mu`` (which the OFF levels pin, whatever the
    discrepancy of the friction ratio) scaled by the discrepancy sd's funnel; None when
    the posterior has no discrepancy sd or no funnel (:func:`funnel_scale`)."""
    names = list(base.names)
    if FUNNEL_SD not in names:
        return None
    sd_index = names.index(FUNNEL_SD)
    scaled = tuple(i for i in range(n_physical) if names[i] != "mu")
    delta0 = funnel_scale(log_post, base.params, theta, scaled, sd_index)
    if delta0 is None:
        return None
    centre = jnp.asarray(np.asarray(theta, float)[list(scaled)])
    return FunnelTarget(base, centre, scaled, sd_index, delta0)
