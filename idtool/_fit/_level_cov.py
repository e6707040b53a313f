"""The levels model's covariance ``C = V + Sigma(sds)`` in per-trace blocks and a low rank
(issue 28): solves and log-determinants in time and memory linear in the traces.

The levels model (:mod:`idtool._fit._variability`) holds per trace its log OFF level and,
where measured, its log FR. Their covariance has three parts, each structured:

- ``V``, the free levels' covariance (:mod:`idtool._fit._free_levels`): the inverse of
  arrowhead normal equations, so per trace a 2 x 2 block (its own OFF and FR) plus a
  term of rank ``q`` (the shared bench parameters' uncertainty, the same in every
  trace): ``V = blockdiag(V_i) + L L^T``;
- the scatter: diagonal (``scatter_mu^2`` on OFF rows, ``scatter_fr^2`` on FR rows);
- the discrepancy: ``discrepancy_fr^2 zz`` with ``zz = P K P^T``, ``K`` the correlation
  between the ``p`` distinct measured operating points and ``P`` which one each FR row
  is at: rank ``p`` (:mod:`idtool._fit._discrepancy`).

So ``C = B + W W^T`` with ``B`` block-diagonal (2 x 2 per trace) and ``W = [L,
discrepancy_fr D]`` of ``q + p`` columns (``D D^T = zz``); Woodbury's identity gives
``C^-1 = B^-1 - B^-1 W (I + W^T B^-1 W)^-1 W^T B^-1`` and ``log det C = log det B + log
det (I + W^T B^-1 W)``: O(traces (q + p)^2) instead of O(traces^3) (Golub & Van Loan,
*Matrix Computations*, 4th ed., §2.1.4).

Rows are held in pairs, ``(traces, 2)``: (log OFF, log FR) per trace. A trace whose FR
is not measured has its FR row decoupled (block diagonal 1, no low rank, residual and
Jacobian 0): it adds nothing to a solve, a quadratic form or a log-determinant.
:func:`to_pairs` and :func:`from_pairs` map the levels model's row vectors (OFF rows for
every trace, then FR rows for the measured) to and from pairs. NumPy or JAX by argument.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from idtool._fit._discrepancy import correlation, psd_root
from idtool._model._xp import xp

__all__ = [
    "LevelCovariance",
    "discrepancy_root",
    "draw",
    "factor",
    "from_pairs",
    "precision_blocks",
    "solve",
    "to_pairs",
]


@dataclasses.dataclass(frozen=True)
class LevelCovariance:
    """``V`` and ``zz`` in blocks (module docstring), NumPy.

    ``block`` (m, 2, 2): ``V``'s per-trace blocks (FR row and column the identity's where
    unmeasured); ``low`` (m, 2, q): ``L``; ``disc`` (m, 2, p): ``D`` (OFF rows 0);
    ``measured`` (m,) 1.0 where the trace's FR is measured.
    """

    block: np.ndarray
    low: np.ndarray
    disc: np.ndarray
    measured: np.ndarray

    @property
    def arrays(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """The arrays the compiled programs take, in order."""
        return self.block, self.low, self.disc, self.measured

    def dense(self, tau2: np.ndarray) -> np.ndarray:
        """``C`` at the variances ``tau2`` as a dense matrix in the levels model's rows
        (the reference the tests check against; (n, n) memory)."""
        m = self.measured.size
        idx = np.flatnonzero(self.measured)
        rows = np.concatenate([np.arange(m) * 2, idx * 2 + 1])
        full = np.zeros((2 * m, 2 * m))
        b = self.block + _scatter(tau2, self.measured, np)
        for i in range(m):
            full[2 * i : 2 * i + 2, 2 * i : 2 * i + 2] = b[i]
        w = _columns(tau2, self.low, self.disc, np).reshape(2 * m, -1)
        full += w @ w.T
        return full[np.ix_(rows, rows)]

    def quad(self, res_rows: np.ndarray, tau2: np.ndarray | None = None) -> float:
        """``r^T C^-1 r`` of a residual in the levels model's rows, at the variances
        ``tau2`` (default 0: ``V``)."""
        t = np.zeros(3) if tau2 is None else np.asarray(tau2, float)
        rp = to_pairs(np.asarray(res_rows, float), self.measured.astype(bool))[:, :, None]
        return float(np.sum(rp * solve(factor(t, *self.arrays), rp)))


def to_pairs(v, measured: np.ndarray):
    """Rows ``(OFF for every trace, FR for the measured)`` (n, ...) as pairs (m, 2,
    ...), 0 in unmeasured FR rows."""
    x = xp(v)
    m = measured.size
    idx = np.flatnonzero(measured)
    fr = x.zeros((m, *v.shape[1:]))
    fr = fr.at[idx].set(v[m:]) if x is not np else _set(fr, idx, v[m:])
    return x.stack([v[:m], fr], axis=1)


def from_pairs(p, measured: np.ndarray):
    """Inverse of :func:`to_pairs`."""
    x = xp(p)
    return x.concatenate([p[:, 0], p[np.flatnonzero(measured), 1]])


def _set(a: np.ndarray, idx: np.ndarray, v: np.ndarray) -> np.ndarray:
    a[idx] = v
    return a


def discrepancy_root(x_rows: np.ndarray, measured: np.ndarray, scales: np.ndarray) -> np.ndarray:
    """``D`` (m, 2, p): ``D D^T = zz`` on the FR rows, from the measured rows'
    operating-point coordinates ``x_rows`` (n_measured, 3): one column per distinct
    operating point (``zz`` is a function of the coordinates only)."""
    m = measured.size
    idx = np.flatnonzero(measured)
    uniq, where = np.unique(x_rows, axis=0, return_inverse=True)
    root = psd_root(np.asarray(correlation(uniq, uniq, scales)))  # (p, p)
    d = np.zeros((m, 2, uniq.shape[0]))
    d[idx, 1] = root[np.ravel(where)]
    return d


def _scatter(tau2, measured, x):
    """The scatter's diagonal per pair (m, 2, 2): ``scatter_mu^2`` on OFF, ``scatter_fr^2``
    on measured FR rows."""
    diag = x.stack([x.full(measured.shape, tau2[0]), measured * tau2[1]], axis=1)
    return diag[:, :, None] * x.eye(2)


def _columns(tau2, low, disc, x):
    """``W = [L, discrepancy_fr D]`` (m, 2, q + p)."""
    return x.concatenate([low, x.sqrt(tau2[2]) * disc], axis=2)


def factor(tau2, block, low, disc, measured):
    """What solves with ``C`` at the variances ``tau2`` (3,) need: ``B^-1`` (m, 2, 2),
    ``B^-1 W`` (m, 2, r), the Cholesky factor of ``I + W^T B^-1 W`` (r, r) and ``log det
    C`` (module docstring)."""
    x = xp(tau2, block, low, disc)
    b = block + _scatter(tau2, measured, x)
    det = b[:, 0, 0] * b[:, 1, 1] - b[:, 0, 1] * b[:, 1, 0]
    adj = x.stack(
        [x.stack([b[:, 1, 1], -b[:, 0, 1]], axis=1), x.stack([-b[:, 1, 0], b[:, 0, 0]], axis=1)],
        axis=1,
    )
    binv = adj / det[:, None, None]
    w = _columns(tau2, low, disc, x)
    bw = x.einsum("mij,mjr->mir", binv, w)
    inner = x.eye(w.shape[2]) + x.einsum("mir,mis->rs", w, bw)
    chol = x.linalg.cholesky(inner)
    logdet = x.sum(x.log(det)) + 2.0 * x.sum(x.log(x.diagonal(chol)))
    return binv, bw, chol, w, logdet


def solve(f, rhs):
    """``C^-1 rhs`` for ``rhs`` in pairs (m, 2, c), from :func:`factor`'s ``f``."""
    binv, bw, chol, w, _ = f
    x = xp(binv, rhs)
    y = x.einsum("mij,mjc->mic", binv, rhs)
    t = x.einsum("mir,mic->rc", w, y)
    t = x.linalg.solve(chol.T, x.linalg.solve(chol, t))
    return y - x.einsum("mir,rc->mic", bw, t)


