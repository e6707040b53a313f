"""Benchmark: posterior sampling of the example fit, idtool (JAX) against NumPy/SciPy.

Same target on both sides: the log-posterior of :mod:`idtool._posterior._likelihood` for the
example dataset's fit (Dahl law, power-limited coupling, AR(1) noise; 8 sampled
parameters, the 96 per-trace nuisances integrated out), and the same emcee moves. The
fit is the noise-only one (``variability=False``): the NumPy replica implements that
posterior, not the levels model's that ``idtool sample`` draws by default (32 x 3000 of
that one on the example: 21.5 s in all on 2 cores, 2026-11-24).

* idtool: ``sample_posterior`` (jitted log-posterior batched over walkers, ``vectorize=True``),
  32 walkers x 3000 steps, in memory and with ``chain.h5`` checkpoints as
  ``idtool sample`` runs it. Compilation and the mode search are timed apart.
* SciPy: the same log-posterior in NumPy, one walker at a time (emcee's default
  ``vectorize=False``): the friction ratio at the 6 distinct operating points from the
  Dahl ODE by ``solve_ivp(LSODA, rtol=1e-8)`` (:func:`dahl_friction_ratio` below; the
  one of ``benchmarks/bench_fit.py`` is not reused, its docstring says why), the bench
  model vectorised in NumPy (generous to SciPy: no Python loop over samples), the same
  AR(1) whitening and nuisance integral (the per-trace Gram matrices are shared
  constants). A full 3000-step run
  would take hours, so it runs ``--scipy-steps`` steps (default 5) and its time per
  step is measured; both sides run the same sampler on the same posterior, so their
  effective samples per step are the same (idtool's, measured on its full run), and
  ESS/s = ESS per step / seconds per step.

First: the default posterior (the levels model's) with the moves before and after issue
26 and a default run until converged (:func:`levels_moves`), then the ensemble's size on
it, 16 walkers (the default since issue 26) against 32 (:func:`ensemble_sizes`). Also:
the default stretch move against idtool's moves (32 x 3000 each; skip with ``--quick``),
and a cross-check of the two log-posteriors at 8 points (must agree to 0.2: the contact
solvers differ by ~1e-5 in FR, which moves the log-posterior by up to ~0.1).

Measured 2026-11-27 (2 cores, one busy with a study), :func:`ensemble_sizes`: 16 walkers
tau 129 (discrepancy_fr), 2.54 ms/step, 50 tau in 16.4 s; 32 walkers tau 115, 4.23
ms/step, 24.3 s.

The walkers' box coordinates (issue 26, ``idtool/_posterior/_box.py``), measured with
fixed-length chains of ``sample_posterior`` (16 walkers x 40,000 steps, 2026-11-27, load
4-8), the slowest parameter's integrated time before -> after: "scatter" 101 1,311 and
1,172 (the coupling gain, sampler seeds 1 and 2) -> 256 (the discrepancy sd; Kt 61 along
its profile); "coupling" 501 852 -> 522; the example (16,000 steps) 76 -> 75 (Kt 54 ->
31, the gain 57 -> 26). ESS per step is 16 / tau: 1.6x (coupling 501) to 5x (scatter
101); a step costs the same.

Targets (issue 5): 32 x 3000 on the example in under 2 minutes on 2 cores; ESS/s at
least 30x the non-vectorised SciPy run.

Measured on a 2-core machine with light other load (idtool 0.1.0): 32 x 3000 in 28 s
(compile 0.9 s, mode search 7.5 s, sampling 19.3 s = 6.4 ms/step), max tau 27 (stretch
move: 81), min ESS 3550; SciPy 12 ms per evaluation = 0.38 s/step; ESS/s 184 against
3.1, ratio 60 (42 with compilation and mode search counted).

Run: ``.venv/bin/python benchmarks/bench_sample.py`` (about 2 minutes; mind other load on
the machine, JAX's thread pool suffers from it more than SciPy's single thread: under a
load of 4 on 2 cores the ratio fell to about 30).
"""

from __future__ import annotations

import argparse
import math
import tempfile
import time
from pathlib import Path

import numpy as np
from scipy.integrate import solve_ivp

WALKERS, STEPS = 32, 3000
LP_TOLERANCE = 0.2


