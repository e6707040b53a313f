"""Normal equations of a least-squares problem with per-group parameters: the arrowhead.

A bench fit has ``s`` shared parameters and ``b`` nuisances per trace, and each trace's
residuals depend on its own nuisances only. ``J^T J`` is then an arrowhead: a dense
shared block ``A`` (s, s), per trace a coupling ``B_i`` (s, b) and a diagonal block
``D_i`` (b, b), zero between traces. :class:`Arrow` holds just these blocks (memory
linear in the traces) and solves a damped system by eliminating the nuisances through
their Schur complement, ``S = A - sum_i B_i D_i^-1 B_i^T`` (the bundle adjustment
recipe: Triggs et al., *Bundle adjustment: a modern synthesis*, 2000, §6.1), in time
linear in the traces instead of cubic. :class:`DenseNormal` is the same interface on the
dense matrices, the reference the tests check the arrowhead against.

Layout of the parameter vector ``z``: the ``s`` shared parameters first, then the
nuisances group by group (the j-th nuisance of trace i at ``s + j m + i``), as
:class:`idtool._model._benchmodel.BenchModel` orders them.
"""

from __future__ import annotations

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Bool, Float

from idtool._fit._cov import ArrowCovariance, Covariance, DenseCovariance
from idtool._model._xp import xp

__all__ = [
    "Arrow",
    "ArrowInverse",
    "DenseNormal",
    "arrow_pinv",
    "block_index",
    "inverse_and_weakest",
]


def block_index(n_shared: int, n_groups: int, per_group: int) -> np.ndarray:
    """(groups, per_group) position in ``z`` of each group's nuisances (module
    docstring's layout)."""
    return n_shared + np.arange(per_group)[None, :] * n_groups + np.arange(n_groups)[:, None]


class Arrow(eqx.Module):
    """``J^T J`` and ``J^T r`` in arrowhead blocks (module docstring).

    Attributes:
        a: (s, s) shared block.
        b: (m, s, nb) coupling of the shared parameters with each group's nuisances.
        d: (m, nb, nb) each group's own block.
        gs: (s,) shared part of ``J^T r``.
        gb: (m, nb) each group's part of ``J^T r``.
    """

    a: Float[Array, "s s"]
    b: Float[Array, "m s nb"]
    d: Float[Array, "m nb nb"]
    gs: Float[Array, " s"]
    gb: Float[Array, "m nb"]

    def split(self, v: Float[Array, " p"]) -> tuple[Array, Array]:
        """A vector in ``z``'s layout as (shared (s,), per group (m, nb))."""
        s = self.a.shape[0]
        m, nb = self.gb.shape
        return v[:s], v[s:].reshape(nb, m).T

    @staticmethod
    def join(vs: Array, vb: Array) -> Float[Array, " p"]:
        """Inverse of :meth:`split` (NumPy for NumPy blocks: no one-operation program
        in the fit's summary)."""
        return xp(vs, vb).concatenate([vs, vb.T.ravel()])

    @property
    def grad(self) -> Float[Array, " p"]:
        """``J^T r`` in ``z``'s layout."""
        return self.join(self.gs, self.gb)

    def diagonal(self) -> Float[Array, " p"]:
        """The diagonal of ``J^T J`` in ``z``'s layout."""
        return self.join(jnp.diag(self.a), jnp.diagonal(self.d, axis1=1, axis2=2))

    def matvec(self, h: Float[Array, " p"]) -> Float[Array, " p"]:
        """``J^T J h``."""
        hs, hb = self.split(h)
        ys = self.a @ hs + jnp.einsum("msb,mb->s", self.b, hb)
        yb = jnp.einsum("msb,s->mb", self.b, hs) + jnp.einsum("mbc,mc->mb", self.d, hb)
        return self.join(ys, yb)

    def masked(self, mask: Bool[Array, " p"]) -> Arrow:
        """Parameters outside ``mask`` frozen: identity rows and columns, zero gradient."""
        ms, mb = self.split(mask)
        nb = self.d.shape[-1]
        a = jnp.where(ms[:, None] & ms[None, :], self.a, jnp.diag(jnp.where(ms, 0.0, 1.0)))
        b = jnp.where(ms[None, :, None] & mb[:, None, :], self.b, 0.0)
        both = mb[:, :, None] & mb[:, None, :]
        eye = jnp.where(mb[:, :, None], 0.0, jnp.eye(nb))
        d = jnp.where(both, self.d, eye)
        return Arrow(a, b, d, jnp.where(ms, self.gs, 0.0), jnp.where(mb, self.gb, 0.0))

    def solve(self, shift: Float[Array, " p"], v: Float[Array, " p"]) -> Float[Array, " p"]:
        """``x`` with ``(J^T J + diag(shift)) x = v``: each group's nuisances eliminated
        (batched (nb, nb) solves), the (s, s) Schur complement solved densely, the
        nuisances back-substituted. Exact, like a dense solve, in O(m)."""
        s = self.a.shape[0]
        ss, sb = self.split(shift)
        vs, vb = self.split(v)
        d = self.d + sb[:, :, None] * jnp.eye(self.d.shape[-1])
        # D_i^-1 [B_i^T, v_i] for every group at once: (m, nb, s + 1)
        x = jnp.linalg.solve(d, jnp.concatenate([self.b.transpose(0, 2, 1), vb[:, :, None]], 2))
        schur = self.a + jnp.diag(ss) - jnp.einsum("msb,mbt->st", self.b, x[..., :s])
        xs = jnp.linalg.solve(schur, vs - jnp.einsum("msb,mb->s", self.b, x[..., s]))
        xb = x[..., s] - jnp.einsum("mbs,s->mb", x[..., :s], xs)
        return self.join(xs, xb)

    def dense(self) -> tuple[Float[Array, "p p"], Float[Array, " p"]]:
        """The dense ``J^T J`` (p, p) and ``J^T r`` (p,): for the reference and for
        callers that need the whole matrix (O(p^2) memory)."""
        s = self.a.shape[0]
        m, nb = self.gb.shape
        idx = block_index(s, m, nb)  # (m, nb)
        jtj = jnp.zeros((s + m * nb,) * 2).at[:s, :s].set(self.a)
        jtj = jtj.at[np.arange(s)[None, :, None], idx[:, None, :]].set(self.b)
        jtj = jtj.at[idx[:, :, None], np.arange(s)[None, None, :]].set(self.b.transpose(0, 2, 1))
        jtj = jtj.at[idx[:, :, None], idx[:, None, :]].set(self.d)
        return jtj, self.grad

    def as_dense(self) -> DenseNormal:
        """The same equations as a :class:`DenseNormal` (the reference path)."""
        return DenseNormal(*self.dense())


