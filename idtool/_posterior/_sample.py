"""Posterior sampling of a fit with emcee (issue 5).

* The log-posterior of :mod:`idtool._posterior._likelihood`, batched over walkers (the contact
  model vmapped, the bench model with walkers as its fastest axis), is compiled once and
  handed to ``emcee.EnsembleSampler(vectorize=True)``; emcee evaluates half the ensemble
  (DE move) or a quarter (snooker move) at a time, in batches of a fixed size
  (:func:`idtool._posterior._moves.batch_rows`), so every call has the same shape (one
  compilation).
* Without a fixed number of steps it samples until the chain has converged
  (:mod:`idtool._posterior._runner`).
* Walkers start from a multivariate normal around the fit's optimum with the fit's
  covariance (the shared block of ``cov_z``; the noise parameters from their asymptotic
  errors), brought inside the parameters' ranges
  (:func:`idtool._posterior._start.start_within`); the log-posterior must be finite at
  the optimum and at every start. Where the fit's interval of a physical parameter
  spans over 0.2 decades (Kt read through a coupling law the bench may not follow, or
  through pull-to-pull scatter), the levels posterior is profiled along it, the walkers
  start on that profile and sample coordinates sheared along it
  (:mod:`idtool._posterior._ridge`), over every bounded parameter's place in its range
  (:mod:`idtool._posterior._box`); elsewhere the physical parameters are on that box and
  the discrepancy's funnel is opened over it (:mod:`idtool._posterior._funnel`).
* Seeded: walker starts from ``numpy.random.default_rng(seed)``, emcee's moves from
  ``RandomState(seed)``; the same seed gives the same chain, bit for bit.
* Checkpointed (``chain_path``): every ``checkpoint_s`` seconds (and at the end) the
  steps run so far are appended to ``chain.h5`` atomically (:mod:`idtool._posterior._chainfile`),
  so ``chain.h5`` is always a complete chain, random state included, that
  ``resume=True`` continues exactly where it stopped: an interrupted and resumed run
  gives the same chain as an uninterrupted one.
"""

from __future__ import annotations

import dataclasses
import functools
import hashlib
import os
import time
from pathlib import Path
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from idtool._errors import IdtoolError
from idtool._fit._cov import covariance_state
from idtool._fit._folder import CHAIN_H5
from idtool._fit._variability import SD_PARAMS
from idtool._model._benchmodel import BenchModel
from idtool._model._noise import NOISE_MODELS
from idtool._posterior._box import BoxTarget, base_internal, ridge_in_box
from idtool._posterior._chainfile import last_state, read_linearisation, read_settings
from idtool._posterior._funnel import FunnelTarget, open_funnel
from idtool._posterior._levels import (
    SD_PRIOR,
    LevelsTarget,
    build_levels_target,
    levels_params,
    levels_start,
)
from idtool._posterior._likelihood import (
    Target,
    build_target,
    sampled_params,
)
from idtool._posterior._moves import batch_rows as _batch
from idtool._posterior._moves import sampler_moves as _moves
from idtool._posterior._posterior import LEVELS, FitLike, Posterior
from idtool._posterior._prior import (
    DISTRIBUTIONS,
    Prior,
    default_prior,
    parse_priors,
    read_priors,
)
from idtool._posterior._reparam import AbstractReparameterised
from idtool._posterior._ridge import (
    RidgeTarget,
    open_sides,
    ridge_profile,
    ridge_walkers,
    weak_parameter,
)
from idtool._posterior._runner import FIRST_CHECK, MAX_MINUTES, MAX_STEPS, ChainStore, run_chain
from idtool._posterior._start import find_start, initial_walkers, start_within

__all__ = [
    "CHAIN_FILE",
    "LEVELS_WALKERS",
    "WALKERS",
    "LogPosterior",
    "default_walkers",
    "sample_posterior",
]

