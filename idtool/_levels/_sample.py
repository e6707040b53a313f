"""The posterior of a steady-state friction table's fit: emcee on the likelihood
:func:`idtool._levels._estimate.estimate` maximises, through the sampler the bench fit's
levels posterior uses (:mod:`idtool._posterior`).

Sampled: the physical parameters (internal scale) and the table's identifiable sds
(``scatter_mu``; ``scatter_fr`` when conditions repeat; ``discrepancy_fr``). The
likelihood is the estimate's,

    y ~ N(g(theta), M + Sigma(sds)),

``y`` the rows' (log OFF, log FR), ``M`` the known measurement variance from the
table's standard errors and ``Sigma`` the scatter and the per-condition discrepancy
(:mod:`idtool._levels._estimate`). Priors: the physical parameters' defaults
(:func:`idtool._posterior._prior.default_prior`: proper, over each parameter's range,
so a direction the table does not inform is sampled over its prior), the sds
half-normal with scale 0.1 (:data:`idtool._posterior._levels.SD_PRIOR`, as on a bench
fit); ``priors`` override them as ``idtool sample --priors`` does.

Machinery reused as is: the walkers on the prior box's coordinates
(:class:`~idtool._posterior._box.BoxTarget`, every bounded physical parameter), the
batched and once-compiled log-posterior (:class:`~idtool._posterior._sample.LogPosterior`),
the run until converged by the integrated autocorrelation time, split R-hat and bulk ESS
(:func:`~idtool._posterior._runner.run_chain`, its rule unchanged), ``chain.h5``
checkpoints and resume (:mod:`idtool._posterior._chainfile`). Not used: the funnel of
the bench sampler.

Where the posterior goes. On a simulated table (tests/test_levels_sample.py, 36 rows,
the power-limited coupling) it is an L in (Kt, power_load_n): one arm at Kt near its
estimate with the load scale from its estimate up to its prior's top (the constant
law's limit), the other at the estimate's load scale with Kt down to its prior's floor
(1e4 N/m, where the friction ratio no longer tells Kt), the coupling gain shifting
along it. The table's Wald intervals span 0.2-0.5 decades; the posterior's 95%
intervals two. Differential evolution and the snooker, started around the estimate,
crossed the arms slowly: 17,694 steps to converge (tau of Kt 265 on the walkers'
coordinates, acceptance 0.15), 20,592 and 42,731 on seeds 2 and 3 (the load scale's
tau 371 and Kt's 539).

So, as on the bench (:mod:`idtool._posterior._ridge`), when Kt's start interval spans
more than :data:`~idtool._posterior._ridge.RIDGE_DECADES` the walkers are sheared along
Kt's profile (:class:`~idtool._posterior._ridge.RidgeTarget` over the box: each other
parameter as its offset from the profile's maximiser, Jacobian 1), start spread along it
(:func:`~idtool._posterior._ridge.ridge_walkers`) and a tenth of the steps redraw Kt
from the profile (the bench's ridge jump): the Kt arm becomes one straight direction. Kt
rather than the widest parameter (the load scale, on most seeds): Kt's arm is the long
thin one; profiled along the load scale instead, seed 0 took 13,023 steps (Kt's tau 248)
against 8,598. The shear cannot straighten the other arm (the load scale at a fixed Kt),
so every other physical parameter whose start interval is that wide gets a move of its
own, a tenth of the steps (:func:`~idtool._levels._moves.redraw_move`): its place in its
range redrawn uniformly, the rest kept, an independence proposal accepted by the
posterior's ratio (Metropolis within Gibbs): one proposal reaches any point of the arm.
Seed 2: 7,986 steps (the load scale's tau 110) against 24,437 along the ridge alone.
Both moves take their share from differential evolution and the snooker
(:func:`~idtool._levels._moves.table_moves`); the bench sampler's moves are unchanged.
The chain records the shear and the redrawn parameters (``ridge``, ``redraw``), so a
resumed chain rebuilds both. Every move keeps the posterior: the distribution sampled is
the one before, on other coordinates.

Walkers start around the fit's estimate with its covariance, widened on each
parameter to its 95% interval's width (the profile's where it is not Wald's, one
internal unit where it is open) and along the directions the table does not inform;
along the ridge, on the profile in proportion to its mass.
"""

from __future__ import annotations