class DenseNormal(eqx.Module):
    """Dense ``J^T J`` (p, p) and ``J^T r`` (p,) with :class:`Arrow`'s interface: the
    reference (an LU solve of the whole matrix, O(p^3))."""

    jtj: Float[Array, "p p"]
    jtr: Float[Array, " p"]

    @property
    def grad(self) -> Float[Array, " p"]:
        return self.jtr

    def diagonal(self) -> Float[Array, " p"]:
        return jnp.diag(self.jtj)

    def matvec(self, h: Float[Array, " p"]) -> Float[Array, " p"]:
        return self.jtj @ h

    def masked(self, mask: Bool[Array, " p"]) -> DenseNormal:
        both = mask[:, None] & mask[None, :]
        eye = jnp.eye(mask.size)
        jtj = jnp.where(both, self.jtj, jnp.where(mask[:, None] | mask[None, :], 0.0, eye))
        return DenseNormal(jtj, jnp.where(mask, self.jtr, 0.0))

    def solve(self, shift: Float[Array, " p"], v: Float[Array, " p"]) -> Float[Array, " p"]:
        return jnp.linalg.solve(self.jtj + jnp.diag(shift), v)

    def dense(self) -> tuple[Float[Array, "p p"], Float[Array, " p"]]:
        return self.jtj, self.jtr


class ArrowInverse(eqx.Module):
    """The Moore-Penrose inverse of ``J^T J`` computed from its arrowhead blocks
    (NumPy, :func:`arrow_pinv`), and the spectra the fit's singularity check reads.

    Attributes:
        inverse: the inverse, in ``z``'s layout, in its blocks (never (p, p)).
        shared_evals, shared_evecs: eigen-decomposition of the scaled Schur complement
            of the nuisances, ``S = A - sum_i B_i D_i^+ B_i^T`` (s, s): the curvature of
            the shared parameters with the nuisances profiled out.
        block_evals, block_evecs: those of each scaled block ``D_i`` (m, nb), (m, nb, nb).
        largest: the largest eigenvalue of the scaled ``A`` and ``D_i``.
    """

    inverse: ArrowCovariance
    shared_evals: np.ndarray
    shared_evecs: np.ndarray
    block_evals: np.ndarray
    block_evecs: np.ndarray
    largest: float


