"""The levels model as a linear-Gaussian model of the next pulls (universal kriging).

The levels model (:mod:`idtool._fit._variability`) says, per trace ``i`` at operating
point ``x_i = (ln N, alpha, ln v)``:

    y_OFF,i = log F_off(theta; N_i, v_i) + a_i + e_OFF,i
    y_FR,i  = log FR(theta; x_i) + d(x_i) + c_i + e_FR,i                     (P1)

``a``, ``c`` the pull-to-pull scatter (sds ``scatter_mu``, ``scatter_fr``), ``d`` the
discrepancy (a Gaussian process of sd ``discrepancy_fr`` and correlation ``rho``,
:mod:`idtool._fit._discrepancy`), ``e`` the traces' own level noise (covariance ``V``,
:mod:`idtool._fit._free_levels`). Linearised in the physical parameters ``theta``
(internal scale) at the fit's estimate, with ``J = d g / d theta`` (``jax.jacfwd`` of
the model's log levels) and the discrepancy written ``d = s_d R u`` over every
operating point the plan looks at (``R R^T = K``, ``K`` the correlation between them,
``u ~ N(0, I)``), the unknowns ``beta = (theta, u)`` enter linearly:

    y = X beta + eps,   X = [J, s_d P R],   eps ~ N(0, E),   E = V + Sigma(scatter)   (P2)

With a flat prior on ``theta`` and ``u``'s standard normal one, ``beta``'s posterior
covariance is ``Sigma_beta = (X^T E^-1 X + diag(0, I))^-1``; its ``theta`` block is the
fit's ``(J^T C^-1 J)^-1`` (``C = E + s_d^2 P K P^T``), and the variance of the mean log FR
at a target ``x*``, ``f = h^T theta + d(x*)`` with ``a = (h, s_d R[x*])``, is
``a^T Sigma_beta a``: the universal-kriging variance

    k** - k*^T C^-1 k* + (h - J^T C^-1 k*)^T (J^T C^-1 J)^-1 (h - J^T C^-1 k*)     (P3)

(Cressie, *Statistics for Spatial Data*, 1993, eq. 3.4.62), here in information form so
that a new pull, two rows ``X_c`` with noise ``E_c``, is a rank-2 update (Woodbury):

    Sigma_beta' = Sigma_beta - Sigma_beta X_c^T (E_c + X_c Sigma_beta X_c^T)^-1 X_c Sigma_beta  (P4)

A pull at the target itself conditions the target's own discrepancy (its ``u`` column is
the target's), which pulls elsewhere inform only through ``rho``.

A new pull's level noise ``E_c`` (an approximation, said so in the plan): the per-trace
(2, 2) blocks of ``V`` of the measured traces with the planned ON time (else all
measured), each moved to the candidate by the ratios of the levels (the load cell's noise
is absolute: in (log OFF, log ON) the block scales by ``OFF_i / OFF_c`` and
``ON_i / ON_c``, the model's levels at the candidate), their element-wise median; the
shared bench parameters' low-rank
part of ``V`` is left out for the new pull (it is the existing traces'); plus the
scatter. The sds are uncertain: every quantity is computed for ``S`` draws of the sds
from the fit's grids (REML likelihood times the spike-and-slab prior, as predictions
draw them), and the band of a mixture over them.
"""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np

from idtool._fit._artefact import LawFit
from idtool._fit._discrepancy import correlation, length_scales, operating_coordinates, psd_root
from idtool._fit._level_design import level_design
from idtool._fit._variability import SD_PARAMS
from idtool._model._benchmodel import BenchModel

__all__ = ["LinearLaw", "Points", "linear_law", "log_levels_and_jacobian"]


@dataclasses.dataclass(frozen=True)
class Points:
    """Operating points: load [N], amplitude fraction [-], speed [m/s], each (n,)."""

    normal_load_n: np.ndarray
    amplitude_fraction: np.ndarray
    pull_speed_m_s: np.ndarray

    @property
    def coords(self) -> np.ndarray:
        """``(ln N, alpha, ln v)`` (n, 3), rounded so equal points compare equal."""
        x = operating_coordinates(self.normal_load_n, self.amplitude_fraction, self.pull_speed_m_s)
        return np.round(np.asarray(x), 10)

    def __len__(self) -> int:
        return int(np.size(self.normal_load_n))


@jax.jit
def _levels_jacobian(model: BenchModel, theta, load, alpha, speed):
    k = theta.size

    def g(th):
        v = {p.name: p.value(th[i]) for i, p in enumerate(model.shared_params[:k])}
        fr = model.friction_ratios(v, load, alpha, speed)
        off = jax.vmap(lambda n, s: model.law_at(v, n).off_force_n(s))(load, speed)
        return jnp.stack([jnp.log(off), jnp.log(fr)])

    return g(theta), jax.jacfwd(g)(theta)


