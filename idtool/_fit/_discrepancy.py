"""The physical model's discrepancy as a smooth function of the operating point (issue 10).

What the physical model misses is not noise: a coupling law of the wrong shape misses
neighbouring operating points by similar amounts. The levels model
(:mod:`idtool._fit._variability`) therefore treats the discrepancy of log FR as a
Gaussian process over the operating point ``x = (ln N, alpha, ln v)``:

    d(x) ~ GP(0, discrepancy_fr^2 rho(x, x')),
    rho(x, x') = exp(-1/2 sum_j ((x_j - x'_j) / l_j)^2)

with length scales ``l_j`` half the range the design spans in each coordinate
(:func:`length_scales`; floored where the design does not vary). Why half the range:
with two or three levels per coordinate, as on the paper's matrix, neighbouring levels
are then correlated (0.14-0.6), so a measured operating point informs the held-out ones
between its neighbours, while beyond about two length scales outside the design the
discrepancy reverts to its full, unconditional sd: extrapolation is not trusted. A
design this small cannot estimate the length scales; the coverage tests on data from
other coupling laws (tests/test_coverage.py) check the choice.

Predictions condition the discrepancy on the traces' own friction ratios (kriging,
:class:`Conditioning`): at an operating point the data measured, the mean-FR band follows
the data and is as narrow as they are; between measured points it is interpolated; far
from them it carries the whole discrepancy sd. Given the physical parameters theta and the
sds, ``d(x*) | y`` is Gaussian with

    mean  s_d^2 k*^T S^-1 (y - g(theta)),   variance  s_d^2 - s_d^4 k*^T S^-1 k*,
    S = V + s_c^2 I + s_d^2 K

over the measured friction ratios ``y`` (their noise covariance ``V``, scatter sd
``s_c``): exact for each draw of (theta, sds) from their posterior, so the draws carry
the whole uncertainty.
"""

from __future__ import annotations

import dataclasses
import functools

import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float

from idtool._data._blocks import FitData
from idtool._model._xp import xp

__all__ = [
    "SCALE_FLOORS",
    "Conditioning",
    "correlation",
    "discrepancy_moments",
    "length_scales",
    "operating_coordinates",
    "psd_root",
]

# Smallest length scales, for coordinates the design does not vary (or barely): 10% in
# load and speed, 0.05 in amplitude fraction. The discrepancy at another load than the
# only one measured is then unconditional a little way off it.
SCALE_FLOORS = np.array([0.1, 0.05, 0.1])
NUGGET_FRACTION = 0.1


def operating_coordinates(load_n: ArrayLike, alpha: ArrayLike, speed_m_s: ArrayLike) -> Array:
    """``(ln N, alpha, ln v)`` of operating points, (..., 3): loads [N] and speeds
    [m/s] on log scales (the model's response is multiplicative in both). NumPy on
    NumPy input, JAX on JAX input (:mod:`idtool._model._xp`)."""
    x = xp(load_n, alpha, speed_m_s)
    return x.stack(
        [x.log(x.asarray(load_n)), x.asarray(alpha), x.log(x.asarray(speed_m_s))],
        axis=-1,
    )


def length_scales(data: FitData) -> np.ndarray:
    """The correlation length per coordinate: half the design's range, floored
    (:data:`SCALE_FLOORS`; module docstring)."""
    x = np.asarray(operating_coordinates(data.op_load_n, data.op_alpha, data.op_speed_m_s))
    return np.maximum(0.5 * np.ptp(x, axis=0), SCALE_FLOORS)


def correlation(
    xa: Float[ArrayLike, "a 3"], xb: Float[ArrayLike, "b 3"], scales: Float[ArrayLike, " 3"]
) -> Float[Array, "a b"]:
    """The discrepancy's correlation between operating points (module docstring); NumPy
    or JAX by argument."""
    x = xp(xa, xb, scales)
    diff = (x.asarray(xa)[:, None, :] - x.asarray(xb)[None, :, :]) / x.asarray(scales)
    smooth = x.exp(-0.5 * x.sum(diff**2, axis=-1))
    same = x.all(x.abs(diff) < 1e-9, axis=-1)
    return (1.0 - NUGGET_FRACTION) * smooth + NUGGET_FRACTION * same


