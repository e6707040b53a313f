"""``idtool predict fits/NAME --load 450 --amplitude 0.5``: friction ratio with its band."""

from __future__ import annotations

import argparse
import json
import math

from ._errors import IdtoolError

__all__ = ["register"]


def _numbers(text: str) -> list[float]:
    out = []
    for part in text.split(","):
        try:
            value = float(part)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{part!r} is not a number") from None
        if not math.isfinite(value):
            raise argparse.ArgumentTypeError(f"{part!r} is not a finite number")
        out.append(value)
    return out


def _check(name: str, values: list[float], lo: float, hi: float, closed_hi: bool) -> None:
    for v in values:
        if not (v > lo and (v <= hi if closed_hi else v < hi)):
            bracket = "]" if closed_hi else ")"
            raise IdtoolError(f"{name} {v:g}: must lie in ({lo:g}, {hi:g}{bracket}")


def _extrapolation(data, loads, amplitudes, speeds) -> list[str]:
    notes = []
    for label, given, seen in (
        ("normal load", loads, data.normal_load_n),
        ("amplitude fraction", amplitudes, data.amplitude_fraction),
        ("pull speed", speeds, data.pull_speed_m_s),
    ):
        lo, hi = float(min(seen)), float(max(seen))
        out = [f"{v:.3g}" for v in given if v < lo * (1 - 1e-9) or v > hi * (1 + 1e-9)]
        if out:
            vals = ", ".join(out)
            notes.append(
                f"{label} {vals} lies outside the fitted range [{lo:g}, {hi:g}]: extrapolation"
            )
    return notes


def _run(args: argparse.Namespace) -> int:
    from ._fitstore import load_fit
    from ._predict import amplitude_for_reduction, predict_friction_ratio, prediction_draws

    if args.amplitude is None and args.target_reduction is None:
        raise IdtoolError("give --amplitude, --target-reduction, or both")
    _check("--load", args.load, 0.0, math.inf, False)
    if args.amplitude is not None:
        _check("--amplitude", args.amplitude, 0.0, 1.0, True)
    if args.target_reduction is not None and not 0.0 < args.target_reduction < 100.0:
        raise IdtoolError(
            f"--target-reduction {args.target_reduction:g}: give a percentage in (0, 100)"
        )
    if args.draws < 10:
        raise IdtoolError(f"--draws {args.draws}: give at least 10")
    fit = load_fit(args.fit)
    data = fit.model.data
    speeds = args.speed
    if speeds is None:
        seen = sorted(set(data.pull_speed_m_s.tolist()))
        if len(seen) > 1:
            raise IdtoolError(f"the fit has several pull speeds ({seen}); give --speed")
        speeds = seen
    _check("--speed", speeds, 0.0, math.inf, False)
    draws = prediction_draws(fit, max_draws=args.draws, seed=args.seed)
    notes = _extrapolation(data, args.load, args.amplitude or [], speeds)
    doc: dict = {"source": draws.source, "note": draws.note, "n_draws": draws.n}
    lines = [f"predictions from the {draws.note}"]
    if args.amplitude is not None:
        preds = predict_friction_ratio(draws, args.load, args.amplitude, speeds)
        doc["predictions"] = [p.to_dict() for p in preds]
        lines.append(
            f"{'load [N]':>9s} {'amplitude':>9s} {'speed':>8s}   {'FR median [95%]':28s}"
            f"reduction % median [95%]"
        )
        for p in preds:
            red, (rlo, rhi) = p.reduction_percent
            fr = f"{p.median:.4f} [{p.ci95[0]:.4f}, {p.ci95[1]:.4f}]"
            lines.append(
                f"{p.normal_load_n:9g} {p.amplitude_fraction:9g} {p.pull_speed_m_s:8g}   "
                f"{fr:28s}{red:.1f} [{rlo:.1f}, {rhi:.1f}]"
            )
    if args.target_reduction is not None:
        inverse = amplitude_for_reduction(draws, args.target_reduction, args.load, speeds)
        doc["inverse"] = [a.to_dict() for a in inverse]
        lines += [a.statement() for a in inverse]
        needed = [a.amplitude[0] for a in inverse if a.reachable]
        notes += [
            n.replace("amplitude fraction", "needed amplitude fraction")
            for n in _extrapolation(data, [], needed, [])
        ]
    doc["warnings"] = notes
    lines += [f"warning: {n}" for n in notes]
    if args.json:
        print(json.dumps(doc, indent=1))
    else:
        print("\n".join(lines))
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
    p.add_argument("--load", type=_numbers, required=True, help="normal load(s) [N], e.g. 450,670")
    p.add_argument("--amplitude", type=_numbers, help="commanded amplitude fraction(s) in (0, 1]")
    p.add_argument("--speed", type=_numbers, help="pull speed(s) [m/s] (default: the fit's)")
    p.add_argument(
        "--target-reduction", type=float, help="friction reduction [%%] to find the amplitude for"
    )
    p.add_argument("--json", action="store_true", help="print JSON")
    p.add_argument("--draws", type=int, default=2000, help="draws used (default 2000)")
    p.add_argument("--seed", type=int, default=0, help="seed of covariance draws (no posterior)")
    p.set_defaults(func=_run)
