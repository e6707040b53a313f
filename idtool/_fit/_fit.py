"""Joint least-squares fit of a dataset: multi-start Levenberg-Marquardt with a coloured
Jacobian (:mod:`idtool._fit._lm`), correlated noise, Gauss-Newton covariance and identifiability
checks.

Procedure (one friction law, one coupling law):

1. Start values for the bench nuisances come from the data (:func:`start_values`).
2. Multi-start: of :data:`SCREENED` x ``n_starts`` quasi-random points over the
   physical parameters (seeded; the coupling gain set through a velocity ratio below 1,
   see :func:`_start_point`), two sets are run: the sequence's first ``n_starts``, and
   the ``n_starts`` whose start already fits the traces best (lowest loss: a scatter
   search's trial points, as in Ugray et al. 2007's GlobalSearch); 8-16 runs, the sets
   may share points. From each, Levenberg-Marquardt moves every parameter, for a short
   step budget. Joint end points rank basins by their real loss (held nuisances let a
   spurious low-Kt basin win on two-load designs), and with the coloured Jacobian a
   step costs the same whichever parameters move. Distinct optima are summarised.
3. Each set's lowest end point is taken to convergence, and the lower of the two kept
   (either set alone has lost the basin the other found). The noise model's correlation state
   (AR(1), the default: the lag-1 autocorrelation ``phi`` of the block residuals) is
   estimated from the residuals and the fit repeated on residuals whitened with it
   until it settles (:meth:`~idtool._model._noise.AbstractNoise.estimate_state`):
   load-cell noise is correlated, and treating it as independent would make every
   interval too narrow.
4. Covariance ``sigma^2 (J^T J)^-1`` of the whitened problem, on the internal scale;
   95% intervals are mapped through the transforms (so they respect the bounds).
"""

from __future__ import annotations

import math
import threading
from concurrent.futures import ThreadPoolExecutor

import jax
import jax.numpy as jnp
import numpy as np

from idtool._data._blocks import FitData
from idtool._diagnostic import Diagnostic
from idtool._fit._arrow import inverse_and_weakest
from idtool._fit._lm import LMResult
from idtool._fit._program import run_lm, unwhiten
from idtool._fit._result import Estimate, FitResult, estimate_of, uninformed
from idtool._model._actuator import DEFAULT_ACTUATOR
from idtool._model._benchmodel import BenchModel, bench_model
from idtool._model._names import DEFAULT_COUPLING, DEFAULT_DIRECTION, DEFAULT_LEVEL_MODEL
from idtool._model._noise import DEFAULT_NOISE
from idtool._model._offset import DEFAULT_OFFSET
from idtool._model._settings import ParameterSetting

__all__ = ["SCREENED", "fit_model", "quasi_random"]

# Steps per multi-start run: enough to rank the basins (a joint fit from a start takes
# 20-40); the best is then continued. 10 of 10 two-load designs found the true basin.
_MULTISTART_STEPS = 20
# Candidate starts per multi-start run, ranked by their loss at the start (one
# linearisation each, the LM program run for no step). Unscreened, the 8 starts' 20
# steps ranked the basins wrongly where the starts crawl: 16 simulations of a study
# truth with 10 pulls planned at 10-20% amplitude (exponential coupling) ended in a
# far basin on 9 (6-9x the optimum's loss; Kt at its bound on the 6 looked at), every start
# still crawling after its 20 steps (one reached the optimum in 100); screened from
# 32, 16 of 16 reached it or a neighbouring optimum (loss within 0.1%), in fewer LM
# steps (142-196 against 151-260 per fit; tests/test_fit.py). Screened only, a two-speed
# bench lost its basin (all 8 screened starts lay in one far basin: log L -2083 against
# -1087), so the plain sequence's starts run too (tests/test_speed_design.py).
SCREENED = 4
_POLISH_STEPS = 100
# An end point that stopped because no damped step lowered the loss any more still
# counts as the optimum when its Gauss-Newton decrement g' (J'J)^-1 g is below this many
# residual variances: it is then within sqrt(0.01) = 0.1 standard errors of the optimum
# in every direction, a shift of 5% of a 95% interval's half-width. LM's own tolerance
# (1e-8) was out of reach while the slope actuator's OFF switch was an unrounded corner
# (a kink in the loss each time an OFF delay crosses a sub-sample): decrements of 1e-3
# to 2e-2, growing with the traces (1.8e-2 on 48, where the loss rose along the
# Gauss-Newton step however short). Rounded (idtool._model._bench.mean_force_n), 48
# traces reach 4e-9. The lag actuator's switches are still unrounded corners.
_DECREMENT_AT_OPTIMUM = 1e-2