def discrepancy_moments(
    x_new: Float[ArrayLike, "p 3"],
    x_rows: Float[ArrayLike, "n 3"],
    scales: Float[ArrayLike, " 3"],
    weights: Float[ArrayLike, " n"],
    s_inv: Float[ArrayLike, "n n"],
    sd_disc: Float[ArrayLike, ""],
) -> tuple[Float[Array, " p"], Float[Array, " p"]]:
    """Mean and variance of the discrepancy at ``x_new`` given the data, for one draw
    (module docstring): ``weights = S^-1 (y - g)`` and ``s_inv = S^-1`` of that draw
    (zeros for the unconditional discrepancy). Jittable."""
    s2 = jnp.asarray(sd_disc) ** 2
    k = correlation(x_new, x_rows, scales)  # (p, n)
    mean = s2 * (k @ weights)
    reduction = jnp.einsum("pn,nm,pm->p", k, s_inv, k)
    return mean, jnp.maximum(s2 - s2**2 * reduction, 0.0)


def psd_root(a: np.ndarray) -> np.ndarray:
    """``R`` with ``R R^T = a`` for a symmetric positive semi-definite ``a`` (eigenvalues
    below 0 by round-off clipped to 0)."""
    w, u = np.linalg.eigh(a)
    return u * np.sqrt(np.maximum(w, 0.0))