def precision_blocks(f):
    """The per-trace (2, 2) diagonal blocks of ``C^-1`` (m, 2, 2), from :func:`factor`'s
    ``f``: ``B_i^-1 - (B^-1 W)_i (I + W^T B^-1 W)^-1 (B^-1 W)_i^T`` (Woodbury), what a
    trace's leave-one-out density needs, without the (n, n) inverse."""
    binv, bw, chol, _, _ = f
    x = xp(binv, bw)
    m, _, r = bw.shape
    u = x.linalg.solve(chol, bw.reshape(2 * m, r).T).reshape(r, m, 2)
    return binv - x.einsum("rmi,rmj->mij", u, u)


def draw(tau2, block, low, disc, measured, eps):
    """A draw of ``N(0, C)`` at the variances ``tau2`` (3,), in pairs (m, 2), from
    standard normals ``eps`` (2 m + r,) (``r`` the columns of ``W``): the first 2 m
    through each trace's ``chol(B_i)``, the last r through ``W``. Its covariance is
    ``B + W W^T = C``: the same Gaussian as ``chol(C) eps`` on the dense matrix, in
    O(m r) instead of O(m^3). Linear in ``eps``; unmeasured FR entries are to be dropped
    (:func:`from_pairs`)."""
    x = xp(tau2, block, low, disc, eps)
    b = block + _scatter(tau2, measured, x)
    m = b.shape[0]
    own = eps[: 2 * m].reshape(m, 2)
    l00 = x.sqrt(b[:, 0, 0])
    l10 = b[:, 1, 0] / l00
    l11 = x.sqrt(b[:, 1, 1] - l10**2)
    lower = x.stack([l00 * own[:, 0], l10 * own[:, 0] + l11 * own[:, 1]], axis=1)
    return lower + x.einsum("mir,r->mi", _columns(tau2, low, disc, x), eps[2 * m :])