def _loglik(w: np.ndarray, log_det: float, n_traces: int) -> tuple[float, float]:
    """Exact Gaussian log-likelihood of whitened residuals ``w`` at the MLE of sigma,
    ``log_det`` the whitening's ``log |det L|`` per trace
    (:meth:`~idtool._model._noise.AbstractNoise.trace_log_det`; AR(1):
    ``0.5 log(1 - phi^2)``); and that sigma [N]."""
    n = w.size
    s2 = float(np.sum(w**2) / n)
    return -0.5 * n * (math.log(2 * math.pi * s2) + 1) + n_traces * log_det, math.sqrt(s2)


def _distinct(points: list[dict], rel: float = 1e-6, near: float = 0.05) -> list[dict]:
    """Group multi-start end points into optima, best first.

    Two end points are the same optimum if their losses agree to ``rel`` (a flat or
    saturated direction can leave them apart) or if they lie within ``near`` of each
    other on the internal scale in every physical parameter (a start stopped by its step
    budget short of the bottom of the same basin; standard errors there are ~0.01).
    """
    groups: list[dict] = []
    for p in sorted(points, key=lambda p: p["rss"]):
        for g in groups:
            same_loss = abs(p["rss"] - g["rss"]) <= rel * max(g["rss"], 1e-300) + 1e-12
            if same_loss or np.max(np.abs(p["z"] - g["z"])) < near:
                g["count"] += 1
                break
        else:
            groups.append(p | {"count": 1})
    return groups


@jax.jit
def _amplitude_m(coupling, alpha, load_n, max_amplitude_m):
    """A coupling law's slip amplitude [m] (one program, not an eager operation each)."""
    return coupling.amplitude_m(alpha, load_n, max_amplitude_m)


def _start_point(model: BenchModel, u: np.ndarray) -> dict[str, float]:
    """Physical start values from a point ``u`` of the unit cube (one coordinate per
    physical parameter).

    Log-uniform over each parameter's ``start_box``, except the coupling gain: it is set
    from a velocity ratio VR in [0.05, 0.95] at a reference operating point (largest
    commanded amplitude, median load). A gain drawn blindly often leaves every trace at
    VR >= 1, where FR = 1 exactly and the loss is flat in the coupling: a plateau that
    the optimiser crawls along for dozens of steps, while the data show FR < 1.
    """
    d = model.data
    specs = model.shared_params[: len(u)]
    gain = model.coupling.gain_param
    start: dict[str, float] = {}
    for j, p in enumerate(specs):
        if p.start_box is not None and p.name != gain:
            lo, hi = p.start_box
            start[p.name] = float(np.exp(np.log(lo) + u[j] * (np.log(hi) - np.log(lo))))
    names = [p.name for p in specs]
    if gain not in names or gain in _user_started(model):
        return start  # the gain fixed, or started where the user said
    j = names.index(gain)
    loads, alphas = np.asarray(d.normal_load_n), np.asarray(d.amplitude_fraction)
    ref = np.lexsort((np.abs(loads - np.median(loads)), -alphas))[0]
    w = 2.0 * np.pi * float(d.vibration_frequency_hz)
    amplitude = float(d.pull_speed_m_s[ref]) / ((0.05 + 0.9 * u[j]) * w)
    # The coupling with unit gain and its other parameters at their start values (the
    # fixed ones at theirs); its friction-free amplitude is proportional to the gain.
    unit = model.coupling_of({p.name: start.get(p.name, p.start) for p in specs} | {gain: 1.0})
    per_gain = float(_amplitude_m(unit, alphas[ref], loads[ref], d.max_amplitude_m))
    spec = specs[j]
    start[gain] = float(np.clip(amplitude / per_gain, 1.01 * spec.lo, 0.99 * spec.hi))
    return start


def _user_started(model: BenchModel) -> set[str]:
    """The parameters whose start (or fixed value) the user gave."""
    return {s.name for s in model.settings if s.nominal is not None}


def quasi_random(n: int, d: int, seed: int) -> np.ndarray:
    """``n`` quasi-random points in the unit cube ``[0, 1)^d``, randomly shifted by ``seed``.

    Richtmyer's Kronecker sequence ``frac(shift + i sqrt(p_j))`` over the first primes
    ``p_j``: low discrepancy for every ``n`` (not only powers of two, as Sobol points),
    each coordinate's gaps below ~2/n, and no scipy.stats import (half a second of the
    time to a first fit). Up to 12 dimensions.
    """
    primes = np.array([2, 3, 5, 7, 11, 13, 17, 19, 23, 29, 31, 37], float)
    if not 1 <= d <= primes.size:
        raise ValueError(f"d = {d}: quasi_random supports 1 to {primes.size} dimensions")
    alpha = np.sqrt(primes[:d]) % 1.0
    shift = np.random.default_rng(seed).random(d)
    return (shift + np.arange(1, n + 1)[:, None] * alpha) % 1.0


