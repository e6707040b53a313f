"""Every trace's own OFF and ON levels, fitted freely: stage 1 of the levels model.

The hierarchical model of the levels (:mod:`idtool._fit._variability`) works on a
summary of the traces: every trace's OFF and ON levels fitted freely, with the bench
nuisances (offsets, pull starts, horn lags, actuator slopes), on the same AR(1)-whitened
block means as the fit. Their estimates ``y`` (log OFF, log FR) and covariance ``V``
summarise what the traces say about the levels; the bench model is linear in the levels,
so this summary loses nothing to first order. An ON window too short for the force to
settle (``MIN_AT_LEVEL_S``) does not measure its ON level: that trace's FR is left out
(its OFF level stays). Its ON level is still freed, as a nuisance, wherever the trace
informs it at all (``INFORMED_ON``): held at the physical model's value, the model's
error there went into the trace's OFF level. On the departure bench "all" (seed 602, a
coupling law the fit does not ship and a lag actuator) the block fit's FR was 20-35%
high at the three ON windows of 1 s that end just short of settling; held there, their
OFF levels came out 1.3-3.3% high with standard errors 0.6x the honest ones, and mu
0.8% high, outside its interval; freed, they are within 0.5% of their truths. Everything
here reuses the fit's own linearisation (no new program to compile).
"""

from __future__ import annotations

import dataclasses
import math

import jax.numpy as jnp
import numpy as np

from idtool._data._blocks import padded_size
from idtool._fit._compiled import program
from idtool._fit._discrepancy import psd_root
from idtool._fit._level_cov import LevelCovariance, from_pairs
from idtool._fit._lm import coloured_blocks
from idtool._fit._program import level_structure, run_lm
from idtool._model._benchmodel import BenchModel

__all__ = ["INFORMED_ON", "MIN_AT_LEVEL_S", "FreeLevels", "free_levels", "model_log_levels"]

# An ON level counts as measured when the force sits at it for this long (about four
# 40 ms blocks): shorter, the trace only bounds it (its depth is beyond the slope's reach).
MIN_AT_LEVEL_S = 0.15
# An unmeasured ON level is freed (a nuisance, no FR row) when its information in the
# trace is at least this fraction of the OFF level's. A lag window that ends in the
# approach to its level gives 0.15-0.5 (departure "all", seed 602); one that ends in the
# rate-limited fall 0, the slope model's rounded corner (not identifiable, CORNER_N)
# 1e-8 to 5e-6 (clean, seed 1: freed there, the Gauss-Newton step moved two ON levels by
# 176 and 294 N). Held below it, the model's value moves the OFF level by at most
# sqrt(1e-3) = 3% of the value's error.
INFORMED_ON = 1e-3
# A trace's nuisance (its offset, pull start, horn lags: ``u`` past its levels) whose
# information in the whitened block means is below this, on its internal scale (its sd
# above 1,000 of its scales: 10 s for a horn lag), is held where the fit left it, out of
# the step and of the levels' covariance. A trace whose horn did not lower the force
# (planned at 670 N and 10%, FR 1) shows no switch: its lags have no information, the
# step sent one by -10.8 s, the ON window emptied and the next step took the ON level to
# -367 N; the levels model was lost and the intervals fell back to the noise-only ones
# (issue 29's laws study: 3 of 20 benches, which held 14 of its 20 FR misses; held, the
# levels model stands on 2 of them, and the study's FR misses fall to 14 of 120).
UNINFORMED_NUISANCE = 1e-6
# Gauss-Newton in ``u`` goes on from the first step while a step moves a level by more
# than this fraction of itself. The block means are linear in a level only where the
# force sits at it: the ramps into and out of the ON level last (OFF - ON) / slope, so a
# first step from a physical model far from the data is biased. On the departure bench
# "coupling" (seed 3: a coupling law the fit does not ship; the physical model's ON level
# at 670 N, 50% 22 N below the data's) one step left those traces' own FRs at 0.42
# against their truth 0.461, 14 standard errors off, and the FR bands at all six measured
# operating points missed their truths; iterated, they are within their errors. The
# error left by one step grows as the step squared (relative ~0.9 x step^2 there), so a
# first step under 1% leaves ~1e-4 (on the example, a twentieth of the FRs' standard
# errors) and costs nothing more.
ITERATE_ABOVE = 0.01
# ... each step halved until the residuals fall (a step from far off may overshoot: the
# lag actuator's approach is curved), and stops when no level moves by more than this
# fraction, or after MAX_STEPS; where no step lowers the residuals, the last one stands.
CONVERGED_BELOW = 1e-6
MAX_STEPS = 20
# The free levels' own noise state replaces the fit's when they differ as much as the
# fit's own refits would go on for (AbstractNoise.state_settled, idtool._fit._fit).