import dataclasses
import hashlib
import math
import os
import time
from pathlib import Path
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jax.scipy.linalg import cho_solve
from jaxtyping import Array

from idtool._errors import IdtoolError
from idtool._fit._variability import SD_PARAMS
from idtool._lawfit._profile import Side
from idtool._levels._estimate import SD_NAMES, Optimum, _data
from idtool._levels._model import LevelsData, LevelsModel, LevelsSpec, log_levels
from idtool._levels._moves import table_moves
from idtool._model._params import Param
from idtool._posterior._box import BoxTarget, base_internal, ridge_in_box
from idtool._posterior._chainfile import last_state, read_settings
from idtool._posterior._levels import SD_PRIOR
from idtool._posterior._moves import batch_rows
from idtool._posterior._prior import Prior, default_prior, parse_priors, read_priors
from idtool._posterior._record import LEVELS, PosteriorRecord
from idtool._posterior._ridge import RidgeTarget, ridge_profile, ridge_walkers, weak_parameter
from idtool._posterior._runner import FIRST_CHECK, MAX_MINUTES, MAX_STEPS, ChainStore, run_chain
from idtool._posterior._sample import LogPosterior, default_walkers
from idtool._posterior._start import initial_walkers, start_within

__all__ = ["TABLE", "LevelsPosterior", "TableTarget", "sample_table"]

TABLE = "levels-table"  # the chain's 'noise': a friction table's likelihood
_START_SD_OPEN = 1.0  # internal units of spread along an open side or an uninformed direction
MAX_PREDICT_DRAWS = 1000


class TableTarget(eqx.Module):
    """The table's log-posterior (module docstring), batched over walkers."""

    y: Array  # (2 n,) log OFF, then log FR, of every row
    m: Array  # (2 n, 2 n) the measurement variance from the standard errors
    k: Array  # (n, n) 1 between rows of one condition
    # the table's numbers as leaves and its classes as the static part: one compiled
    # program for every table of one shape and model (the model itself, static, was one
    # per fit: five in tests/test_levels_sample.py's resumed chains)
    data: LevelsData
    spec: LevelsSpec = eqx.field(static=True)
    priors: tuple[Prior, ...] = eqx.field(static=True)
    sd_names: tuple[str, ...] = eqx.field(static=True)

    @property
    def params(self) -> tuple[Param, ...]:
        by_name = {p.name: p for p in SD_PARAMS}
        return (*self.spec.params, *(by_name[n] for n in self.sd_names))

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(p.name for p in self.params)

    def log_posterior_batch(self, theta: Array) -> Array:
        """Log-posterior (up to a constant) of internal vectors (walkers, ndim)."""
        lp = jnp.zeros(theta.shape[0])
        v = {}
        for i, (p, prior) in enumerate(zip(self.params, self.priors, strict=True)):
            v[p.name] = p.value(theta[:, i])
            lp = lp + prior.logpdf(v[p.name]) + p.log_jacobian(theta[:, i])
        kp = len(self.spec.params)
        # (walkers, 2 n)
        g = jax.vmap(lambda th: log_levels(self.spec, self.data, th))(theta[:, :kp])
        n = self.k.shape[0]
        zero = jnp.zeros(theta.shape[0])
        tau2 = [v.get(name, zero) ** 2 for name in SD_NAMES]
        eye = jnp.eye(n)

        def cov(t0, t1, t2):
            c = self.m
            c = c.at[:n, :n].add(t0 * eye)
            return c.at[n:, n:].add(t1 * eye + t2 * self.k)

        chol = jnp.linalg.cholesky(jax.vmap(cov)(*tau2))
        r = self.y[None] - g
        quad = jax.vmap(lambda c, x: x @ cho_solve((c, True), x))(chol, r)
        logdet = 2.0 * jnp.sum(jnp.log(jnp.diagonal(chol, axis1=1, axis2=2)), axis=1)
        out = lp - 0.5 * (quad + logdet)
        out = jnp.where(jnp.isfinite(lp), out, -jnp.inf)
        return jnp.where(jnp.isnan(out), -jnp.inf, out)