# The ensemble's default size (issue 26). A walker's autocorrelation time in steps
# depends little on the ensemble's size while a step costs in proportion to it, so the
# levels posterior converges sooner with fewer walkers. Measured on fixed-length chains
# (16,000 steps, two sampler seeds each; on the ridge benches 24,000 steps, one seed;
# 2 cores): emcee's integrated time of the slowest parameter, and ms per step:
#
#   bench                          16 walkers              32 walkers
#   example                        tau 129, 127; 2.50 ms   tau 115, 142; 4.61 ms
#   clean 1                        tau 144, 136; 2.48 ms   tau 114, 106; 4.49 ms
#   coupling 501 (along a ridge)   tau 527; 2.80 ms        tau 529; 4.54 ms
#   all 602 (along a ridge)        tau 496; 2.59 ms        tau 439; 4.50 ms
#
# 50 tau of steps, the rule's chain length, then take 16.0 against 29.4 s on the
# example, 17.3 against 24.8 s on clean 1, 74 against 120 s and 64 against 99 s on the
# ridge benches; the bulk ESS the rule also asks for is 16 x 50 = 800 >= 400. On the
# traces' own (noise-only) posterior, not measured, 32 as before.
LEVELS_WALKERS = 16
WALKERS = 32

CHAIN_FILE = CHAIN_H5.name


@jax.jit
def _batched(theta, target):
    """The log-posterior of a batch: the levels model's, or the traces' (Target)."""
    return target.log_posterior_batch(theta)


class LogPosterior:
    """The batched log-posterior as emcee calls it: ``(n, ndim) -> (n,)`` NumPy arrays.

    Batches are cut (and padded) to ``batch`` rows, so one compiled program serves every
    call; the first call's compilation time is kept in ``compile_s``.
    """

    def __init__(self, target: Target | LevelsTarget | AbstractReparameterised, batch: int):
        self.target = target
        self.batch = batch
        self.compile_s: float | None = None
        self.evaluations = 0

    def __call__(self, theta: np.ndarray) -> np.ndarray:
        theta = np.atleast_2d(np.asarray(theta, float))
        n = theta.shape[0]
        pad = (-n) % self.batch
        x = np.concatenate([theta, np.repeat(theta[-1:], pad, axis=0)]) if pad else theta
        out = []
        for i in range(0, x.shape[0], self.batch):
            chunk = jnp.asarray(x[i : i + self.batch])
            if self.compile_s is None:
                t0 = time.perf_counter()
                _batched.lower(chunk, self.target).compile()
                self.compile_s = time.perf_counter() - t0
            out.append(np.asarray(_batched(chunk, self.target)))
        self.evaluations += n
        return np.concatenate(out)[:n]


def _fingerprint(fit: FitLike) -> str:
    h = hashlib.sha256()
    # the covariance as its state file holds it: a dense one (a folder written before
    # the blocks) hashes to what it did, so its chains resume
    # the noise state as phi alone was (an empty state as phi = 0): old chains resume
    state = np.asarray(fit.noise_state, float)
    for a in (fit.z, *covariance_state(fit.cov_z).values(), state if state.size else np.zeros(1)):
        h.update(np.ascontiguousarray(a, dtype=float).tobytes())
    return h.hexdigest()


def default_walkers(noise: str, ndim: int) -> int:
    """The ensemble's size when none is given: :data:`LEVELS_WALKERS` on the levels
    model's posterior, :data:`WALKERS` on the traces' own (noise-only) posterior; at
    least ``2 ndim + 2``, the differential-evolution move's minimum (ter Braak 2006)."""
    return max(LEVELS_WALKERS if noise == LEVELS else WALKERS, 2 * ndim + 2)


def _settings(fit: FitLike, params, priors, noise, walkers, seed) -> dict:
    return {
        "names": [p.name for p in params],
        # the chain is on the internal scale: how each column maps to physical units
        "transforms": [p.transform() for p in params],
        "noise": noise,
        "priors": {n: p.to_dict() for n, p in priors.items()},
        "walkers": walkers,
        "seed": seed,
        "fit": _fingerprint(fit),
        "law": fit.model.law.name,
        "coupling": fit.model.coupling.name,
    }