@dataclasses.dataclass(frozen=True)
class FreeLevels:
    """Every trace's OFF and ON level fitted freely (module docstring).

    ``y`` holds log OFF for every trace, then log FR for the traces in ``measured``;
    its covariance (AR(1) noise, nuisances and shared slopes integrated) is
    ``cov_parts``, in per-trace blocks and a low rank (memory linear in the traces), or
    ``cov_y``, dense (n, n), read from a fit folder written before the blocks: one of
    the two is set. :meth:`covariance` gives the dense matrix either way.
    """

    off_n: np.ndarray
    on_n: np.ndarray
    measured: np.ndarray  # (traces,) the ON level is reached and measured
    y: np.ndarray
    cov_y: np.ndarray | None
    sigma_n: float
    # the covariance in per-trace blocks and a low rank (disc empty)
    cov_parts: LevelCovariance | None = None

    def covariance(self) -> np.ndarray:
        """``y``'s covariance as a dense (n, n) matrix: for the dense reference paths
        (a fit folder without the blocks) and the tests (O(n^2) memory)."""
        if self.cov_y is not None:
            return self.cov_y
        assert self.cov_parts is not None
        return self.cov_parts.dense(np.zeros(3))

    def variances(self) -> np.ndarray:
        """The variances of ``y`` (n,), from the blocks where there are (no (n, n))."""
        if self.cov_y is not None:
            return np.diag(self.cov_y)
        assert self.cov_parts is not None
        p = self.cov_parts
        pairs = np.diagonal(p.block, 0, 1, 2) + np.sum(p.low**2, axis=2)
        return from_pairs(pairs, self.measured)

    def fr_covariance(self) -> np.ndarray:
        """The covariance of the log FR rows (the measured traces'), dense (n_FR, n_FR):
        what the predictions' conditioning takes from a fit folder written before the
        blocks (:class:`~idtool._fit._discrepancy.Conditioning` diagonalises it once; on
        the blocks it takes their diagonal and low rank), and the tests' reference."""
        if self.cov_y is not None:
            m = self.off_n.size
            return self.cov_y[m:, m:]
        assert self.cov_parts is not None
        idx = np.flatnonzero(self.measured)
        low = self.cov_parts.low[idx, 1]
        return np.diag(self.cov_parts.block[idx, 1, 1]) + low @ low.T

    @property
    def friction_ratio(self) -> np.ndarray:
        """Each trace's own FR (NaN where its ON level is not measured)."""
        return np.where(self.measured, self.on_n / self.off_n, np.nan)

    @property
    def friction_ratio_se(self) -> np.ndarray:
        m = self.off_n.size
        se = np.full(m, np.nan)
        k = np.flatnonzero(self.measured)
        se_log = np.sqrt(self.variances()[m:])
        se[k] = self.friction_ratio[k] * se_log
        return se


def _at_level_s(model: BenchModel, z: np.ndarray, levels: np.ndarray) -> np.ndarray:
    """Per trace: how long the force sits at its ON level [s] (-inf without ON), from
    the levels ``(OFF, ON)`` [N] at ``z``."""
    d = model.data
    v = model.values(np.asarray(z, float))
    off, on = np.split(levels, 2)
    start = np.asarray(d.on_start_s) + np.asarray(v["delay_on_s"])
    end = np.asarray(d.on_end_s) + np.asarray(v["delay_off_s"])
    with np.errstate(invalid="ignore", divide="ignore"):  # traces without ON: -inf
        length = np.where(np.isfinite(start) & np.isfinite(end), end - start, -np.inf)
        settle = np.asarray(model.actuator_of(v).settle_time_s(off - on))
    return length - settle