def table_target(model: LevelsModel, opt: Optimum, priors: dict[str, Prior]) -> TableTarget:
    y, m, k = _data(model)
    n = model.table.n_rows
    sd_names = tuple(name for name, on in zip(SD_NAMES, opt.active, strict=True) if on)
    names = (*model.names, *sd_names)
    return TableTarget(
        y=jnp.asarray(y),
        m=jnp.asarray(m),
        k=jnp.asarray(k[:n, :n]),
        data=model.data,
        spec=model.spec,
        priors=tuple(priors[name] for name in names),
        sd_names=sd_names,
    )


def sampled_params(model: LevelsModel, opt: Optimum) -> tuple[Param, ...]:
    by_name = {p.name: p for p in SD_PARAMS}
    sds = (by_name[n] for n, on in zip(SD_NAMES, opt.active, strict=True) if on)
    return (*model.params, *sds)


def _fingerprint(opt: Optimum) -> str:
    h = hashlib.sha256()
    for a in (opt.theta, opt.cov_theta, np.array([opt.sds[n] for n in SD_NAMES])):
        h.update(np.ascontiguousarray(a, dtype=float).tobytes())
    return h.hexdigest()


def _priors(params, priors, stored: dict | None) -> dict[str, Prior]:
    overrides: dict[str, Prior] = {}
    if isinstance(priors, str | os.PathLike):
        overrides = read_priors(priors, params)
    elif priors:
        raw = {n: p.to_dict() if isinstance(p, Prior) else p for n, p in priors.items()}
        overrides = parse_priors(raw, params, "priors")
    sd_names = {p.name for p in SD_PARAMS}
    table = {p.name: SD_PRIOR if p.name in sd_names else default_prior(p) for p in params}
    table |= overrides
    if stored is not None:
        stored_table = parse_priors(stored["priors"], params, "chain.h5")
        if priors and stored_table != table:
            raise IdtoolError(
                "the priors differ from those the chain was sampled with; "
                "start over without --resume to change them"
            )
        table = stored_table
    return table


def _start(
    model: LevelsModel, opt: Optimum, sides: dict[str, tuple[Side, Side]], target: TableTarget
) -> tuple[np.ndarray, np.ndarray]:
    """The walkers' centre and covariance, internal scale (module docstring)."""
    k = len(model.params)
    params = target.params
    cov_phys = np.array(opt.cov_theta, float)
    for j, p in enumerate(model.params):
        lo, hi = sides[p.name]
        if math.isfinite(lo.z) and math.isfinite(hi.z):
            want = ((hi.z - lo.z) / 3.92) ** 2
        else:
            want = _START_SD_OPEN**2
        cov_phys[j, j] += max(0.0, want - cov_phys[j, j])
    if opt.null.shape[1]:
        cov_phys += _START_SD_OPEN**2 * opt.null @ opt.null.T
    sd_theta = [
        params[k + j].internal(max(opt.sds[n], 2e-3)) for j, n in enumerate(target.sd_names)
    ]
    theta = np.concatenate([opt.theta, sd_theta])
    cov = np.zeros((theta.size, theta.size))
    cov[:k, :k] = cov_phys
    for j in range(len(target.sd_names)):
        p = params[k + j]
        sd_val = float(p.value(jnp.asarray(theta[k + j])))
        cov[k + j, k + j] = (0.5 * sd_val / p.slope(theta[k + j])) ** 2
    return theta, cov


def _wide(params: tuple[Param, ...], theta: np.ndarray, cov: np.ndarray, k: int) -> list[int]:
    """The physical log-scale parameters (of the first ``k``) whose start interval
    (``cov``: the profile's where it is not Wald's, :func:`_start`) spans more than
    :data:`~idtool._posterior._ridge.RIDGE_DECADES`: the rule of
    :func:`~idtool._posterior._ridge.weak_parameter`, parameter by parameter."""
    return [
        i
        for i in range(k)
        if weak_parameter((params[i],), theta[i : i + 1], cov[i : i + 1, i : i + 1], 1) is not None
    ]