def dahl_friction_ratio(vr: float, lam: float) -> float:
    """Steady cycle-averaged Dahl FR at velocity ratio ``vr`` and stiffness ``lam``.

    ``df/dtheta = lam (vr + cos theta) (1 - sgn(vr + cos theta) f)`` is linear in f for a
    given slip, so one cycle from f = 0 together with the homogeneous response
    ``h = 1 - g`` (``g`` the decay of a unit initial state) gives the periodic state
    ``f* = f(2 pi) / h(2 pi)`` by superposition, for any lam. LSODA, rtol 1e-8, steps of
    at most 1/64 cycle: without that bound LSODA can step over the short backward
    stretch (``bench_fit.dahl_friction_ratio`` returns FR ~ 1 at VR 0.2, Lambda 12-14,
    where the truth is 0.134; so it is not reused here).
    """

    def rhs(theta, y):
        du = vr + math.cos(theta)
        return [lam * (du - abs(du) * y[0]), lam * abs(du) * (1.0 - y[1]), y[0], y[1]]

    step = 2 * math.pi / 64
    y0 = [0.0] * 4
    sol = solve_ivp(rhs, (0, 2 * math.pi), y0, "LSODA", rtol=1e-8, atol=1e-12, max_step=step)
    f_end, h_end, int_f, int_h = sol.y[:, -1]
    return float((int_f + f_end / h_end * (2 * math.pi - int_h)) / (2 * math.pi))