def _linearise(model: BenchModel, z: np.ndarray, state):
    """The fit's own linearisation at ``z`` (no new program to compile): the whitened
    residuals, the levels ``(OFF, ON)``, their Jacobian in the physical parameters and
    each trace's blocks of the normal equations in ``u = (OFF, ON, z[k:])`` (colours:
    the shared bench parameters, the trace's OFF and ON levels, its nuisances;
    :func:`~idtool._fit._program.bench_normal_equations`)."""
    out = run_lm(model, np.asarray(z, float), np.ones(z.size, bool), state, 0)
    lv, dlv, cc, cr = (np.asarray(x) for x in out.aux)
    return np.asarray(out.residuals), lv, dlv, cc, cr


def free_levels(model: BenchModel, z: np.ndarray, state) -> FreeLevels:
    """The traces' own levels, from the fit ``z`` and its noise ``state`` (the noise
    model's correlation state, :mod:`idtool._model._noise`; module docstring).

    One Gauss-Newton step in ``u`` from the fit's optimum: the block means are linear
    in the levels wherever the force sits at them, so the step lands on the free
    optimum up to the nuisances' second-order terms (on the example, Levenberg-Marquardt
    run to convergence in ``u`` moved the free FRs by ~1e-4, a twentieth of their
    standard errors; measured while this was written, not a test).

    The noise state (AR(1): phi) is the free levels' own, from their residuals (like the
    noise sd): the fit's ``phi`` comes from residuals that hold its model's misfit of the
    levels, which it reads as slow noise. On the departure bench "all" (a coupling law
    the fit does not ship) the fit's phi was 0.97 and the free levels' 0.75 (residuals
    1.8 N rms against 0.47 N): at 0.97 the OFF levels' standard errors came out 1.8x
    their errors' spread and the scatter of mu half its truth, below its interval.
    """
    z = np.asarray(z, float)
    free, u = _free_step(model, z, state)
    noise = model.noise
    if noise.autoregressive:
        white = noise.initial_state()
        e = np.asarray(_level_residuals(model, jnp.asarray(u), jnp.asarray(z), white))
        own = noise.estimate_state(e, np.asarray(model.data.first))
        if not noise.state_settled(state, own):
            free, _ = _free_step(model, z, own)
    return free


@program()
def _level_residuals(model: BenchModel, u, z, state):
    """:meth:`BenchModel.level_residuals` as one program: run op by op it compiled (or
    loaded from the cache) ~100 one-operation programs, ~0.4 s of a warm fit."""
    return model.level_residuals(u, z, state)


def _u_layout(model: BenchModel) -> tuple[np.ndarray, np.ndarray]:
    """Positions in ``u`` of the shared bench parameters (sb,) and of each trace's own
    inputs (m, 2 + nb): its OFF level, its ON level, its nuisances (the colours' order)."""
    group, m = model.level_group, model.data.n_traces
    own = np.stack([np.flatnonzero(group == i) for i in range(m)])
    return np.flatnonzero(group < 0), own


