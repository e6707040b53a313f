"""``idtool predict fits/NAME --load 450 --amplitude 0.5``: friction ratio with its band."""

from __future__ import annotations

import argparse
import json
import math

import idtool
from idtool._cli._args import number_list
from idtool._errors import IdtoolError

__all__ = ["register"]


def _check(name: str, values: list[float], lo: float, hi: float, closed_hi: bool) -> None:
    for v in values:
        if not (v > lo and (v <= hi if closed_hi else v < hi)):
            bracket = "]" if closed_hi else ")"
            raise IdtoolError(f"{name} {v:g}: must lie in ({lo:g}, {hi:g}{bracket}")


def _run(args: argparse.Namespace) -> int:

    # The options are checked before the fit is read (it takes a second or two).
    if args.amplitude is None and args.target_reduction is None:
        raise IdtoolError("give --amplitude, --target-reduction, or both")
    _check("--load", args.load, 0.0, math.inf, False)
    _check("--speed", args.speed or [], 0.0, math.inf, False)
    _check("--amplitude", args.amplitude or [], 0.0, 1.0, True)
    if args.target_reduction is not None and not 0.0 < args.target_reduction < 100.0:
        raise IdtoolError(
            f"--target-reduction {args.target_reduction:g}: give a percentage in (0, 100)"
        )
    if args.draws < 10:
        raise IdtoolError(f"--draws {args.draws}: give at least 10")
    fit = idtool.load_fit(args.fit)
    draws = fit.draws(args.draws, args.seed)
    n_draws = sum(c.n for c in draws.components)  # every coupling law's, when averaged
    doc: dict = {"source": draws.source, "note": draws.note, "n_draws": n_draws}
    doc |= {"coupling_law_weights": draws.law_weights} if draws.law_weights else {}
    lines = [f"draws: {draws.note}"]
    notes: list[str] = []
    if args.amplitude is not None:
        preds = fit.predict(
            args.load, args.amplitude, args.speed, max_draws=args.draws, seed=args.seed
        )
        doc["predictions"] = [p.to_dict() for p in preds]
        notes += preds.warnings
        lines += [
            "mean FR: what pulls at this operating point average to (use it for the "
            "design curve); next pull: where a single new pull will land (use it for "
            "acceptance limits)",
            f"{'load [N]':>9s} {'amplitude':>9s} {'speed':>8s}   {'mean FR [95%]':27s}"
            f"{'next pull FR [95%]':27s}reduction % [95%]",
        ]
        for p in preds:
            red, (rlo, rhi) = p.reduction_percent
            fr = f"{p.median:.4f} [{p.ci95[0]:.4f}, {p.ci95[1]:.4f}]"
            nmed, (nlo, nhi) = p.new_trace or (p.median, p.ci95)
            new = f"{nmed:.4f} [{nlo:.4f}, {nhi:.4f}]"
            lines.append(
                f"{p.normal_load_n:9g} {p.amplitude_fraction:9g} {p.pull_speed_m_s:8g}   "
                f"{fr:27s}{new:27s}{red:.1f} [{rlo:.1f}, {rhi:.1f}]"
            )
            if p.by_law:  # averaged over coupling laws: each law's own median
                laws = ", ".join(f"{law} {m:.4f}" for law, m in p.by_law)
                lines.append(f"{'':30s}mean FR by coupling law: {laws}")
    if args.target_reduction is not None:
        inverse = fit.amplitude_for(
            args.target_reduction, args.load, args.speed, max_draws=args.draws, seed=args.seed
        )
        doc["inverse"] = [a.to_dict() for a in inverse]
        lines += [a.statement() for a in inverse]
        notes += [n for n in inverse.warnings if n not in notes]
    doc["warnings"] = notes
    lines += [f"warning: {n}" for n in notes]
    print(json.dumps(doc, indent=1) if args.json else "\n".join(lines))
    return 0


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "predict",
        help="friction ratio (median, 95%% band) at operating points; amplitude for a target",
        description="Predict the friction ratio and the friction reduction from a fit's "
        "posterior (posterior.nc from 'idtool sample'; without it, Gaussian draws from the "
        "fit's covariance). Comma-separated lists give a grid (loads x amplitudes x speeds). "
        "--target-reduction gives the amplitude fraction needed for that reduction, or says "
        "it is out of reach.",
    )
    p.add_argument("fit", help="fit folder, e.g. fits/NAME")
    p.add_argument(
        "--load", type=number_list, required=True, help="normal load(s) [N], e.g. 450,670"
    )
    p.add_argument(
        "--amplitude", type=number_list, help="commanded amplitude fraction(s) in (0, 1]"
    )
    p.add_argument("--speed", type=number_list, help="pull speed(s) [m/s] (default: the fit's)")
    p.add_argument(
        "--target-reduction", type=float, help="friction reduction [%%] to find the amplitude for"
    )
    p.add_argument("--json", action="store_true", help="print JSON")
    p.add_argument("--draws", type=int, default=2000, help="draws used (default 2000)")
    p.add_argument("--seed", type=int, default=0, help="seed of covariance draws (no posterior)")
    p.set_defaults(func=_run)