def sample_table(
    model: LevelsModel,
    opt: Optimum,
    sides: dict[str, tuple[Side, Side]],
    *,
    walkers: int | None = None,
    steps: int | None = None,
    seed: int | None = None,
    priors: str | os.PathLike | dict | None = None,
    chain_path: str | os.PathLike | None = None,
    resume: bool = False,
    progress: bool = False,
    checkpoint_s: float = 20.0,
    max_steps: int = MAX_STEPS,
    max_minutes: float = MAX_MINUTES,
) -> PosteriorRecord:
    """Sample the table's posterior (module docstring); the arguments as
    :func:`idtool._posterior._sample.sample_posterior`'s (no noise model: a table has
    its likelihood). Returns the chain's record (``noise`` :data:`TABLE`)."""
    import emcee

    chain_file = Path(chain_path) if chain_path is not None else None
    stored, done = None, 0
    if resume and chain_file is not None and chain_file.exists():
        stored, done = read_settings(chain_file)
    params = sampled_params(model, opt)
    names = [p.name for p in params]
    if stored is not None:
        if stored.get("noise") != TABLE:
            raise IdtoolError(
                f"{chain_file}: not a friction table's chain; start over with --force"
            )
        for name, given in (("walkers", walkers), ("seed", seed)):
            if given is not None and given != stored[name]:
                raise IdtoolError(
                    f"the chain was sampled with --{name} {stored[name]}, not {given}; "
                    "start over without --resume to change it"
                )
        walkers, seed = int(stored["walkers"]), int(stored["seed"])
        if stored["fit"] != _fingerprint(opt) or stored["names"] != names:
            raise IdtoolError(
                f"{chain_file}: sampled from another fit; start over without --resume"
            )
    table = _priors(params, priors, stored)
    seed = 0 if seed is None else seed
    ndim = len(params)
    walkers = default_walkers(LEVELS, ndim) if walkers is None else walkers
    if walkers < 2 * ndim + 2 or walkers % 2:
        raise IdtoolError(
            f"{walkers} walkers for {ndim} parameters: give an even number above {2 * ndim}"
        )
    if steps is not None and steps < 10:
        raise IdtoolError(f"steps {steps}: give at least 10")
    if steps is None and max_steps < FIRST_CHECK:
        raise IdtoolError(f"max_steps {max_steps}: give at least {FIRST_CHECK}")
    if not max_minutes > 0:
        raise IdtoolError(f"max_minutes {max_minutes:g}: give a positive number")
    started = time.perf_counter()
    target = table_target(model, opt, table)
    k = len(model.params)
    box = BoxTarget.of(target, tuple(range(k)))
    batch = batch_rows(walkers, LEVELS)
    sampled: BoxTarget | RidgeTarget = box
    if done == 0:
        theta, cov = _start(model, opt, sides, target)
        rng = np.random.default_rng(seed)
        wide = _wide(params, theta, cov, k)
        weak = names.index("Kt") if "Kt" in names and names.index("Kt") in wide else None
        redraw = [i for i in wide if i != weak]
        if weak is None:
            x = np.asarray(box.from_internal(jnp.asarray(theta)))
            cov_x = box.cov_from_internal(theta, cov)
        else:  # sampled along its profile (module docstring)
            ridge = ridge_profile(LogPosterior(target, batch), target, theta, weak)  # type: ignore[arg-type]
            sampled = RidgeTarget.along(box, ridge_in_box(ridge, box))
            centres, spread = ridge_walkers(
                ridge, start_within(theta, cov, params)[1], walkers, rng
            )
            cov_x = box.cov_from_internal(np.mean(centres, axis=0), spread)
            x = np.asarray(sampled.from_internal(box.from_internal(jnp.asarray(centres))))
        fn = LogPosterior(sampled, batch)
        p0 = initial_walkers(x, cov_x, fn, walkers, rng, params)
        initial: Any = emcee.State(p0, random_state=np.random.RandomState(seed).get_state())
    else:
        assert chain_file is not None and stored is not None
        if stored.get("ridge"):
            sampled = RidgeTarget.from_doc(box, stored["ridge"])
        redraw = [names.index(n) for n in stored.get("redraw", [])]
        fn = LogPosterior(sampled, batch)
        initial = last_state(chain_file)
    mode_s = time.perf_counter() - started
    settings = {
        "names": names,
        "transforms": [p.transform() for p in params],
        "noise": TABLE,
        "priors": {n: p.to_dict() for n, p in table.items()},
        "walkers": walkers,
        "seed": seed,
        "fit": _fingerprint(opt),
        "law": model.law,
        "coupling": model.coupling,
        "box": box.to_doc(),
        "ridge": sampled.to_doc() if isinstance(sampled, RidgeTarget) else None,
        "redraw": [names[i] for i in redraw],
    }
    store = ChainStore(chain_file, settings, np.asarray(opt.theta))
    bar = _progress(progress, steps if steps is not None else max(done, FIRST_CHECK), done)
    start_done = done
    try:
        diag, sample_s = run_chain(
            lambda backend: emcee.EnsembleSampler(
                walkers,
                ndim,
                fn,
                vectorize=True,
                backend=backend,
                moves=table_moves(sampled, redraw),
            ),
            initial,
            store,
            done,
            tuple(names),
            steps,
            max_steps,
            max_minutes,
            checkpoint_s,
            bar,
        )
    finally:
        bar.close()
    chain, lp, acc = store.read()
    chain = np.asarray(base_internal(sampled, jnp.asarray(chain)))
    values = np.stack(
        [np.asarray(p.value(np.asarray(chain[:, :, i], float))) for i, p in enumerate(params)],
        axis=-1,
    )
    timing = {
        "mode_search_s": mode_s,
        "compile_s": float(fn.compile_s or 0.0),
        "sampling_s": sample_s,
        "steps_this_run": float(diag.steps - start_done),
        "total_s": time.perf_counter() - started,
        "log_posterior_evaluations": float(fn.evaluations),
    }
    return PosteriorRecord(
        params=params,
        chain=chain,
        values=values,
        log_prob=lp,
        acceptance=acc,
        diagnostics=diag,
        noise=TABLE,
        priors=table,
        seed=seed,
        law=model.law,
        coupling=model.coupling,
        timing=timing,
        z_lin=np.asarray(opt.theta),
    )