def _free_step(
    model: BenchModel, z: np.ndarray, state, max_steps: int = MAX_STEPS
) -> tuple[FreeLevels, np.ndarray]:
    """:func:`free_levels` at a given noise ``state``, and ``u`` at the free optimum
    (Gauss-Newton from the physical levels, at most ``1 + max_steps`` steps: module
    constants).

    The normal equations in ``u`` are an arrowhead (the shared bench parameters, then
    per trace its levels and nuisances): solved through the Schur complement of the
    trace blocks (:mod:`idtool._fit._arrow`'s recipe), and the levels' covariance kept
    as per-trace blocks plus the shared parameters' low rank
    (:mod:`idtool._fit._level_cov`): linear in the traces, where the dense (6 traces)^2
    system cost traces^3."""
    k, m = model.n_physical, model.data.n_traces
    w, lv, _, cc, cr = _linearise(model, z, state)
    shared, own = _u_layout(model)
    sb = shared.size
    measured = _at_level_s(model, z, lv) >= MIN_AT_LEVEL_S
    on_free = measured | (cc[:, sb + 1, sb + 1] > INFORMED_ON * cc[:, sb, sb])
    u = np.concatenate([lv, z[k:]])
    # the levels the FRs are read from: every OFF level, the measured ON levels
    levels = np.concatenate([np.arange(m), m + np.flatnonzero(measured)])

    def step_of(solved) -> np.ndarray:
        h = np.zeros_like(u)
        h[shared], h[own] = solved[0], solved[1]
        return h

    solved = _gauss_newton(w, cc, cr, sb, on_free)
    h = step_of(solved)
    if _moved(h, u, levels) > ITERATE_ABOVE:
        for _ in range(max_steps):
            better = _line_search(model, z, state, u, h, float(w @ w), levels, sb, on_free)
            if better is None:
                break  # no decrease along the step: the last step stands
            u, (w, cc, cr), solved = better
            h = step_of(solved)
            if _moved(h, u, levels) <= CONVERGED_BELOW:
                break
    h_s, h_b, d_inv, e, schur_inv, held = solved
    u = u - h
    # the residual sum of squares at the free optimum, to second order
    rss = float(w @ w) - float(cr[:, :sb].sum(axis=0) @ h_s) - float(np.sum(cr[:, sb:] * h_b))
    sigma2 = rss / (w.size - (sb + h_b.size - int(held.sum())))
    idx = np.flatnonzero(measured)
    if not (np.all(u[:m] > 0.0) and np.all(u[m + idx] > 0.0)):
        # the step from a fit far from the data (a horn fading by a fifth within its
        # window, departure 'fading' seed 701) can take a level through zero: no log level
        raise np.linalg.LinAlgError("a trace's own level comes out at or below zero")
    # y = (log OFF, log ON - log OFF for the measured): per trace its Jacobian in the
    # trace's own inputs (2, t)
    off, on = u[:m], u[m : 2 * m]
    dy = np.zeros((m, 2, d_inv.shape[1]))
    dy[:, 0, 0] = 1.0 / off
    dy[:, 1, 0] = np.where(measured, -1.0 / off, 0.0)
    with np.errstate(divide="ignore"):  # an unmeasured ON level may sit at zero
        dy[:, 1, 1] = np.where(measured, 1.0 / np.where(measured, on, 1.0), 0.0)
    block = sigma2 * dy @ d_inv @ dy.transpose(0, 2, 1)
    low = dy @ e @ psd_root(sigma2 * schur_inv)
    block[~measured, 1, :] = 0.0
    block[~measured, :, 1] = 0.0
    block[~measured, 1, 1] = 1.0
    parts = LevelCovariance(block, low, np.zeros((m, 2, 0)), measured.astype(float))
    y = np.concatenate([np.log(off), np.log(u[m + idx] / u[idx])])
    return FreeLevels(
        off_n=off,
        on_n=on,
        measured=measured,
        y=y,
        cov_y=None,  # in its blocks, parts: never (n, n)
        sigma_n=math.sqrt(sigma2),
        cov_parts=parts,
    ), u


def _moved(h: np.ndarray, u: np.ndarray, levels: np.ndarray) -> float:
    """The largest step of a level relative to the level."""
    return float(np.max(np.abs(h[levels] / u[levels]), initial=0.0))