def fit_model(
    data: FitData,
    law: str = "dahl",
    coupling: str = DEFAULT_COUPLING,
    seed: int = 0,
    n_starts: int = 8,
    noise: str = DEFAULT_NOISE,
    actuator: str = DEFAULT_ACTUATOR,
    start_from: FitResult | None = None,
    offset: str = DEFAULT_OFFSET,
    settings: tuple[ParameterSetting, ...] = (),
    level: str = DEFAULT_LEVEL_MODEL,
    direction: str = DEFAULT_DIRECTION,
) -> FitResult:
    """Fit one law, coupling, actuator, load-cell offset and level model to prepared data;
    see the module docstring. ``start_from``: a fit of a model this one nests (the slope
    actuator for the lag one, the constant offset for the drifting one, the constant
    coupling for a saturating one, the steady levels for the relaxing or creeping ones):
    its optimum is the start, the new parameters where this model reduces to that one
    (:attr:`Param.nested_at`; each of :attr:`Param.nested_starts` in turn, the likeliest
    end kept), with no multi-start.
    ``settings``: the user's fixed values, bounds, scales, starts and priors
    (:mod:`idtool._model._settings`); ``direction``: of the vibration
    (:data:`idtool.DIRECTIONS`)."""
    model = bench_model(data, law, coupling, noise, actuator, offset, settings, level, direction)
    k = model.n_physical
    base = model.z0()
    everything = np.ones(base.size, bool)
    count = {"steps": 0, "jacobians": 0}
    counting = threading.Lock()

    def run(z, mask, state, max_steps):
        out = run_lm(model, np.asarray(z, float), mask, state, max_steps)
        with counting:  # the multi-start runs in two threads
            count["steps"] += int(out.steps)
            count["jacobians"] += int(out.n_jacobians)
        return out

    if start_from is not None:
        # its parameters by name (same data: same nuisance centres and scales); the new
        # ones where this model reduces to that one if they say (nested_at), else at
        # their start values; the noise's state where it ended
        prev = start_from.model.names
        z = np.array(
            [
                start_from.z[prev.index(p.name)]
                if p.name in prev
                else (base[i] if p.nested_at is None else p.internal(p.nested_at))
                for i, p in enumerate(model.params)
            ]
        )
        # a new parameter with several starts (Param.nested_starts): each in turn
        zs = [z]
        for i, p in enumerate(model.params):
            if p.name not in prev and p.nested_starts:
                zs = [zz.copy() for zz in zs for _ in p.nested_starts]
                values = p.nested_starts * (len(zs) // len(p.nested_starts))
                for zz, value in zip(zs, values, strict=True):
                    zz[i] = p.internal(value)
        fits = []
        state = _carried_state(model, start_from)
        for zz in zs:  # ranked by likelihood: each settles its own state
            best = run(zz, everything, state, _POLISH_STEPS)
            best, settled = _settle_state(model, best, state, run)
            fits.append(_summarise(model, best, settled, start_from.optima, count))
        return max(fits, key=lambda f: f.loglik)

    # 2. multi-start: from each quasi-random point of the physical parameters (the
    # nuisances at their data-driven start values) everything is fitted jointly. A step
    # costs the same whichever parameters move, and joint end points rank basins by
    # their real loss: held nuisances ranked a spurious low-Kt basin first on two-load
    # designs (nuisance misfit was ~60x the final loss there).
    points: list[dict] = []
    # every physical parameter fixed or started by the user: one start is the fit
    varied = [
        p
        for p in model.shared_params[:k]
        if p.start_box is not None
        or (p.name == model.coupling.gain_param and p.name not in _user_started(model))
    ]
    cube = quasi_random(SCREENED * n_starts, k, seed) if varied else np.zeros((1, k))
    starts = [_start_point(model, u) for u in cube]
    zs = []
    for start in starts:
        z = base.copy()
        z[:k] = model.z0(**start)[:k]
        zs.append(z)
    # two at a time: the program runs while the other thread waits for its result,
    # and the starts are independent (same end points in any order; 0.58 s against
    # 0.68 s for the example's 8 starts on 2 cores)
    with ThreadPoolExecutor(2) as pool:
        white = model.noise.initial_state()
        # the sequence's first n_starts points, and the n_starts of all its points that
        # fit the traces best at their start (their loss, the LM program run for no
        # step; a stable sort: ties keep the sequence's order)
        plain = list(range(min(n_starts, len(zs))))
        screened = plain
        if len(zs) > n_starts:
            at_start = list(pool.map(lambda z: float(run(z, everything, white, 0).loss), zs))
            screened = [int(i) for i in np.argsort(at_start, kind="stable")[:n_starts]]
        ran = sorted(set(plain) | set(screened))
        ends = dict(
            zip(
                ran,
                pool.map(lambda i: run(zs[i], everything, white, _MULTISTART_STEPS), ran),
                strict=True,
            )
        )
    for i in ran:
        out = ends[i]
        points.append(
            {
                "z": np.asarray(out.z)[:k],
                "rss": 2.0 * float(out.loss),
                "converged": bool(out.converged),
                "start": starts[i],
            }
        )
    optima = _distinct(points)

    # 3. the lowest end point of each set, taken to convergence; the lower one wins
    # (each alone lost the basin where the other found it: the plain starts' on crawling
    # benches, the screened ones' on a two-speed bench whose screened starts all lay in
    # one far basin)
    finals = []
    for group in {min(g, key=lambda i: float(ends[i].loss)) for g in (plain, screened)}:
        best = ends[group]
        if not bool(best.converged):
            best = run(best.z, everything, model.noise.initial_state(), _POLISH_STEPS)
        finals.append(best)
    best = min(finals, key=lambda o: float(o.loss))

    best, state = _settle_state(model, best, model.noise.initial_state(), run)
    return _summarise(model, best, state, optima, count)


def _carried_state(model: BenchModel, start_from: FitResult) -> np.ndarray:
    """The noise state to start a refit from: the previous fit's, by parameter name
    (uncorrelated in a coefficient it did not have)."""
    previous = start_from.model.noise.state_by_name(start_from.noise_state)
    return model.noise.state_from_names(previous)


def _settle_state(
    model: BenchModel, best: LMResult, state: np.ndarray, run
) -> tuple[LMResult, np.ndarray]:
    """Refit on whitened residuals (correlated noise) until the noise model's state
    settles (:meth:`~idtool._model._noise.AbstractNoise.state_settled`), from ``best``
    fitted with ``state``; the last fit and the state it was fitted with."""
    data = model.data
    everything = np.ones(best.z.size, bool)
    for _ in range(3 if model.noise.autoregressive else 0):
        e = unwhiten(np.asarray(best.residuals), state, model)
        new = model.noise.estimate_state(e, data.first)
        # Stop once the state settles (the estimates then move far less than their
        # errors); it stays the one the parameters were fitted with.
        if model.noise.state_settled(state, new):
            break
        state = new
        best = run(best.z, everything, state, _POLISH_STEPS)
    return best, state


def _values_and_jacobian(
    model: BenchModel, z: np.ndarray, levels: np.ndarray, dlevels: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Every parameter's value in its unit, then each trace's friction ratio ON/OFF; and
    their Jacobian in ``z``, in its two non-zero parts: the values' slopes (p,) (each
    value moves with its own ``z`` only) and the ratios' (traces, k) in the physical
    parameters; from the levels and their derivatives that the last linearisation of
    the fit computed (so no further program to compile). The dense (p + traces, p)
    Jacobian would make the delta method O(p^3)."""
    specs = model.params
    p, m = len(specs), model.data.n_traces
    vals, slopes = np.empty(p + m), np.empty(p)
    for i, spec in enumerate(specs):
        vals[i], slopes[i] = float(spec.value(z[i])), spec.slope(z[i])
    off, on = levels[:m], levels[m:]
    vals[p:] = on / off
    dratio = (dlevels[m:] * off[:, None] - on[:, None] * dlevels[:m]) / off[:, None] ** 2
    return vals, slopes, dratio


def _summarise(
    model: BenchModel,
    best: LMResult,
    state: np.ndarray,
    optima: list[dict],
    count: dict[str, int],
) -> FitResult:
    data = model.data
    z = np.asarray(best.z)
    w = np.asarray(best.residuals)
    n, p = w.size, z.size
    rss = float(w @ w)
    sigma2 = rss / (n - p)
    # (J^T J)^+ from the arrowhead blocks, kept in them (O(m) time and memory, never
    # (p, p): idtool._fit._cov). A parameter the data do not move at all (saturated at a
    # bound) has a zero column and zero variance; the bound warning below names it.
    normal = jax.tree.map(np.asarray, best.normal)  # NumPy: no one-operation programs
    inverse, weakest, weakest_direction = inverse_and_weakest(normal, model.n_shared)
    jtr = np.asarray(normal.grad)
    decrement = inverse.quad(jtr)
    converged = bool(best.converged) or decrement < _DECREMENT_AT_OPTIMUM * rss / n
    cov = inverse.scaled(sigma2)
    variances = cov.diagonal()
    se_z = np.sqrt(np.maximum(variances, 0.0))
    se_safe = np.where(se_z > 0.0, se_z, 1.0)[: model.n_shared]
    # the shared parameters' correlations (all the reports show; the nuisances' would be
    # (p, p))
    corr = cov.leading(model.n_shared) / np.outer(se_safe, se_safe)

    # delta method for the physical values (and the per-trace friction ratios)
    vals, slopes, dratio = _values_and_jacobian(model, z, *(np.asarray(x) for x in best.aux[:2]))
    k = model.n_physical
    var_ratio = np.einsum("ij,jk,ik->i", dratio, cov.leading(k), dratio)
    se_vals = np.sqrt(np.maximum(np.concatenate([slopes**2 * variances, var_ratio]), 0.0))

    warnings: list[str] = []
    estimates: dict[str, Estimate] = {}
    specs = model.params
    for i, spec in enumerate(specs):
        estimates[spec.name] = est = estimate_of(spec, z[i], se_z[i])
        value, (lo, hi), at_bound = est.estimate, est.ci95, est.at_bound
        if spec.physical and at_bound:
            warnings.append(
                Diagnostic(
                    "bound",
                    f"{spec.name} = {value:.4g} {spec.unit} sits at the bound of its range "
                    f"[{spec.lo:g}, {spec.hi:g}]: the data push it outside what the model "
                    "allows",
                    parameter=spec.name,
                    value=value,
                    range=(spec.lo, spec.hi),
                )
            )
        elif (weak := uninformed(spec, lo, hi)) is not None:
            warnings.append(weak)
    labels = {s.name: s.fixed_label for s in model.settings}
    for name, value in model.fixed.items():  # the user's (or rig's) values, said so
        unit = next(p.unit for p in model.declared_params if p.name == name)
        estimates[name] = Estimate(
            name, unit, value, 0.0, (value, value), fixed=True, fixed_label=labels[name]
        )
    for a in range(k):
        for b in range(a + 1, k):
            if abs(corr[a, b]) > 0.95:
                warnings.append(
                    Diagnostic(
                        "correlation",
                        f"{specs[a].name} and {specs[b].name} are correlated at "
                        f"{corr[a, b]:+.3f}: the data mostly inform a combination of the two",
                        parameters=(specs[a].name, specs[b].name),
                        correlation=float(corr[a, b]),
                    )
                )
    if weakest < 1e-12:
        v = weakest_direction
        top = np.argsort(-np.abs(v))[:3]
        combo = ", ".join(f"{specs[j].name} ({v[j]:+.2f})" for j in top)
        warnings.append(
            Diagnostic(
                "singular",
                f"near-singular direction in parameter space: {combo}",
                eigenvalue_ratio=weakest,
            )
        )
    loads = np.unique(data.normal_load_n)
    if len(model.coupling.fit_params) > 1 and loads.size == 1:
        warnings.append(
            Diagnostic(
                "single_load",
                f"all traces share one normal load ({loads[0]:g} N): the "
                f"{model.coupling.name} coupling's shape only shows through the load "
                "dependence, so it cannot be told apart from the constant coupling; use "
                "--coupling constant or add loads",
                normal_load_n=float(loads[0]),
            )
        )
    if not converged:
        warnings.append(
            Diagnostic(
                "lm_not_converged",
                "Levenberg-Marquardt stopped before its tolerance; check the fit",
            )
        )

    offs = len(specs)
    fr = vals[offs : offs + data.n_traces]
    fr_se = se_vals[offs : offs + data.n_traces]
    log_det = float(model.noise.trace_log_det(jnp.asarray(state)))
    loglik, sigma = _loglik(w, log_det, data.n_traces)
    return FitResult(
        model=model,
        z=z,
        cov_z=cov,
        noise_state=np.asarray(state, float),
        sigma_n=sigma,
        rss=rss,
        loglik=loglik,
        estimates=estimates,
        correlation=corr,
        friction_ratio=fr,
        friction_ratio_se=fr_se,
        optima=optima,
        warnings=warnings,
        lm_steps=count["steps"],
        jacobian_evaluations=count["jacobians"],
    )