def _progress(enabled: bool, total: int, initial: int):
    if not enabled:
        return _NoBar()
    from tqdm import tqdm

    return tqdm(total=total, initial=initial, unit="step", desc="sampling", dynamic_ncols=True)


class _NoBar:
    total: int = 0

    def update(self, n: int) -> None:
        pass

    def set_postfix_str(self, text: str) -> None:
        pass

    def close(self) -> None:
        pass


@dataclasses.dataclass(frozen=True)
class LevelsPosterior:
    """A table fit's posterior: its draws (physical units, as ``posterior.nc`` keeps
    them) and what the chain said.

    Attributes:
        draws: name -> flat draws (burn-in dropped, thinned to at most 4000).
        diagnostics: :meth:`Diagnostics.to_dict` of the whole chain.
        timing: seconds by stage.
        seed: the sampler's.
        record: the chain itself, when sampled in this session (None when read back).
    """

    draws: dict[str, np.ndarray]
    diagnostics: dict[str, Any]
    timing: dict[str, float]
    seed: int
    record: PosteriorRecord | None = dataclasses.field(default=None, repr=False, compare=False)

    @classmethod
    def of(cls, record: PosteriorRecord) -> LevelsPosterior:
        return cls(
            record.stored_draws(), record.diagnostics.to_dict(), dict(record.timing),
            record.seed, record,
        )  # fmt: skip

    @property
    def converged(self) -> bool:
        return bool(self.diagnostics.get("converged"))

    @property
    def n_draws(self) -> int:
        return int(next(iter(self.draws.values())).size)

    def summary(self) -> dict[str, dict[str, Any]]:
        """Each parameter's median, 95% interval, mean and sd."""
        out: dict[str, dict[str, Any]] = {}
        for name, x in self.draws.items():
            lo, med, hi = np.percentile(x, [2.5, 50.0, 97.5])
            out[name] = {
                "median": float(med),
                "ci95": [float(lo), float(hi)],
                "mean": float(np.mean(x)),
                "sd": float(np.std(x)),
            }
        return out

    def thetas(self, model: LevelsModel, max_draws: int = MAX_PREDICT_DRAWS):
        """Internal ``theta`` (d, k) and the sds (name -> (d,)) of up to ``max_draws``
        evenly spaced draws."""
        n = self.n_draws
        idx = np.unique(np.linspace(0, n - 1, min(n, max_draws)).astype(int))
        theta = np.stack(
            [[p.internal(float(x)) for x in self.draws[p.name][idx]] for p in model.params],
            axis=1,
        )
        sds = {s: self.draws[s][idx] if s in self.draws else np.zeros(idx.size) for s in SD_NAMES}
        return theta, sds

    def describe(self) -> str:
        d = self.diagnostics
        verdict = "converged" if self.converged else "NOT converged"
        return f"{d.get('walkers')} walkers x {d.get('steps')} steps, {verdict}"