def _line_search(
    model: BenchModel, z: np.ndarray, state, u, h, rss: float, levels, sb: int, on_free
):
    """``u - t h`` for the largest ``t`` in 1, 1/2, ..., 1/64 that keeps the levels
    positive, lowers the whitened residuals' sum of squares below ``rss`` and leaves a
    solvable system there (an ON level pushed beyond the slope's reach has no
    information left: departure "all", seed 601), with its linearisation and its
    :func:`_gauss_newton` step; None if none does."""
    t = 1.0
    for _ in range(7):
        candidate = u - t * h
        if np.all(candidate[levels] > 0.0):
            w, cc, cr = _linearise_at(model, candidate, z, state)
            if float(w @ w) < rss:
                try:
                    solved = _gauss_newton(w, cc, cr, sb, on_free)
                except np.linalg.LinAlgError:
                    solved = None
                if solved is not None and all(np.all(np.isfinite(x)) for x in solved[:2]):
                    return candidate, (w, cc, cr), solved
        t /= 2.0
    return None


def _gauss_newton(w, cc, cr, sb: int, on_free: np.ndarray):
    """One Gauss-Newton step in ``u`` from each trace's blocks of the normal equations
    (:func:`_linearise`): the steps of the shared bench parameters (sb,) and of each
    trace's own inputs (m, t), and what the covariance needs (``D_i^-1``, ``D_i^-1
    B_i^T``, the Schur complement's inverse, which of each trace's inputs are held: its
    ON level where ``on_free`` is False, a nuisance below ``UNINFORMED_NUISANCE``)."""
    a, gs = cc[:, :sb, :sb].sum(axis=0), cr[:, :sb].sum(axis=0)
    b, d, gb = cc[:, :sb, sb:].copy(), cc[:, sb:, sb:].copy(), cr[:, sb:].copy()
    # an ON level held (not freed), or a nuisance the trace does not inform: its row and
    # column out of the system
    held = np.zeros(d.shape[:2], bool)
    held[:, 1] = ~on_free
    held[:, 2:] = np.diagonal(d, axis1=1, axis2=2)[:, 2:] < UNINFORMED_NUISANCE
    trace, col = np.nonzero(held)
    d[trace, col, :] = 0.0
    d[trace, :, col] = 0.0
    d[trace, col, col] = 1.0
    b[trace, :, col] = 0.0
    gb[trace, col] = 0.0
    d_inv = np.linalg.inv(d)  # (m, t, t)
    e = d_inv @ b.transpose(0, 2, 1)  # (m, t, sb): D_i^-1 B_i^T
    schur = a - np.einsum("msb,mbc->sc", b, e)
    schur_inv = np.linalg.inv(schur) if sb else np.zeros((0, 0))
    h_s = schur_inv @ (gs - np.einsum("mbs,mb->s", e, gb))
    h_b = np.einsum("mbc,mc->mb", d_inv, gb) - e @ h_s
    return h_s, h_b, d_inv, e, schur_inv, held


@program()
def _u_equations(model: BenchModel, structure, u, z, state):
    """The whitened residuals and each trace's blocks of the normal equations in ``u``
    at ``u`` (what :func:`_linearise` reads from the fit's program at the physical
    levels), for the steps after the first."""
    return coloured_blocks(lambda x: model.level_residuals(x, z, state), u, structure)


def _linearise_at(model: BenchModel, u: np.ndarray, z: np.ndarray, state):
    """:func:`_linearise`'s residuals and blocks at any ``u`` (its blocks padded as the
    fit's programs are, :func:`~idtool._data._blocks.padded_size`)."""
    n = model.data.force_n.shape[0]
    padded = model.padded(padded_size(n))
    w, cc, cr = _u_equations(
        padded, level_structure(padded), jnp.asarray(u), jnp.asarray(z), jnp.asarray(state)
    )
    return np.asarray(w)[:n], np.asarray(cc), np.asarray(cr)


def model_log_levels(model: BenchModel, z: np.ndarray, state):
    """log OFF and log FR per trace at ``z`` and their Jacobian in the physical
    parameters: (2 traces,), (2 traces, k)."""
    _, lv, dlv, _, _ = _linearise(model, z, state)
    m = lv.size // 2
    off, on = lv[:m], lv[m:]
    g = np.concatenate([np.log(off), np.log(on / off)])
    jac = np.concatenate([dlv[:m] / off[:, None], dlv[m:] / on[:, None] - dlv[:m] / off[:, None]])
    return g, jac
