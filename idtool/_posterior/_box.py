"""Walkers on the prior box's own coordinates (issue 26).

Every bounded parameter lives on the internal scale ``z`` of
:class:`~idtool._model._params.Param`, a logistic map of its range: for a ``log``
parameter ``ln v = ln lo + (ln hi - ln lo) sigmoid(z)``. That scale suits
Levenberg-Marquardt (unbounded, of order one), but it bends what is straight on the
physical scale. A saturating coupling's gain and load scale are pinned only through
their product where every ``alpha N`` lies past the knee (``a ~ gain A_max P / N``): a
straight valley ``ln gain + ln P = const`` in logarithms, which the logistic maps onto a
curve whose slope changes eightfold along the walkers' range on the "scatter" bench
(seed 101: the gain's internal value from 0.75 to 3.6, near the top of its range, where
``d ln v / dz`` shrinks as ``sigmoid(z) (1 - sigmoid(z))``). Differential evolution's
proposals are straight lines between walkers, and they stall on such a bend (emcee's
integrated times of the gain and the load scale 1,020-1,310 steps in 40,000-step chains).

So the walkers hold, for each boxed parameter, its place in its range,

    u = sigmoid(k z),   k = 1 for a ``log`` parameter, 2 for a ``tanh`` one,

which is ``(ln v - ln lo) / (ln hi - ln lo)`` and ``(v - lo) / (hi - lo)``: an affine
map of the logarithm (or of the value), under which the valley is straight again. The
density on ``u`` is the target's at ``z(u) = logit(u) / k`` times
``|dz/du| = 1 / (k u (1 - u))``; outside ``0 < u < 1`` it is zero (the range's walls,
where a proposal is rejected). A log-uniform prior is flat in ``u``.

Measured (16 walkers x 40,000 steps, sampler seeds 1 and 2, emcee's integrated time on
the internal scale) on "scatter" 101, every bounded parameter boxed, no funnel: the gain
368 and 436, the load scale 425 and 450, against 1,311 and 1,172, 1,198 and 1,018 on the
internal coordinates; the slowest parameter 691 and 633 (Kt, whose plateaus the ridge
then crosses: 61 along it) against 1,311 and 1,172. The box is the base under the ridge's
shear (:mod:`idtool._posterior._ridge`) and the funnel's scaling
(:mod:`idtool._posterior._funnel`): :mod:`idtool._posterior._sample` says which
parameters it boxes where.
"""

from __future__ import annotations

from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array

from idtool._model._params import Param
from idtool._posterior._reparam import AbstractReparameterised
from idtool._posterior._ridge import Ridge

__all__ = ["BoxTarget", "base_internal", "box_slope", "ridge_in_box"]

# The slope k of u = sigmoid(k z) by transform kind: (1 + tanh z) / 2 = sigmoid(2 z)
_SLOPE = {"log": 1.0, "tanh": 2.0}


def box_slope(param: Param) -> float:
    """``k`` of ``u = sigmoid(k z)`` for a bounded parameter, 0 for an unbounded one."""
    return _SLOPE.get(param.kind, 0.0)


