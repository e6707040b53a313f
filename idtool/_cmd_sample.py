"""``idtool sample fits/NAME``: posterior of a fit with emcee, diagnostics, PPC."""

from __future__ import annotations

import argparse
import json
import os
import time
from pathlib import Path

from ._errors import IdtoolError

__all__ = ["register", "sample_report"]

_FILES = ("chain.h5", "posterior.nc", "sample.json", "report_sample.txt", "ppc.png")


def _fmt(x: float) -> str:
    return f"{x:.5g}"


def sample_report(post, fit, check, folder: Path, shrink) -> str:
    """A plain-text report of a posterior run."""
    from ._likelihood import DEFAULT_NOISE

    model = fit.model
    t = post.timing
    est = fit.doc.get("parameters", {}) | fit.doc.get("bench", {})
    lines = [
        "[[Posterior]]",
        f"    fit          {folder} ({model.law} friction, {model.coupling} coupling)",
        f"    noise        {post.noise}"
        + (" (default)" if post.noise == DEFAULT_NOISE else "")
        + "; the per-trace nuisances are integrated out, not fixed",
        f"    sampler      emcee, {post.chain.shape[1]} walkers x {post.chain.shape[0]} steps, "
        f"seed {post.seed}; compile {t['compile_s']:.1f} s, sampling {t['sampling_s']:.1f} s "
        f"for {t['steps_this_run']:.0f} steps",
        "[[Parameters]]  (posterior median and 95% interval; the fit's for comparison)",
    ]
    for name, s in post.summary().items():
        fit_ci = ""
        if name in est:
            lo, hi = est[name]["ci95"]
            fit_ci = f"   fit {_fmt(est[name]['estimate'])} [{_fmt(lo)}, {_fmt(hi)}]"
        lines.append(
            f"    {name:20s}{_fmt(s['median']):>12s} {s['unit']:4s} "
            f"[{_fmt(s['ci95'][0])}, {_fmt(s['ci95'][1])}]{fit_ci}"
        )
    lines += ["[[Diagnostics]]", post.diagnostics.report()]
    lines += [
        "[[Posterior predictive check]]",
        f"    {100 * check.inside_fraction:.1f}% of the measured block means lie inside the "
        "95% predictive band",
        f"    lag-1 autocorrelation of the residuals: measured {check.lag1_measured:.3f}, "
        f"replicated 95% [{check.lag1_replicated[0]:.3f}, {check.lag1_replicated[1]:.3f}], "
        f"p = {check.lag1_p_value:.2f}",
        "[[Priors]]",
    ]
    lines += [f"    {n:20s}{p.describe()}" for n, p in post.priors.items()]
    worst = min(shrink)
    lines += [
        "[[Nuisances]]",
        f"    holding the per-trace nuisances at the fit's values would shrink the shared "
        f"parameters' sds to {100 * worst:.0f}-{100 * max(shrink):.0f}% of their marginal "
        "values (fit covariance), so they are integrated out",
        "[[Warnings]]",
    ]
    lines += [f"    - {w}" for w in post.warnings] or ["    none"]
    return "\n".join(lines)