class NumpyPosterior:
    """The idtool log-posterior of one walker in NumPy/SciPy (Dahl, power-limited)."""

    def __init__(self, target):
        m = target.model
        d = m.data
        assert m.law.name == "dahl" and m.coupling.name == "power-limited"
        assert m.noise.name == "ar1"
        bt = np.asarray(d.block_trace)
        nu = {k: np.asarray(x) for k, x in target.nuisances.items()}

        def per_block(x):
            return np.asarray(x)[bt][:, None]

        a = {
            "force_n": np.asarray(d.force_n),
            "sub_time_s": np.asarray(d.sub_time_s),
            "first": np.asarray(d.first),
            "block_trace": bt,
            "startup_s": per_block(nu["pull_start_s"]),
            "on_start_s": per_block(d.on_start_s + nu["delay_on_s"]),
            "on_end_s": per_block(d.on_end_s + nu["delay_off_s"]),
            "offset_n": per_block(nu["offset_n"]),
            "load_n": np.asarray(d.normal_load_n),
            "speed_m_s": np.asarray(d.pull_speed_m_s),
            "op_index": np.asarray(d.op_index),
            "op_load_n": np.asarray(d.op_load_n),
            "op_alpha": np.asarray(d.op_alpha),
            "op_speed_m_s": np.asarray(d.op_speed_m_s),
            "jac_e": np.asarray(target.jac_e),
            "gram": np.asarray(target.gram),
            "continues": np.asarray(target.continues),
        }
        self.a = a
        self.params = target.params
        self.priors = target.priors
        self.n_traces = d.n_traces
        self.w = 2 * math.pi * float(d.vibration_frequency_hz)
        self.a_max = float(d.max_amplitude_m)
        for prior in self.priors:
            assert prior.dist in ("loguniform", "uniform")
        self.evaluations = 0

    def values(self, theta):
        out = {}
        for p, z in zip(self.params, theta, strict=True):
            if p.kind == "log":
                lo, hi = math.log(p.lo), math.log(p.hi)
                out[p.name] = math.exp(lo + (hi - lo) / (1.0 + math.exp(-z)))
            else:  # tanh
                out[p.name] = p.lo + (p.hi - p.lo) * 0.5 * (1.0 + math.tanh(z))
        return out

    def log_prior(self, theta, v) -> float:
        lp = 0.0
        for p, prior, z in zip(self.params, self.priors, theta, strict=True):
            x = v[p.name]
            if not prior.a <= x <= prior.b:
                return -math.inf
            if prior.dist == "loguniform":
                lp += -math.log(x) - math.log(math.log(prior.b / prior.a))
            else:
                lp += -math.log(prior.b - prior.a)
            if p.kind == "log":
                lo, hi = math.log(p.lo), math.log(p.hi)
                s = 1.0 / (1.0 + math.exp(-z))
                lp += math.log(x) + math.log(hi - lo) + math.log(s) + math.log1p(-s)
            else:
                az = abs(z)
                lp += (
                    math.log(p.hi - p.lo) + math.log(2.0) - 2 * (az + math.log1p(math.exp(-2 * az)))
                )
        return lp

    def predict(self, v):
        a = self.a
        fr_ops = np.empty(a["op_load_n"].size)
        for j, (load, alpha, speed) in enumerate(
            zip(a["op_load_n"], a["op_alpha"], a["op_speed_m_s"], strict=True)
        ):
            amp = (
                v["coupling_gain"]
                * alpha
                * self.a_max
                / math.sqrt(1 + (alpha * load / v["power_load_n"]) ** 2)
            )
            fr_ops[j] = dahl_friction_ratio(
                speed / (amp * self.w), v["Kt"] * amp / (v["mu"] * load)
            )
        off = v["mu"] * a["load_n"]
        on = fr_ops[a["op_index"]] * off
        bt, c = a["block_trace"], 0.5

        def smin(x, y, w):
            return 0.5 * (x + y - np.sqrt((x - y) ** 2 + w**2))

        def smax(x, y, w):
            return 0.5 * (x + y + np.sqrt((x - y) ** 2 + w**2))

        t = a["sub_time_s"]
        f_off = off[bt][:, None]
        depth = f_off - on[bt][:, None]
        slope, up = v["slope_n_s"], v["startup_slope_n_s"]
        rise = smin(up * smax(t - a["startup_s"], 0.0, c / up), f_off, c)
        has_on = np.isfinite(a["on_start_s"]) & np.isfinite(a["on_end_s"])
        t_on = np.where(has_on, a["on_start_s"], 0.0)
        on_len = np.where(has_on, a["on_end_s"] - t_on, 0.0)
        drop_on = smin(smax(slope * (t - t_on), 0.0, c), depth, c)
        drop_end = smin(slope * on_len, depth, c)
        drop_after = smax(drop_end - slope * (t - t_on - on_len), 0.0, c)
        drop = np.where(has_on, np.where(t < t_on + on_len, drop_on, drop_after), 0.0)
        return (a["offset_n"] + rise - drop).mean(axis=1)

    def __call__(self, theta) -> float:
        self.evaluations += 1
        v = self.values(theta)
        lp = self.log_prior(theta, v)
        if not math.isfinite(lp):
            return -math.inf
        a = self.a
        e = self.predict(v) - a["force_n"]
        sigma, phi = v["sigma_n"], v["phi"]
        head = math.sqrt(1 - phi**2)
        w = np.where(a["first"], head * e, e - phi * np.roll(e, 1))
        lt_w = np.where(a["first"], head * w, w) - phi * np.where(
            a["continues"], np.roll(w, -1), 0.0
        )
        jw = a["jac_e"] * lt_w[:, None]
        h = np.stack(
            [np.bincount(a["block_trace"], jw[:, j], self.n_traces) for j in range(jw.shape[1])], 1
        )
        g = a["gram"][0] + phi * a["gram"][1] + phi**2 * a["gram"][2]
        sd = 100.0  # idtool._posterior._likelihood.NUISANCE_PRIOR_SD
        mat = g / sigma**2 + np.eye(g.shape[-1]) / sd**2
        chol = np.linalg.cholesky(mat)
        y = np.linalg.solve(chol, (-h / sigma**2)[..., None])
        n, p = e.size, h.size
        ll = -0.5 * n * math.log(2 * math.pi * sigma**2) - 0.5 * float(w @ w) / sigma**2
        ll += 0.5 * float(np.sum(y**2))
        ll -= float(np.sum(np.log(np.diagonal(chol, axis1=-2, axis2=-1)))) + p * math.log(sd)
        ll += 0.5 * self.n_traces * math.log1p(-(phi**2))
        return lp + ll


def sample_module_moves():
    """The moves ``idtool sample`` uses on the noise-only posterior (the SciPy side runs
    the same)."""
    from idtool._posterior._sample import _moves

    return _moves("ar1")


