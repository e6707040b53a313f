"""The fit's covariance of ``z`` in the arrowhead's blocks (issue 28): memory linear in
the traces, never a (p, p) matrix.

The fit's normal equations are an arrowhead (:mod:`idtool._fit._arrow`), and their
pseudo-inverse is ``blockdiag(0, D^+) + L^T S^+ L`` with ``L = [I, -X]``,
``X_i = B_i D_i^+`` and ``S`` the Schur complement of the nuisances. In ``z``'s layout
(``s`` shared parameters first, then the nuisances, the j-th of trace i at
``s + j m + i``) that is, with ``n_i`` trace i's nuisances:

- ``C[s, s] = shared`` (s, s);
- ``C[n_i, s] = cross_i`` (nb, s);
- ``C[n_i, n_j] = delta_ij block_i + load_i core load_j^T`` (``block_i`` (nb, nb),
  ``load_i`` (nb, s), ``core`` (s, s)).

For the fit's own covariance ``shared = core = S^+`` and ``cross_i = load_i core``
(``load_i = -X_i^T``, scaled back); :class:`ArrowCovariance` keeps ``shared`` and
``cross`` apart from ``core`` and ``load`` because the levels model replaces the
physical parameters' rows and columns (:meth:`ArrowCovariance.with_leading`), which
leaves the nuisances' own covariance as it was. At 384 traces of bench_scaling's
design (s = 6, nb = 4) that is 0.2 MB where the dense matrix (p = 1542) took 19 MB,
and every reader's operation (the diagonal, the shared block, a column, a quadratic
form, the shared parameters' covariance given the nuisances) runs in O(m nb s^2).

:class:`DenseCovariance` is the same interface on a dense matrix: a fit folder written
before these blocks stores ``cov_z`` dense, and reads back into it, every operation
the expression the readers used on the matrix (so such a folder gives what it gave);
it is also the reference the tests check the blocks against. :func:`covariance_state`
and :func:`covariance_from_state` map either to and from ``fit_state.npz``'s arrays.
NumPy throughout.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping

import numpy as np
from jaxtyping import Float

__all__ = [
    "STATE_KEYS",
    "ArrowCovariance",
    "Covariance",
    "DenseCovariance",
    "covariance_from_state",
    "covariance_state",
]

# fit_state.npz's keys of the blocks, in the order of ArrowCovariance's fields
STATE_KEYS = ("cov_z_shared", "cov_z_cross", "cov_z_block", "cov_z_load", "cov_z_core")


@dataclasses.dataclass(frozen=True)
class ArrowCovariance:
    """A covariance of ``z`` in arrowhead blocks (module docstring).

    Attributes:
        shared: (s, s) the shared parameters' covariance.
        cross: (m, nb, s) each trace's nuisances against the shared parameters.
        block: (m, nb, nb) each trace's own part of its nuisances' covariance.
        load: (m, nb, s) each trace's loading of the rank-``s`` part the traces' nuisances
            share (their common dependence on the shared parameters).
        core: (s, s) the middle of that rank-``s`` part.
    """

    shared: Float[np.ndarray, "s s"]
    cross: Float[np.ndarray, "m nb s"]
    block: Float[np.ndarray, "m nb nb"]
    load: Float[np.ndarray, "m nb s"]
    core: Float[np.ndarray, "s s"]

    @property
    def n_shared(self) -> int:
        """``s``: the shared parameters, first in ``z``."""
        return int(self.shared.shape[0])

    @property
    def size(self) -> int:
        """``p``, the length of ``z``."""
        m, nb = self.block.shape[:2]
        return self.n_shared + m * nb

    def _join(self, vs: np.ndarray, vb: np.ndarray) -> np.ndarray:
        """A vector in ``z``'s layout from its shared (s,) and per-trace (m, nb) parts."""
        return np.concatenate([vs, vb.T.ravel()])

    def _split(self, v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        m, nb = self.block.shape[:2]
        s = self.n_shared
        return v[:s], v[s:].reshape(nb, m).T

    def dense(self) -> Float[np.ndarray, "p p"]:
        """The whole (p, p) matrix: for small problems and the tests (O(p^2) memory)."""
        m, nb, s = self.load.shape
        cross = self.cross.transpose(1, 0, 2).reshape(nb * m, s)  # z's nuisance order
        load = self.load.transpose(1, 0, 2).reshape(nb * m, s)
        out = np.empty((self.size, self.size))
        out[:s, :s] = self.shared
        out[s:, :s] = cross
        out[:s, s:] = cross.T
        out[s:, s:] = load @ self.core @ load.T
        idx = s + np.arange(nb)[None, :] * m + np.arange(m)[:, None]  # (m, nb)
        out[idx[:, :, None], idx[:, None, :]] += self.block
        return out

    def diagonal(self) -> Float[np.ndarray, " p"]:
        """The variances (p,), in ``z``'s layout."""
        low = np.einsum("mbs,st,mbt->mb", self.load, self.core, self.load)
        return self._join(np.diag(self.shared).copy(), np.diagonal(self.block, 0, 1, 2) + low)

    def leading(self, k: int) -> Float[np.ndarray, "k k"]:
        """The covariance of the first ``k`` parameters of ``z`` (k <= s: the physical
        ones, or all the shared), as a new (k, k) array."""
        if k > self.n_shared:
            raise ValueError(f"leading({k}): only the {self.n_shared} shared parameters")
        return self.shared[:k, :k].copy()

    def column(self, i: int) -> Float[np.ndarray, " p"]:
        """Column ``i`` (p,) of the matrix: every parameter's covariance with ``z_i``."""
        s = self.n_shared
        m = self.block.shape[0]
        if i < s:
            return self._join(self.shared[:, i].copy(), self.cross[:, :, i])
        j, t = divmod(i - s, m)  # nuisance j of trace t
        vb = np.einsum("mbs,s->mb", self.load, self.core @ self.load[t, j])
        vb[t] += self.block[t, :, j]
        return self._join(self.cross[t, j].copy(), vb)

    def quad(self, g: Float[np.ndarray, " p"]) -> float:
        """``g^T C g`` (the delta method's variance of a function with gradient ``g``)."""
        gs, gb = self._split(np.asarray(g, float))
        u = np.einsum("mbs,mb->s", self.load, gb)
        return float(
            gs @ self.shared @ gs
            + 2.0 * gs @ np.einsum("mbs,mb->s", self.cross, gb)
            + np.einsum("mb,mbc,mc->", gb, self.block, gb)
            + u @ self.core @ u
        )

    def scaled(self, factor: float) -> ArrowCovariance:
        """``factor`` times the matrix (a residual variance times ``(J^T J)^+``)."""
        return ArrowCovariance(
            factor * self.shared,
            factor * self.cross,
            factor * self.block,
            self.load,
            factor * self.core,
        )

    def with_leading(self, k: int, cov: Float[np.ndarray, "k k"]) -> ArrowCovariance:
        """The first ``k`` parameters' covariance replaced by ``cov`` and their
        covariances with every other parameter set to zero (the levels model's
        estimates of the physical parameters, independent of the fit's others); the
        rest of the matrix unchanged."""
        shared = self.shared.copy()
        shared[:k, :] = 0.0
        shared[:, :k] = 0.0
        shared[:k, :k] = cov
        cross = self.cross.copy()
        cross[:, :, :k] = 0.0
        return dataclasses.replace(self, shared=shared, cross=cross)

    def shared_given_nuisances(self) -> Float[np.ndarray, "s s"]:
        """The shared parameters' covariance with every nuisance held fixed,
        ``C_ss - C_sn C_nn^-1 C_ns``: ``C_nn = blockdiag(block) + load core load^T``
        inverted by Woodbury's identity in the form that needs no inverse of ``core``
        (which a dropped direction leaves singular),
        ``C_nn^-1 = E^-1 - E^-1 Y core (I + Y^T E^-1 Y core)^-1 Y^T E^-1``
        (``E`` the blocks, ``Y`` the loads). Raises ``LinAlgError`` where a block is
        singular (then so is ``C_nn``)."""
        s = self.n_shared
        rhs = np.concatenate([self.cross, self.load], axis=2)
        sol = np.linalg.solve(self.block, rhs)  # E^-1 [W, Y] per trace
        wf = np.einsum("mbs,mbt->st", self.cross, sol)  # W^T E^-1 [W, Y]
        yf = np.einsum("mbs,mbt->st", self.load, sol)  # Y^T E^-1 [W, Y]
        inner = np.linalg.solve(np.eye(s) + yf[:, s:] @ self.core, yf[:, :s])
        return self.shared - (wf[:, :s] - wf[:, s:] @ self.core @ inner)


@dataclasses.dataclass(frozen=True)
class DenseCovariance:
    """:class:`ArrowCovariance`'s interface on a dense (p, p) matrix: a fit folder's
    ``cov_z`` written before the blocks, and the tests' reference (module docstring).

    Attributes:
        matrix: (p, p) the covariance of ``z``.
        n_shared: ``s``, the shared parameters first in ``z``.
    """

    matrix: Float[np.ndarray, "p p"]
    n_shared: int

    @property
    def size(self) -> int:
        return int(self.matrix.shape[0])

    def dense(self) -> Float[np.ndarray, "p p"]:
        return self.matrix

    def diagonal(self) -> Float[np.ndarray, " p"]:
        return np.diag(self.matrix)

    def leading(self, k: int) -> Float[np.ndarray, "k k"]:
        return self.matrix[:k, :k].copy()

    def column(self, i: int) -> Float[np.ndarray, " p"]:
        return self.matrix[:, i]

    def quad(self, g: Float[np.ndarray, " p"]) -> float:
        return float(g @ self.matrix @ g)

    def scaled(self, factor: float) -> DenseCovariance:
        return DenseCovariance(factor * self.matrix, self.n_shared)

    def with_leading(self, k: int, cov: Float[np.ndarray, "k k"]) -> DenseCovariance:
        out = self.matrix.copy()
        out[:k, :] = 0.0
        out[:, :k] = 0.0
        out[:k, :k] = cov
        return DenseCovariance(out, self.n_shared)

    def shared_given_nuisances(self) -> Float[np.ndarray, "s s"]:
        s, rest = slice(0, self.n_shared), slice(self.n_shared, self.size)
        css, csn, cnn = self.matrix[s, s], self.matrix[s, rest], self.matrix[rest, rest]
        return css - csn @ np.linalg.solve(cnn, csn.T)


Covariance = ArrowCovariance | DenseCovariance


def covariance_state(cov: Covariance) -> dict[str, np.ndarray]:
    """``cov`` as ``fit_state.npz`` stores it: the blocks under :data:`STATE_KEYS`, or a
    dense matrix as ``cov_z`` (a folder written before the blocks, saved again)."""
    if isinstance(cov, DenseCovariance):
        return {"cov_z": np.asarray(cov.matrix)}
    parts = (cov.shared, cov.cross, cov.block, cov.load, cov.core)
    return {key: np.asarray(a) for key, a in zip(STATE_KEYS, parts, strict=True)}


def covariance_from_state(state: Mapping[str, np.ndarray], n_shared: int) -> Covariance:
    """The covariance a state file holds: its blocks (since issue 28), else the dense
    ``cov_z`` of a folder written before them."""
    if STATE_KEYS[0] in state:
        return ArrowCovariance(*(np.asarray(state[key], float) for key in STATE_KEYS))
    return DenseCovariance(np.asarray(state["cov_z"]), n_shared)