def log_levels_and_jacobian(
    model: BenchModel, theta: np.ndarray, points: Points
) -> tuple[np.ndarray, np.ndarray]:
    """The model's log OFF level and log FR at ``points`` (2, n) and their Jacobian in
    the physical parameters on the internal scale ``theta`` (2, n, k) (eq. P1)."""
    g, jac = _levels_jacobian(
        model,
        jnp.asarray(theta, float),
        jnp.asarray(points.normal_load_n, float),
        jnp.asarray(points.amplitude_fraction, float),
        jnp.asarray(points.pull_speed_m_s, float),
    )
    return np.asarray(g), np.asarray(jac)


@dataclasses.dataclass
class LinearLaw:
    """One coupling law's linear-Gaussian model (module docstring), for ``S`` draws of
    the sds; updated in place as pulls are added (:meth:`add`).

    ``sigma`` (S, D, D): ``Sigma_beta`` per sd draw, ``beta = (theta (k), u (p))``;
    ``sds`` (S, 3): the distinct draws of (scatter_mu, scatter_fr, discrepancy_fr),
    ``sd_weight`` (S,) their shares; ``root`` (p, p): ``R``;
    ``cand_rows`` (c, 2, D) and ``target_rows`` (t, D): the rows ``X`` of the candidate
    pulls (log OFF, log FR; the discrepancy columns without ``s_d``, applied per draw)
    and the target functionals; ``cand_noise`` (c, 2, 2): a new pull's level noise
    without the scatter; ``log_fr`` (c,) and ``log_off`` (c,) the model's log levels at
    the candidates, ``target_log_fr`` (t,) at the targets.
    """

    name: str
    weight: float
    model: BenchModel
    theta: np.ndarray
    sds: np.ndarray
    sigma: np.ndarray
    cand_rows: np.ndarray
    cand_noise: np.ndarray
    log_off: np.ndarray
    log_fr: np.ndarray
    target_rows: np.ndarray
    target_log_fr: np.ndarray
    k: int
    sd_weight: np.ndarray  # (S,) each distinct sd draw's share of the draws

    def _scaled(self, rows: np.ndarray) -> np.ndarray:
        """``rows`` (..., D) with the discrepancy columns times each draw's ``s_d``:
        (S, ..., D)."""
        scale = np.ones((self.sds.shape[0], rows.shape[-1]))
        scale[:, self.k :] = self.sds[:, 2:3]
        return rows[None] * scale.reshape((scale.shape[0],) + (1,) * (rows.ndim - 1) + (-1,))

    def candidate_noise(self) -> np.ndarray:
        """``E_c`` per sd draw and candidate (S, c, 2, 2): level noise plus scatter."""
        scatter = np.zeros((self.sds.shape[0], 2, 2))
        scatter[:, 0, 0] = self.sds[:, 0] ** 2
        scatter[:, 1, 1] = self.sds[:, 1] ** 2
        return self.cand_noise[None] + scatter[:, None]

    def target_variance(self) -> np.ndarray:
        """Variance of the mean log FR at each target, per sd draw (S, t) (eq. P3)."""
        a = self._scaled(self.target_rows)  # (S, t, D)
        return np.einsum("std,sde,ste->st", a, self.sigma, a)

    def target_variance_after(self) -> np.ndarray:
        """The same after adding each candidate pull alone (S, c, t) (eq. P4)."""
        a = self._scaled(self.target_rows)  # (S, t, D)
        xc = self._scaled(self.cand_rows)  # (S, c, 2, D)
        sx = np.einsum("sde,scje->scjd", self.sigma, xc)  # Sigma X_c^T, (S, c, 2, D)
        m = self.candidate_noise() + np.einsum("scid,scjd->scij", xc, sx)
        ua = np.einsum("scjd,std->sctj", sx, a)  # X_c Sigma a, (S, c, t, 2)
        red = np.einsum("sctj,sctj->sct", ua, np.linalg.solve(m[:, :, None], ua[..., None])[..., 0])
        return self.target_variance()[:, None, :] - red

    def param_variance(self) -> np.ndarray:
        """Variance of each physical parameter (internal scale) now (S, k)."""
        return np.diagonal(self.sigma[:, : self.k, : self.k], axis1=1, axis2=2)

    def param_variance_after(self) -> np.ndarray:
        """Variance of each physical parameter (internal scale) after adding each
        candidate alone (S, c, k), and now (S, 1, k) first: (S, 1 + c, k)."""
        xc = self._scaled(self.cand_rows)
        sx = np.einsum("sde,scje->scjd", self.sigma, xc)
        m = self.candidate_noise() + np.einsum("scid,scjd->scij", xc, sx)
        st = sx[..., : self.k]  # (S, c, 2, k)
        red = np.einsum("scjk,scjk->sck", st, np.linalg.solve(m, st))
        now = self.param_variance()
        return np.concatenate([now[:, None], now[:, None] - red], axis=1)

    def add(self, c: int) -> None:
        """Add candidate pull ``c`` to the design (eq. P4, every sd draw)."""
        xc = self._scaled(self.cand_rows[c])  # (S, 2, D)
        sx = np.einsum("sde,sje->sjd", self.sigma, xc)
        m = self.candidate_noise()[:, c] + np.einsum("sid,sjd->sij", xc, sx)
        self.sigma = self.sigma - np.einsum("sid,sij,sje->sde", sx, np.linalg.inv(m), sx)
        self.sigma = 0.5 * (self.sigma + self.sigma.transpose(0, 2, 1))

    def copy(self) -> LinearLaw:
        return dataclasses.replace(self, sigma=self.sigma.copy())

    def predictive_rows(self, cands: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Mean (2 b,) and covariance per sd draw (S, 2 b, 2 b) of the log levels (OFF,
        FR per pull) of the pulls ``cands`` (b,) under this law."""
        xc = self._scaled(self.cand_rows[cands]).reshape(self.sds.shape[0], -1, self.sigma.shape[1])
        cov = np.einsum("sid,sde,sje->sij", xc, self.sigma, xc)
        noise = self.candidate_noise()[:, cands]  # (S, b, 2, 2)
        b = cands.size
        for j in range(b):
            cov[:, 2 * j : 2 * j + 2, 2 * j : 2 * j + 2] += noise[:, j]
        mean = np.stack([self.log_off[cands], self.log_fr[cands]], axis=1).reshape(-1)
        return mean, cov


_ROOTS: dict[bytes, np.ndarray] = {}


def _root(points: np.ndarray, scales: np.ndarray) -> np.ndarray:
    """``R`` with ``R R^T = K`` between ``points`` (memoised: the pseudo-Bayesian check
    re-linearises at other parameters on the same points)."""
    key = points.tobytes() + scales.tobytes()
    if key not in _ROOTS:
        if len(_ROOTS) > 8:
            _ROOTS.clear()
        _ROOTS[key] = psd_root(np.asarray(correlation(points, points, scales)))
    return _ROOTS[key]


def _sd_draws(law: LawFit, n: int, seed: int) -> np.ndarray:
    """(n, 3) draws of (scatter_mu, scatter_fr, discrepancy_fr) from the fit's grids
    (an sd without a grid: its estimate; no levels model: zeros)."""
    rng = np.random.default_rng([seed, 7])
    out = np.zeros((n, 3))
    sds = {} if law.levels is None else law.levels[1]
    for j, p in enumerate(SD_PARAMS):
        if p.name in law.sd_grids:
            grid, prob = law.sd_grids[p.name]
            out[:, j] = rng.choice(grid, size=n, p=prob / prob.sum())
        elif p.name in sds:
            out[:, j] = sds[p.name][0]
    return out


def _reference_noise(
    law: LawFit, on_time_s: float | None, cand_off_n: np.ndarray, cand_on_n: np.ndarray
) -> np.ndarray:
    """A new pull's level noise (c, 2, 2) in (log OFF, log FR) (module docstring), at
    candidates whose model OFF and ON levels are ``cand_off_n`` and ``cand_on_n`` [N]."""
    assert law.levels is not None
    free = law.levels[0]
    data = law.model.data
    meas = np.flatnonzero(free.measured)
    if free.cov_parts is not None:
        blocks = free.cov_parts.block[meas]
    else:
        full, m = free.covariance(), free.off_n.size
        pos = {i: m + j for j, i in enumerate(meas)}
        blocks = np.array(
            [full[np.ix_(np.array([i, pos[i]]), np.array([i, pos[i]]))] for i in meas]
        )
    if on_time_s is not None:
        length = np.asarray(data.on_end_s)[meas] - np.asarray(data.on_start_s)[meas]
        same = np.abs(length - on_time_s) < 0.05 * on_time_s
        if same.any():
            meas, blocks = meas[same], blocks[same]
    # the load cell's noise is absolute [N]: a level's log has sd (noise / level), so a
    # block moves to a candidate as (log OFF, log ON) scaled by the levels' ratios,
    # S = T diag(off_i / off_c, on_i / on_c) T^-1 with T: (log OFF, log ON) -> (log OFF,
    # log FR). By the load alone the ON ratio was missed: the FR falls with the
    # amplitude and the load, and on the coupling bench the planned pull's log FR sd came
    # out 0.0069 where the measured traces at its point had 0.0046
    r = np.asarray(free.off_n)[meas][None, :] / np.asarray(cand_off_n)[:, None]  # (c, i)
    q = np.asarray(free.on_n)[meas][None, :] / np.asarray(cand_on_n)[:, None]
    scale = np.zeros((*r.shape, 2, 2))
    scale[..., 0, 0] = r
    scale[..., 1, 0] = q - r
    scale[..., 1, 1] = q
    moved = np.einsum("ciab,ibd,cied->ciae", scale, blocks, scale)
    return np.median(moved, axis=1)


def linear_law(
    name: str,
    weight: float,
    law: LawFit,
    candidates: Points,
    targets: Points,
    n_sd_draws: int,
    seed: int,
    on_time_s: float | None = None,
    theta: np.ndarray | None = None,
    sds: np.ndarray | None = None,
) -> LinearLaw:
    """The :class:`LinearLaw` of a fitted coupling law (its levels model) about its
    estimate (or ``theta``, internal scale: a posterior draw), the sds drawn from its
    grids (or ``sds`` (S, 3) given)."""
    if law.levels is None:
        raise ValueError("the fit has no levels model (variability off): nothing to plan on")
    model = law.model
    k = model.n_physical
    theta = np.asarray(law.z[:k] if theta is None else theta, float)
    free = law.levels[0]
    data = model.data
    m = data.n_traces
    meas = np.flatnonzero(free.measured)
    traces = Points(
        np.asarray(data.normal_load_n, float),
        np.asarray(data.amplitude_fraction, float),
        np.asarray(data.pull_speed_m_s, float),
    )
    nc, nt = len(candidates), len(targets)
    every = Points(
        *(
            np.concatenate([getattr(p, f) for p in (traces, candidates, targets)])
            for f in ("normal_load_n", "amplitude_fraction", "pull_speed_m_s")
        )
    )
    g, jac = log_levels_and_jacobian(model, theta, every)
    # the discrepancy's points: the measured traces', the candidates', the targets'
    coords = every.coords
    x_meas = coords[meas]
    x_rest = coords[m:]
    points, where = np.unique(np.concatenate([x_meas, x_rest]), axis=0, return_inverse=True)
    where = np.ravel(where)
    scales = np.asarray(length_scales(data))
    root = _root(points, scales)
    p = points.shape[0]
    dim = k + p
    # existing rows: OFF of every trace, FR of the measured
    x_exist = np.zeros((m + meas.size, dim))
    x_exist[:m, :k] = jac[0, :m]
    x_exist[m:, :k] = jac[1, meas]
    x_exist[m:, k:] = root[where[: meas.size]]
    cand_rows = np.zeros((nc, 2, dim))
    cand_rows[:, 0, :k] = jac[0, m : m + nc]
    cand_rows[:, 1, :k] = jac[1, m : m + nc]
    cand_rows[:, 1, k:] = root[where[meas.size : meas.size + nc]]
    target_rows = np.zeros((nt, dim))
    target_rows[:, :k] = jac[1, m + nc :]
    target_rows[:, k:] = root[where[meas.size + nc :]]
    sd = _sd_draws(law, n_sd_draws, seed) if sds is None else np.asarray(sds, float)
    # distinct draws once each, with their share (the spike at zero repeats)
    sd, counts = np.unique(sd, axis=0, return_counts=True)
    v = free.covariance()  # (n, n): the existing traces' level noise
    design = level_design(model, free.measured)
    kinds = design.kinds
    info = np.empty((sd.shape[0], dim, dim))
    prior = np.zeros((dim, dim))
    prior[k:, k:] = np.eye(p)
    for s, (smu, sfr, sdisc) in enumerate(sd):
        e = v + np.diag(kinds[:, 0] * smu**2 + kinds[:, 1] * sfr**2)
        x = x_exist.copy()
        x[:, k:] *= sdisc
        info[s] = x.T @ np.linalg.solve(e, x) + prior
    # inverted as one stack: one at a time, OpenBLAS's threads cost 30 times the
    # inversion on two busy cores (9 ms against 0.3 ms at dimension 110)
    sigma = np.linalg.inv(info)
    sigma = 0.5 * (sigma + sigma.transpose(0, 2, 1))
    off_c = np.exp(g[0, m : m + nc])
    noise = _reference_noise(law, on_time_s, off_c, off_c * np.exp(g[1, m : m + nc]))
    return LinearLaw(
        name=name,
        weight=weight,
        model=model,
        theta=theta,
        sds=sd,
        sigma=sigma,
        cand_rows=cand_rows,
        cand_noise=noise,
        log_off=g[0, m : m + nc],
        log_fr=g[1, m : m + nc],
        target_rows=target_rows,
        target_log_fr=g[1, m + nc :],
        k=k,
        sd_weight=counts / counts.sum(),
    )