def levels_moves(steps: int = 4000) -> None:
    """The default posterior (the levels model's) of the example's default fit: the
    slowest parameter's tau and ESS/s with the move idtool used before issue 26 (DE alone)
    and with today's (DE and snooker, half and half), each 32 x ``steps``; then a default
    run until converged."""
    import emcee

    import idtool
    import idtool._posterior._sample as sample_module

    # the power-limited law, which the NumPy reference below writes out
    fit = idtool.fit(
        idtool.load_dataset(idtool.example_dataset_path()), coupling="power-limited", seed=0
    )
    today = sample_module._moves
    runs = {}
    for label, moves in (
        ("DE alone (before)", lambda *_: [(emcee.moves.DEMove(), 1.0)]),
        ("DE + snooker (today)", today),
    ):
        sample_module._moves = moves
        try:
            runs[label] = fit.sample(walkers=WALKERS, steps=steps, seed=0)
        finally:
            sample_module._moves = today
    until = fit.sample(seed=0)
    print()
    print(f"levels posterior of the example's default fit, {WALKERS} walkers x {steps} steps:")
    print(f"{'moves':24}{'slowest':>16}{'tau':>7}{'bulk ESS':>10}{'s':>7}{'ESS/s':>8}{'acc':>6}")
    for label, post in [*runs.items(), ("until converged (today)", until)]:
        d = post.diagnostics
        sampling = post.timing["sampling_s"]
        ess = float(np.min(d.ess_bulk))
        print(
            f"{label:24}{d.slowest:>16}{np.max(d.tau):7.1f}{ess:10.0f}{sampling:7.1f}"
            f"{ess / sampling:8.0f}{np.mean(d.acceptance):6.2f}"
        )
    d = until.diagnostics
    print(
        f"until converged: {d.steps} steps x {until.chain.shape[1]} walkers, "
        f"{until.timing['total_s']:.1f} s in all (compile {until.timing['compile_s']:.1f} s), "
        f"stopped by {d.stopped_by}"
    )
    ensemble_sizes(fit)