def _setting_priors(model: BenchModel, params) -> dict[str, Prior]:
    """The priors the fit's parameter settings give (:mod:`idtool._model._settings`)."""
    out: dict[str, Prior] = {}
    for s in model.settings:
        if s.prior is not None:
            dist, a, b = s.prior
            k1, k2 = DISTRIBUTIONS[dist]
            doc = {s.name: {"dist": dist, k1: a, k2: b}}
            out |= parse_priors(doc, params, s.source or "parameter settings")
    return out


def _resolve(fit, noise, priors, stored: dict | None):
    """Noise model and priors: the stored ones on resume, else the given ones or defaults."""
    if stored is not None:
        if noise is not None and noise != stored["noise"]:
            raise IdtoolError(
                f"the chain was sampled with --noise {stored['noise']}, not {noise}; "
                "start over without --resume to change it"
            )
        noise = stored["noise"]
    # A fit with scatter and discrepancy is sampled on its levels model unless a noise
    # model is asked for (the traces' own likelihood, noise only).
    noise = noise or (LEVELS if fit.levels is not None else fit.model.noise.name)
    if noise == LEVELS:
        if fit.levels is None:
            raise IdtoolError("this fit has no levels model (fitted with --variability off)")
        params = levels_params(fit.model, fit.levels[0])
    else:
        params = sampled_params(dataclasses.replace(fit.model, noise=NOISE_MODELS.get(noise)()))
    overrides: dict[str, Prior] = {}
    if isinstance(priors, str | os.PathLike):
        overrides = read_priors(priors, params)
    elif priors:
        raw = {n: p.to_dict() if isinstance(p, Prior) else p for n, p in priors.items()}
        overrides = parse_priors(raw, params, "priors")
    sd_names = {p.name for p in SD_PARAMS}
    table = {p.name: SD_PRIOR if p.name in sd_names else default_prior(p) for p in params}
    table |= _setting_priors(fit.model, params)  # the fit's parameter table, then --priors
    table |= overrides
    if stored is not None:
        stored_table = parse_priors(stored["priors"], params, CHAIN_FILE)
        if priors and stored_table != table:
            raise IdtoolError(
                "the priors differ from those the chain was sampled with; "
                "start over without --resume to change them"
            )
        table = stored_table
    return noise, params, table