@dataclasses.dataclass(frozen=True)
class Conditioning:
    """What conditioning the discrepancy on the data needs: the measured friction
    ratios' coordinates ``x`` (n, 3), their free estimates ``y`` (log FR, n) and noise
    covariance ``V``, and the length scales. ``V`` is either ``v`` (n, n), dense (a fit
    folder written before the blocks), or, with ``v`` None, ``diag(v_diag) + v_low
    v_low^T`` (``v_low`` (n, q): the shared parameters' rank; memory linear in the
    traces).

    The discrepancy is a function of the operating point, so the rows enter the
    predictions only through the ``p`` distinct points they were measured at
    (:attr:`points`): with ``P`` (n, p) which point each row is at, the kriging moments
    need ``P^T S^-1 (y - g)`` and ``P^T S^-1 P`` (module docstring), per draw (p,) and
    (p, p) whatever the traces (issue 28: (draws, n, n) was 1 GB at 384 traces and
    2000 draws). ``S = A + s_d^2 P K P^T`` with ``A = V + s_c^2 I``: a dense ``V``'s
    eigenvectors (once) give ``A^-1`` at every scatter sd; ``V`` in blocks gives it by
    Woodbury's identity over its rank ``q``, per draw; Woodbury's identity then adds the
    discrepancy's rank ``p``.
    """

    x: np.ndarray
    y: np.ndarray
    v: np.ndarray | None
    scales: np.ndarray
    v_diag: np.ndarray | None = None
    v_low: np.ndarray | None = None

    @functools.cached_property
    def _layout(self) -> tuple[np.ndarray, np.ndarray]:
        """The distinct points (p, 3) and which one each row is at (n,)."""
        points, where = np.unique(self.x, axis=0, return_inverse=True)
        return points, np.ravel(where)

    @property
    def points(self) -> np.ndarray:
        """The distinct operating points' coordinates (p, 3) the rows were measured at."""
        return self._layout[0]

    @property
    def rows(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Load [N], amplitude fraction and speed [m/s] of the distinct :attr:`points`."""
        x = self.points
        return np.exp(x[:, 0]), x[:, 1], np.exp(x[:, 2])

    @functools.cached_property
    def _eigen(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """``V``'s eigenvalues (n,) and eigenvectors (n, n), ``P^T Q`` (p, n) and a root
        ``R`` (p, p) of the points' correlation ``K``."""
        points, where = self._layout
        assert self.v is not None  # the dense path
        lam, q = np.linalg.eigh(self.v)
        pq = np.zeros((points.shape[0], q.shape[1]))
        np.add.at(pq, where, q)
        root = psd_root(np.asarray(correlation(points, points, self.scales)))
        return lam, q, pq, root

    def weights(
        self, log_fr_model: np.ndarray, sd_disc: np.ndarray, sd_scatter: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """Per draw: ``P^T S^-1 (y - g)`` (draws, p) and ``P^T S^-1 P`` (draws, p, p),
        from the model's log FR at the :attr:`points` (draws, p) and the draws' sds
        (draws,): the arguments ``weights`` and ``s_inv`` of
        :func:`discrepancy_moments` with ``x_rows`` the :attr:`points`."""
        where = self._layout[1]
        res = self.y[None] - np.asarray(log_fr_model)[:, where]  # (d, n)
        if self.v is None:
            g, h = self._in_blocks(res, np.asarray(sd_scatter))
            root = self._root
        else:
            lam, q, pq, root = self._eigen
            inv = 1.0 / (lam[None, :] + (np.asarray(sd_scatter) ** 2)[:, None])  # (d, n)
            g = np.einsum("pn,dn,qn->dpq", pq, inv, pq)  # P^T A^-1 P
            h = np.einsum("pn,dn->dp", pq, inv * (res @ q))  # P^T A^-1 (y - g)
        s2 = (np.asarray(sd_disc) ** 2)[:, None, None]
        gr = g @ root  # (d, p, p)
        inner = np.eye(root.shape[1])[None] + s2 * (root.T[None] @ gr)
        s_inv = g - s2 * gr @ np.linalg.solve(inner, gr.transpose(0, 2, 1))
        rh = np.einsum("pr,dp->dr", root, h)[:, :, None]
        weights = h - (s2 * gr @ np.linalg.solve(inner, rh))[:, :, 0]
        return weights, s_inv

    @functools.cached_property
    def _root(self) -> np.ndarray:
        """A root ``R`` (p, p) of the points' correlation ``K``."""
        points = self.points
        return psd_root(np.asarray(correlation(points, points, self.scales)))

    def _in_blocks(self, res: np.ndarray, sd_scatter: np.ndarray) -> tuple[np.ndarray, ...]:
        """``P^T A^-1 P`` (d, p, p) and ``P^T A^-1 res`` (d, p) per draw with ``A =
        diag(v_diag + s_c^2) + U U^T`` (``U = v_low``): ``A^-1 = E - E U (I + U^T E
        U)^-1 U^T E``, ``E`` the diagonal's inverse; O(n q^2) per draw, nothing (n, n)."""
        assert self.v_diag is not None and self.v_low is not None
        u = self.v_low
        n, q = u.shape
        where = self._layout[1]
        p = self.points.shape[0]
        e = 1.0 / (self.v_diag[None, :] + (sd_scatter**2)[:, None])  # (d, n)
        onehot = np.zeros((n, p))
        onehot[np.arange(n), where] = 1.0
        pu = np.stack([e[:, where == j] @ u[where == j] for j in range(p)], axis=1)  # P^T E U
        utu = (e @ (u[:, :, None] * u[:, None, :]).reshape(n, q * q)).reshape(-1, q, q)
        er = e * res
        inner = np.eye(q)[None] + utu
        rhs = np.concatenate([pu.transpose(0, 2, 1), (er @ u)[:, :, None]], axis=2)
        sol = np.linalg.solve(inner, rhs)  # (d, q, p + 1)
        g = np.einsum("dp,pq->dpq", e @ onehot, np.eye(p)) - pu @ sol[:, :, :p]
        h = er @ onehot - (pu @ sol[:, :, p:])[:, :, 0]
        return g, h