def ensemble_sizes(fit, steps: int = 16000, burn: int = 2000) -> None:
    """The ensemble's size on the levels posterior (issue 26; the default,
    ``idtool._posterior._sample.LEVELS_WALKERS``): a fixed-length chain of 16 and of 32
    walkers, the slowest parameter's integrated autocorrelation time in steps (emcee's,
    after ``burn`` steps), the cost of a step, and what 50 tau of steps (the rule's
    chain length) take."""
    import emcee

    print()
    print(f"ensemble size, levels posterior, {steps} steps each (tau after {burn}):")
    print(f"{'walkers':>8}{'slowest':>16}{'tau':>7}{'ms/step':>9}{'50 tau [s]':>12}")
    for walkers in (16, 32):
        post = fit.sample(walkers=walkers, steps=steps, seed=0)
        tau = emcee.autocorr.integrated_time(post.chain[burn:], quiet=True)
        ms = 1000.0 * post.timing["sampling_s"] / steps
        slowest = post.names[int(np.argmax(tau))]
        print(
            f"{walkers:8d}{slowest:>16}{np.max(tau):7.0f}{ms:9.2f}"
            f"{50.0 * np.max(tau) * ms / 1000.0:12.1f}"
        )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="skip the stretch-move run")
    parser.add_argument("--scipy-steps", type=int, default=5)
    args = parser.parse_args()
    total0 = time.perf_counter()
    levels_moves()

    import emcee

    import idtool
    from idtool._fit._run import fit_dataset
    from idtool._posterior._sample import LogPosterior, sample_posterior

    print("fitting the example dataset ...", flush=True)
    t0 = time.perf_counter()
    example = idtool.load_dataset(idtool.example_dataset_path())
    fit = fit_dataset(example, coupling="power-limited", seed=0, variability=False).chosen
    print(f"  fit in {time.perf_counter() - t0:.1f} s", flush=True)

    print(f"idtool: {WALKERS} walkers x {STEPS} steps, in memory ...", flush=True)
    post = sample_posterior(fit, walkers=WALKERS, steps=STEPS, seed=0)
    with tempfile.TemporaryDirectory() as tmp:
        print("idtool: the same with chain.h5 checkpoints (as idtool sample) ...", flush=True)
        post_file = sample_posterior(
            fit, walkers=WALKERS, steps=STEPS, seed=0, chain_path=Path(tmp) / "chain.h5"
        )
    assert np.array_equal(post.chain, post_file.chain), "checkpointing changed the chain"
    moves = sample_module_moves()
    stretch = None
    if not args.quick:
        print("idtool: the same with emcee's default stretch move ...", flush=True)
        import idtool._posterior._sample as sample_module

        sample_module._moves = lambda *_: [(emcee.moves.StretchMove(), 1.0)]
        stretch = sample_posterior(fit, walkers=WALKERS, steps=STEPS, seed=0)

    # the same posterior in NumPy/SciPy
    from idtool._posterior._likelihood import build_target

    target = build_target(fit.model, fit.z, "ar1", post.priors)
    numpy_lp = NumpyPosterior(target)
    rng = np.random.default_rng(1)
    kept = post.chain[post.diagnostics.burn :].reshape(-1, post.chain.shape[-1])
    points = kept[rng.choice(kept.shape[0], 8, replace=False)]
    lp_jax = np.asarray(LogPosterior(target, 8)(points))
    lp_np = np.array([numpy_lp(p) for p in points])
    lp_diff = float(np.max(np.abs(lp_jax - lp_np)))

    print(f"SciPy: emcee vectorize=False, {WALKERS} walkers x {args.scipy_steps} steps ...")
    sampler = emcee.EnsembleSampler(
        WALKERS,
        kept.shape[1],
        numpy_lp,
        moves=moves,
    )
    start = post.chain[-1]
    numpy_lp.evaluations = 0
    t0 = time.perf_counter()
    sampler.run_mcmc(start, args.scipy_steps, skip_initial_state_check=True)
    scipy_s = time.perf_counter() - t0
    per_eval = scipy_s / numpy_lp.evaluations
    scipy_step = per_eval * WALKERS

    t = post.timing
    idt_step = t["sampling_s"] / STEPS
    ess = post.diagnostics.ess
    ess_per_step = float(np.min(ess)) / STEPS
    ess_s_idtool = float(np.min(ess)) / t["sampling_s"]
    ess_s_idtool_all = float(np.min(ess)) / (t["sampling_s"] + t["compile_s"] + t["mode_search_s"])
    ess_s_scipy = ess_per_step / scipy_step
    print()
    print(
        f"Example: {fit.model.data.n_traces} traces, {fit.model.data.n_blocks} blocks, "
        f"{kept.shape[1]} sampled parameters ({', '.join(post.names)})"
    )
    print(f"log-posterior, NumPy/SciPy vs JAX at 8 posterior draws: max |diff| = {lp_diff:.2e}")
    print()
    print(
        f"idtool {WALKERS} x {STEPS}: compile {t['compile_s']:.1f} s, mode search "
        f"{t['mode_search_s']:.1f} s, sampling {t['sampling_s']:.1f} s "
        f"({1e3 * idt_step:.1f} ms/step); with chain.h5 checkpoints "
        f"{post_file.timing['sampling_s']:.1f} s"
    )
    print(
        f"  tau max {np.max(post.diagnostics.tau):.1f}, ESS min {np.min(ess):.0f} / median "
        f"{np.median(ess):.0f}, acceptance {np.mean(post.acceptance):.3f}, "
        f"converged: {post.diagnostics.converged}"
    )
    if stretch is not None:
        sd = stretch.diagnostics
        print(
            f"  stretch move instead: tau max {np.max(sd.tau):.1f}, ESS min {np.min(sd.ess):.0f}, "
            f"sampling {stretch.timing['sampling_s']:.1f} s, converged: {sd.converged}"
        )
    print(
        f"SciPy: {1e3 * per_eval:.1f} ms per log-posterior evaluation, "
        f"{scipy_step:.2f} s per step ({numpy_lp.evaluations} evaluations timed); "
        f"{STEPS} steps would take {STEPS * scipy_step / 3600:.1f} h"
    )
    print()
    print(f"{'':44}{'ESS/s':>10}{'ratio':>8}")
    print(f"{'SciPy, emcee vectorize=False':44}{ess_s_scipy:10.3f}{1.0:8.1f}")
    print(f"{'idtool, sampling only':44}{ess_s_idtool:10.1f}{ess_s_idtool / ess_s_scipy:8.0f}")
    print(
        f"{'idtool, + compile and mode search':44}{ess_s_idtool_all:10.1f}"
        f"{ess_s_idtool_all / ess_s_scipy:8.0f}"
    )
    wall = t["sampling_s"] + t["compile_s"] + t["mode_search_s"]
    print()
    ratio = ess_s_idtool / ess_s_scipy
    print(
        f"target 32 x 3000 under 120 s: {wall:.0f} s ({'PASS' if wall < 120 else 'FAIL'}); "
        f"ESS/s ratio >= 30: {ratio:.0f} ({'PASS' if ratio >= 30 else 'FAIL'})"
    )
    print(f"benchmark total {time.perf_counter() - total0:.0f} s")
    if lp_diff > LP_TOLERANCE:
        raise SystemExit(f"the two log-posteriors differ by {lp_diff:.3g} (> {LP_TOLERANCE})")


if __name__ == "__main__":
    main()