def _run(args: argparse.Namespace) -> int:
    from . import __version__
    from ._fitstore import load_fit
    from ._likelihood import build_target, conditioning_shrinkage
    from ._posterior_store import write_posterior
    from ._ppc import plot_predictive, posterior_predictive
    from ._provenance import provenance
    from ._sample import CHAIN_FILE, sample_posterior

    started = time.perf_counter()
    folder = Path(args.fit)
    fit = load_fit(folder)
    chain = folder / CHAIN_FILE
    if chain.exists() and not (args.resume or args.force):
        raise IdtoolError(f"{chain} exists: pass --resume to continue it or --force to start over")
    if args.checkpoint_s < 0:
        raise IdtoolError(f"--checkpoint-s {args.checkpoint_s:g}: give a number >= 0")
    if args.resume and not chain.exists():
        print(f"idtool sample: no {chain} to resume; starting a new chain")
    if args.force and not args.resume:
        for name in _FILES:  # a new chain: no output of the old one may survive
            (folder / name).unlink(missing_ok=True)
    try:
        post = sample_posterior(
            fit,
            walkers=args.walkers,
            steps=args.steps,
            seed=args.seed,
            noise=args.noise,
            priors=args.priors,
            chain_path=chain,
            resume=args.resume,
            progress=not args.no_progress,
            checkpoint_s=args.checkpoint_s,
        )
    except KeyboardInterrupt:
        saved = f"the steps done so far are in {chain}" if chain.exists() else "nothing saved"
        print(f"idtool sample: interrupted; {saved}; continue with --resume", flush=True)
        return 130
    target = build_target(fit.model, post.z_lin, post.noise, post.priors)
    check = posterior_predictive(post, fit, seed=post.seed, target=target)
    shrink = conditioning_shrinkage(fit.cov_z, fit.model.n_shared)
    report = sample_report(post, fit, check, folder, shrink)
    prov = provenance(args.argv)
    doc = {
        "posterior": post.summary(),
        "noise": post.noise,
        "priors": {n: p.to_dict() for n, p in post.priors.items()},
        "diagnostics": post.diagnostics.to_dict(),
        "posterior_predictive": check.to_dict(),
        "nuisances": {
            "treatment": "integrated out (linearised at the fit, Gaussian)",
            "sd_ratio_if_fixed": dict(
                zip(fit.model.names[: fit.model.n_shared], map(float, shrink), strict=True)
            ),
        },
        "warnings": list(post.warnings),
        "timing_s": post.timing,
        "seed": post.seed,
        "idtool_version": __version__,
        "command": prov["command"],
        "versions": prov["versions"],
        "created_utc": prov["created_utc"],
    }
    write_posterior(post, folder / "posterior.nc", extra={"fit_folder": str(folder)})
    for name, text in (
        ("sample.json", json.dumps(doc, indent=1) + "\n"),
        ("report_sample.txt", report + "\n"),
    ):
        tmp = folder / (name + ".partial")
        tmp.write_text(text)
        os.replace(tmp, folder / name)
    plot_predictive(check, fit.model.data.trace_ids, folder / "ppc.png")
    print(report)
    print(f"wrote {folder}/ ({', '.join(_FILES)}) in {time.perf_counter() - started:.1f} s")
    return 0


def _positive_int(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not an integer") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"{value}: give a positive integer")
    return value


def register(sub: argparse._SubParsersAction) -> None:
    from ._likelihood import DEFAULT_NOISE, NOISE_MODELS

    p = sub.add_parser(
        "sample",
        help="sample the posterior of a fit with emcee",
        description="Posterior of a fit's physical, bench and noise parameters with emcee "
        "(per-trace nuisances integrated out), checkpointed to fits/NAME/chain.h5; writes "
        "posterior.nc (ArviZ InferenceData), sample.json, report_sample.txt and ppc.png.",
    )
    p.add_argument("fit", help="fit folder written by 'idtool fit', e.g. fits/NAME")
    p.add_argument("--walkers", type=_positive_int, help="walkers (default 32)")
    p.add_argument(
        "--steps", type=_positive_int, default=3000, help="total chain length (default 3000)"
    )
    p.add_argument("--seed", type=int, help="random seed (default 0)")
    p.add_argument("--resume", action="store_true", help="continue chain.h5 up to --steps in total")
    p.add_argument("--force", action="store_true", help="discard an existing chain.h5")
    p.add_argument(
        "--noise",
        choices=NOISE_MODELS,
        default=None,
        help=f"noise model of the block means (default {DEFAULT_NOISE}: load-cell noise is "
        "correlated, independent noise gives falsely tight posteriors)",
    )
    p.add_argument("--priors", help="TOML or JSON file overriding default priors")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.add_argument(
        "--checkpoint-s",
        type=float,
        default=20.0,
        help="seconds between checkpoints of chain.h5 (default 20)",
    )
    p.set_defaults(func=_run)