class BoxTarget(AbstractReparameterised):
    """A log-posterior on each boxed parameter's place in its range ``u`` (module
    docstring); the other coordinates as the base has them."""

    base: Any  # the LevelsTarget
    slopes: tuple[float, ...] = eqx.field(static=True)  # (ndim,) k per coordinate, 0: not boxed

    @classmethod
    def of(cls, base: Any, boxed: tuple[int, ...] | None = None) -> BoxTarget:
        """``base`` with the bounded parameters among ``boxed`` (indices; None: every
        bounded one) on their range's coordinate."""
        slopes = [box_slope(p) for p in base.params]
        if boxed is not None:
            slopes = [k if i in boxed else 0.0 for i, k in enumerate(slopes)]
        return cls(base, tuple(slopes))

    @property
    def _k(self) -> Array:
        return jnp.asarray(self.slopes, float)

    def to_internal(self, x):
        """Internal vectors ``z`` (..., ndim) of the walkers' ``x`` (inside the walls)."""
        x = jnp.asarray(x)
        k = self._k
        boxed = k > 0.0
        u = jnp.where(boxed, x, 0.5)
        return jnp.where(boxed, (jnp.log(u) - jnp.log1p(-u)) / jnp.where(boxed, k, 1.0), x)

    def from_internal(self, theta):
        """The walkers' ``x`` (..., ndim) of internal vectors ``theta``."""
        theta = jnp.asarray(theta)
        k = self._k
        return jnp.where(k > 0.0, jax.nn.sigmoid(k * theta), theta)

    def log_jacobian(self, x) -> Array:
        """``log |dz / dx|`` (...,) at the walkers' ``x`` (inside the walls)."""
        k = self._k
        boxed = k > 0.0
        u = jnp.where(boxed, x, 0.5)
        terms = -jnp.log(jnp.where(boxed, k, 1.0)) - jnp.log(u) - jnp.log1p(-u)
        return jnp.sum(jnp.where(boxed, terms, 0.0), axis=-1)

    def log_posterior_batch(self, x: Array) -> Array:
        """The base's log-posterior at ``z(x)`` plus ``log |dz/dx|``; ``-inf`` outside
        the walls (``u <= 0`` or ``u >= 1``)."""
        x = jnp.asarray(x)
        boxed = self._k > 0.0
        inside = jnp.all(jnp.where(boxed, (x > 0.0) & (x < 1.0), True), axis=-1)
        safe = jnp.where(inside[..., None], x, jnp.where(boxed, 0.5, x))
        lp = self.base.log_posterior_batch(self.to_internal(safe)) + self.log_jacobian(safe)
        return jnp.where(inside & ~jnp.isnan(lp), lp, -jnp.inf)

    def cov_from_internal(self, theta: np.ndarray, cov: np.ndarray) -> np.ndarray:
        """A covariance ``cov`` (ndim, ndim) of internal vectors near ``theta`` (ndim,),
        carried to the walkers' coordinates to first order (``J cov J``,
        ``J = diag(dx/dz)`` at ``theta``)."""
        k = np.asarray(self.slopes, float)
        u = np.asarray(self.from_internal(jnp.asarray(theta)), float)
        d = np.where(k > 0.0, k * u * (1.0 - u), 1.0)
        return np.asarray(cov, float) * np.outer(d, d)

    def to_doc(self) -> dict:
        """The map as data (recorded with the chain, which holds ``x``)."""
        return {
            "kind": "box",
            "slopes": list(self.slopes),
            "formula": (
                "z[i] = ln(x[i] / (1 - x[i])) / slopes[i] where slopes[i] > 0, else x[i];"
                " applied after the ridge's or the funnel's map, where the chain has one"
            ),
        }

    @classmethod
    def from_doc(cls, base: Any, doc: dict) -> BoxTarget:
        """Rebuilt from :meth:`to_doc` (a resumed chain)."""
        return cls(base, tuple(float(k) for k in doc["slopes"]))


def base_internal(target: Any, x: Array) -> Array:
    """``x`` on ``target``'s walkers' coordinates mapped through every reparameterisation
    down to the levels target's internal scale (a funnel or a ridge over a box, say)."""
    while isinstance(target, AbstractReparameterised):
        x = target.to_internal(x)
        target = target.base
    return x


def ridge_in_box(ridge: Ridge, box: BoxTarget) -> Ridge:
    """``ridge`` (profiled on the internal scale) on ``box``'s coordinates: its grid and
    maximising vectors mapped (the profiled column set to the grid), and its
    log-density per unit of the profiled coordinate's ``u`` (the profile's own less
    ``log |du/dz|``), which the ridge-jump move proposes from
    (:mod:`idtool._posterior._ridge_jump`). ``log_lik`` is the data's and stays."""
    k = box.slopes[ridge.index]
    grid = np.asarray(ridge.grid, float)
    theta = np.array(ridge.theta, float)
    theta[:, ridge.index] = grid
    x = np.asarray(box.from_internal(jnp.asarray(theta)), float)
    if k == 0.0:
        return Ridge(ridge.index, grid, x, ridge.log_post, ridge.log_lik)
    u = x[:, ridge.index]
    log_du_dz = np.log(k) + np.log(u) + np.log1p(-u)
    return Ridge(ridge.index, u, x, np.asarray(ridge.log_post) - log_du_dz, ridge.log_lik)