def arrow_pinv(arrow: Arrow, rcond: float = 1e-13) -> ArrowInverse:
    """``(J^T J)^+`` from the arrowhead blocks, in O(m (s + nb)^3) time and O(m nb s)
    memory, kept in its blocks (:class:`~idtool._fit._cov.ArrowCovariance`; the dense
    pseudo-inverse is O(p^3): 11 s at 384 traces, p = 1544, and 19 MB).

    As the fit's dense covariance did: the matrix is first scaled to a unit diagonal
    (zero columns, parameters the data do not move, keep scale 1), and eigenvalues below
    ``rcond`` times the largest (of the scaled ``A`` and ``D_i``) count as zero, in each
    block ``D_i`` and in the Schur complement. For a regular matrix this is its inverse
    (block elimination is exact); a zero column gets zero variance, as with ``pinv``.
    """
    a, b, d = (np.asarray(x, float) for x in (arrow.a, arrow.b, arrow.d))
    scale_s = np.sqrt(np.diag(a))
    scale_b = np.sqrt(np.diagonal(d, axis1=1, axis2=2))
    scale_s = np.where(scale_s > 0.0, scale_s, 1.0)
    scale_b = np.where(scale_b > 0.0, scale_b, 1.0)
    a = a / np.outer(scale_s, scale_s)
    b = b / (scale_s[None, :, None] * scale_b[:, None, :])
    d = d / (scale_b[:, :, None] * scale_b[:, None, :])
    block_evals, block_evecs = np.linalg.eigh(d)
    largest = float(max(np.linalg.eigvalsh(a).max(), block_evals.max()))
    floor = rcond * largest
    kept = block_evals > floor
    inv_evals = np.where(kept, 1.0 / np.where(kept, block_evals, 1.0), 0.0)
    d_inv = np.einsum("mij,mj,mkj->mik", block_evecs, inv_evals, block_evecs)
    x = np.einsum("msb,mbc->msc", b, d_inv)  # B_i D_i^+
    schur = a - np.einsum("msb,mtb->st", x, b)
    schur = 0.5 * (schur + schur.T)
    shared_evals, shared_evecs = np.linalg.eigh(schur)
    keep = shared_evals > floor
    inv_shared = np.where(keep, 1.0 / np.where(keep, shared_evals, 1.0), 0.0)
    schur_inv = (shared_evecs * inv_shared) @ shared_evecs.T
    # the inverse is blockdiag(0, D^+) + [I; -X^T] S^+ [I, -X], X = (B_i D_i^+)_i, kept in
    # those blocks (idtool._fit._cov), each scaled back
    core = schur_inv / np.outer(scale_s, scale_s)
    load = -np.transpose(x, (0, 2, 1)) * scale_s[None, None, :] / scale_b[:, :, None]
    return ArrowInverse(
        inverse=ArrowCovariance(
            shared=core,
            cross=np.einsum("mbs,st->mbt", load, core),
            block=d_inv / (scale_b[:, :, None] * scale_b[:, None, :]),
            load=load,
            core=core,
        ),
        shared_evals=shared_evals,
        shared_evecs=shared_evecs,
        block_evals=block_evals,
        block_evecs=block_evecs,
        largest=largest,
    )


def inverse_and_weakest(
    normal: Arrow | DenseNormal, n_shared: int, rcond: float = 1e-13
) -> tuple[Covariance, float, np.ndarray]:
    """``(J^T J)^+`` (scaled to a unit diagonal, eigenvalues below ``rcond`` times the
    largest dropped: :func:`arrow_pinv`), in blocks on the arrowhead, dense
    (:class:`~idtool._fit._cov.DenseCovariance`, ``n_shared`` shared parameters first)
    on the dense reference; the ratio of the smallest
    eigenvalue of the scaled matrix to its largest, and that eigenvector (p,) (in
    ``z``'s layout), for the fit's near-singularity warning.

    On the arrowhead the smallest eigenvalue is taken over the Schur complement (the
    shared parameters, nuisances profiled out) and the traces' blocks, the largest over
    ``A`` and the blocks: the same near-singular directions as the whole matrix's, at
    O(m) instead of O(p^3). The dense reference decomposes the whole matrix."""
    if isinstance(normal, DenseNormal):
        jtj = np.asarray(normal.jtj)
        scale = np.sqrt(np.diag(jtj))
        scale = np.where(scale > 0.0, scale, 1.0)
        scaled = jtj / np.outer(scale, scale)
        evals, evecs = np.linalg.eigh(scaled)
        inverse = np.linalg.pinv(scaled, rcond=rcond, hermitian=True) / np.outer(scale, scale)
        dense = DenseCovariance(inverse, n_shared)
        return dense, float(evals[0] / evals[-1]), evecs[:, 0]
    inv = arrow_pinv(normal, rcond)
    s = inv.shared_evals.size
    m, nb = inv.block_evals.shape
    vector = np.zeros(s + m * nb)
    i, j = np.unravel_index(np.argmin(inv.block_evals), inv.block_evals.shape)
    if inv.shared_evals[0] <= inv.block_evals[i, j]:
        smallest = float(inv.shared_evals[0])
        vector[:s] = inv.shared_evecs[:, 0]
    else:
        smallest = float(inv.block_evals[i, j])
        vector[block_index(s, m, nb)[i]] = inv.block_evecs[i, :, j]
    return inv.inverse, smallest / inv.largest, vector