def sample_posterior(
    fit: FitLike,
    walkers: int | None = None,
    steps: int | None = None,
    seed: int | None = None,
    noise: str | None = None,
    priors: str | os.PathLike | dict | None = None,
    chain_path: str | os.PathLike | None = None,
    resume: bool = False,
    progress: bool = False,
    checkpoint_s: float = 20.0,
    max_steps: int = MAX_STEPS,
    max_minutes: float = MAX_MINUTES,
) -> Posterior:
    """Sample the posterior of ``fit``'s shared parameters (module docstring).

    Args:
        fit: what sampling needs of a fit (:class:`~idtool._posterior._record.FitLike`).
        walkers: ensemble size (default :func:`default_walkers`: 16 on the levels
            model's posterior, 32 on the traces' own).
        steps: total chain length (a resumed chain is continued up to ``steps``); ``None``
            (the default) samples until the chain has converged
            (:data:`idtool._posterior._diagnostics.RULE`; :mod:`idtool._posterior._runner`),
            at most ``max_steps`` steps in total and ``max_minutes`` of this run's
            sampling, whichever comes first.
        seed: seeds the walker starts and emcee's moves (default 0; on resume the
            random state comes from the chain file).
        noise: a registered noise model (``NOISE_MODELS``; default: the fit's).
        priors: overrides of the default priors: a TOML/JSON path or a dict.
        chain_path: checkpoint file (``chain.h5``); ``None`` keeps the chain in memory.
        resume: continue the chain in ``chain_path``.
    """
    import emcee

    chain_file = Path(chain_path) if chain_path is not None else None
    stored, done = None, 0
    if resume and chain_file is not None and chain_file.exists():
        stored, done = read_settings(chain_file)
    noise, params, table = _resolve(fit, noise, priors, stored)
    if stored is not None:
        for name, given in (("walkers", walkers), ("seed", seed)):
            if given is not None and given != stored[name]:
                raise IdtoolError(
                    f"the chain was sampled with --{name} {stored[name]}, not {given}; "
                    "start over without --resume to change it"
                )
        walkers, seed = int(stored["walkers"]), int(stored["seed"])
        if stored["fit"] != _fingerprint(fit) or stored["names"] != [p.name for p in params]:
            raise IdtoolError(
                f"{chain_file}: sampled from another fit; start over without --resume"
            )
    seed = 0 if seed is None else seed
    ndim = len(params)
    walkers = default_walkers(noise, ndim) if walkers is None else walkers
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
    warnings: tuple[str, ...] = ()
    one_sided: dict[str, str] = {}  # the sides the data alone bound (_ridge.open_sides)
    # sampled along a ridge (_ridge.RidgeTarget) or with the funnel opened (_funnel)
    sheared: AbstractReparameterised | None = None
    if done == 0 and noise == LEVELS:
        free, sds = fit.levels
        levels_target = build_levels_target(fit.model, free, table)
        k = fit.model.n_physical
        theta, cov = levels_start(fit.z[:k], fit.cov_z.leading(k), sds, levels_target)
        z_lin = np.asarray(fit.z)
        fn = LogPosterior(levels_target, _batch(walkers, noise))
        rng = np.random.default_rng(seed)
        weak = weak_parameter(levels_target.params, theta, cov, k)
        if weak is not None:  # the data barely bound it: sampled along its profile
            capped = start_within(theta, cov, params)[1]
            ridge = ridge_profile(fn, levels_target, theta, weak)
            one_sided = {params[weak].name: open_sides(ridge)}
            # sheared over the box of every bounded parameter (_box.BoxTarget)
            box = BoxTarget.of(levels_target)
            sheared = RidgeTarget.along(box, ridge_in_box(ridge, box))
            fn = LogPosterior(sheared, _batch(walkers, noise))
            theta, cov = ridge_walkers(ridge, capped, walkers, rng)
            cov = box.cov_from_internal(np.mean(theta, axis=0), cov)
            theta = np.asarray(sheared.from_internal(box.from_internal(jnp.asarray(theta))))
        else:
            # the physical parameters on their box (_box.BoxTarget), then the
            # discrepancy's funnel opened over it (_funnel.FunnelTarget), if it has one:
            # the funnel reads the discrepancy sd on its internal scale, left unboxed
            box = BoxTarget.of(levels_target, tuple(range(k)))
            fn = LogPosterior(box, _batch(walkers, noise))
            theta, cov = (
                np.asarray(box.from_internal(jnp.asarray(theta))),
                box.cov_from_internal(theta, cov),
            )
            sheared = box
            funnel = open_funnel(box, fn, theta, k)
            if funnel is not None:
                sheared = funnel
                theta, cov = funnel.sheared_start(theta, cov)
                fn = LogPosterior(funnel, _batch(walkers, noise))
        mode_s = time.perf_counter() - started
        p0 = initial_walkers(theta, cov, fn, walkers, rng, levels_target.params)
        initial: Any = emcee.State(p0, random_state=np.random.RandomState(seed).get_state())
    elif done == 0:
        rebuild = functools.partial(build_target, fit.model, noise=noise, priors=table)
        start = find_start(fit, rebuild(np.asarray(fit.z)), rebuild)
        mode_s = time.perf_counter() - started
        z_lin, warnings = start.z_lin, start.warnings
        fn = LogPosterior(start.target, _batch(walkers, noise))
        rng = np.random.default_rng(seed)
        p0 = initial_walkers(start.theta, start.cov, fn, walkers, rng, start.target.params)
        initial = emcee.State(p0, random_state=np.random.RandomState(seed).get_state())
    else:
        assert chain_file is not None
        z_lin = read_linearisation(chain_file)
        if noise == LEVELS:
            levels_target = build_levels_target(fit.model, fit.levels[0], table)
            assert stored is not None
            # the box under the ridge or the funnel (a chain sampled before it: none)
            base = (
                BoxTarget.from_doc(levels_target, stored["box"])
                if stored.get("box")
                else levels_target
            )
            if stored.get("ridge"):  # sampled along a ridge (_ridge.RidgeTarget)
                sheared = RidgeTarget.from_doc(base, stored["ridge"])
            elif stored.get("funnel"):  # the funnel opened (_funnel.FunnelTarget)
                sheared = FunnelTarget.from_doc(base, stored["funnel"])
            elif isinstance(base, BoxTarget):
                sheared = base
            fn = LogPosterior(
                sheared if sheared is not None else levels_target, _batch(walkers, noise)
            )
        else:
            fn = LogPosterior(build_target(fit.model, z_lin, noise, table), _batch(walkers, noise))
        initial = last_state(chain_file)
        mode_s = 0.0
    settings = _settings(fit, params, table, noise, walkers, seed)
    settings |= {"warnings": list(warnings), "one_sided": one_sided}
    if sheared is not None:  # the chain holds transformed vectors: how to map them back
        for part in (sheared, getattr(sheared, "base", None)):
            if isinstance(part, AbstractReparameterised):
                settings[part.to_doc()["kind"]] = part.to_doc()
    store = ChainStore(chain_file, settings, np.asarray(z_lin))
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
                moves=_moves(noise, sheared if isinstance(sheared, RidgeTarget) else None),
            ),
            initial,
            store,
            done,
            tuple(p.name for p in params),
            steps,
            max_steps,
            max_minutes,
            checkpoint_s,
            bar,
        )
    finally:
        bar.close()
    chain, lp, acc = store.read()
    if sheared is not None:  # the sampled coordinates back to the internal scale
        chain = np.asarray(base_internal(sheared, jnp.asarray(chain)))
    values = np.stack(
        [np.asarray(p.value(np.asarray(chain[:, :, i], float))) for i, p in enumerate(params)],
        axis=-1,
    )
    if stored is not None:
        warnings = tuple(stored.get("warnings", ()))
        one_sided = dict(stored.get("one_sided", {}))
    timing = {
        "mode_search_s": mode_s,
        "compile_s": float(fn.compile_s or 0.0),
        "sampling_s": sample_s,
        "steps_this_run": float(diag.steps - start_done),
        "total_s": time.perf_counter() - started,
        "log_posterior_evaluations": float(fn.evaluations),
    }
    return Posterior(
        params=params,
        chain=chain,
        values=values,
        log_prob=lp,
        acceptance=acc,
        diagnostics=diag,
        noise=noise,
        priors=table,
        seed=seed,
        law=fit.model.law.name,
        coupling=fit.model.coupling.name,
        timing=timing,
        z_lin=np.asarray(z_lin),
        warnings=warnings,
        model=fit.model,
        conditioning=fit.conditioning,
        free_levels=fit.levels[0] if noise == LEVELS else None,
        one_sided=one_sided,
    )


class _NoBar:
    total: int = 0

    def update(self, n: int) -> None:
        pass

    def set_postfix_str(self, text: str) -> None:
        pass

    def close(self) -> None:
        pass


def _progress(enabled: bool, total: int, initial: int):
    if not enabled:
        return _NoBar()
    from tqdm import tqdm

    return tqdm(total=total, initial=initial, unit="step", desc="sampling", dynamic_ncols=True)
