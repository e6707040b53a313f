"""``idtool predict fits/NAME --load 450 --amplitude 0.5``: friction ratio with its band."""

from __future__ import annotations

import argparse
import json
import math

import numpy as np

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
    from idtool._levels._store import is_levels_fit  # (lazy: --help loads no JAX)

    if is_levels_fit(args.fit):
        return _run_table(args)
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


def _run_table(args: argparse.Namespace) -> int:
    """``predict`` on a friction table's fit (``idtool.LevelsFit.predict``): FR at the
    grid of loads x amplitude fractions (of the table's reference amplitude) x sliding
    speeds (default: the table's), with the bands at a new condition and of the next
    measurement; with ``--target-reduction`` the amplitude for it (:func:`_amplitude_for`)."""
    fit = idtool.load_levels_fit(args.fit)
    t = fit.table
    speeds = args.speed or sorted({float(v) for v in t.sliding_speed_m_s})
    inverse = [] if args.target_reduction is None else _amplitude_for(fit, args, speeds)
    if args.amplitude is None:
        doc = {"kind": "levels", "inverse": inverse, "warnings": []}
        text = "\n".join(i["statement"] for i in inverse)
        print(json.dumps(doc, indent=1) if args.json else text)
        return 0
    grid = np.array([(n, a, v) for n in args.load for a in args.amplitude for v in speeds])
    p = fit.predict(grid[:, 0], grid[:, 2], amplitude_fraction=grid[:, 1])
    rows = p.to_rows()
    notes: list[str] = []
    tested = {
        "load": (t.normal_load_n, grid[:, 0], "N", 1.0),
        "amplitude": (t.amplitude_m, grid[:, 1] * t.reference_amplitude_m, "um", 1e6),
        "speed": (t.sliding_speed_m_s, grid[:, 2], "mm/s", 1e3),
    }
    for name, (have, asked, unit, scale) in tested.items():
        lo, hi = float(np.min(have)), float(np.max(have))
        if np.any((asked < lo * (1 - 1e-9)) | (asked > hi * (1 + 1e-9))):
            span = f"{lo * scale:g}" if hi == lo else f"{lo * scale:g}-{hi * scale:g}"
            notes.append(f"a {name} outside the table's {span} {unit}: extrapolated by the model")
    if not np.all(p.pinned):
        notes.append("the table does not bound FR at the points marked 'not bounded'")
    source = "posterior draws" if fit.posterior is not None else "the fit's covariance"
    lines = [
        f"friction table fit {t.name}: bands from {source}; amplitude as a fraction of "
        f"{t.reference_amplitude_m * 1e6:g} um",
        "mean FR: at a new condition (the parameters and the model discrepancy); next: "
        "where a single new measurement there will land (plus the scatter)",
        f"{'load [N]':>9s} {'amplitude':>9s} {'speed':>8s}   {'mean FR [95%]':27s}"
        f"{'next FR [95%]':27s}reduction % [95%]",
    ]
    for (n, a, v), row in zip(grid, rows, strict=True):
        row["amplitude_fraction"] = float(a)
        fr, (lo, hi), (nlo, nhi) = row["fr"], row["fr_mean_ci95"], row["fr_next_ci95"]
        row["reduction_percent"] = 100.0 * (1.0 - fr)
        row["reduction_ci95"] = [100.0 * (1.0 - hi), 100.0 * (1.0 - lo)]
        if not row["pinned"]:
            cells = "not bounded by the table"
        else:
            cells = (
                f"{f'{fr:.4f} [{lo:.4f}, {hi:.4f}]':27s}{f'{fr:.4f} [{nlo:.4f}, {nhi:.4f}]':27s}"
                f"{100 * (1 - fr):.1f} [{100 * (1 - hi):.1f}, {100 * (1 - lo):.1f}]"
            )
        lines.append(f"{n:9g} {a:9g} {v:8g}   {cells}")
    lines += [i["statement"] for i in inverse]
    lines += [f"warning: {n}" for n in notes]
    doc = {"kind": "levels", "source": source, "predictions": rows, "warnings": notes}
    doc |= {"inverse": inverse} if inverse else {}
    print(json.dumps(doc, indent=1) if args.json else "\n".join(lines))
    return 0


# amplitude fractions searched for a target reduction on a table fit
_FRACTIONS = np.linspace(0.0025, 1.0, 400)


def _amplitude_for(fit, args: argparse.Namespace, speeds: list[float]) -> list[dict]:
    """The amplitude fraction [-] at which the mean FR reaches the target reduction,
    per load and speed, on a grid of :data:`_FRACTIONS` (linear between its points):
    the estimate where the model's FR crosses ``1 - target``, the band where the mean
    band's ends do (the band's upper end reaching it first gives the lower amplitude)."""
    target = 1.0 - args.target_reduction / 100.0
    out = []
    for n in args.load:
        for v in speeds:
            p = fit.predict(n, v, amplitude_fraction=_FRACTIONS)
            lo_band, hi_band = (np.asarray(b, float) for b in p.mean_band)

            def crossing(curve: np.ndarray) -> float:
                below = np.flatnonzero(curve <= target)
                if below.size == 0 or not np.all(np.isfinite(curve)):
                    return math.inf
                i = int(below[0])
                if i == 0:
                    return float(_FRACTIONS[0])
                a0, a1, c0, c1 = _FRACTIONS[i - 1], _FRACTIONS[i], curve[i - 1], curve[i]
                return float(a0 + (a1 - a0) * (c0 - target) / (c0 - c1))

            med, lo, hi = crossing(np.asarray(p.fr)), crossing(lo_band), crossing(hi_band)
            pinned = bool(np.all(p.pinned))
            full = (
                f"full amplitude gives {100 * (1 - float(p.fr[-1])):.1f}% (95% band "
                f"{100 * (1 - hi_band[-1]):.1f}-{100 * (1 - lo_band[-1]):.1f}%)"
            )
            what = f"{args.target_reduction:g}% reduction at {n:g} N, {v:g} m/s"
            if not pinned:  # the bands are NaN where the table does not bound FR
                full = f"full amplitude gives {100 * (1 - float(p.fr[-1])):.1f}%"
                lo = hi = math.nan
            if not math.isfinite(med):
                text = f"{what} is out of reach: {full}"
            elif not pinned:
                text = (
                    f"{what} needs amplitude {med:.3f} (no band: the table does not bound "
                    "FR at every amplitude)"
                )
            elif not math.isfinite(hi):
                text = (
                    f"{what} needs amplitude {med:.3f} (95% band {lo:.3f} to out of reach: {full})"
                )
            else:
                text = f"{what} needs amplitude {med:.3f} (95% band {lo:.3f}-{hi:.3f})"
            out.append(
                {
                    "normal_load_n": n,
                    "sliding_speed_m_s": v,
                    "target_reduction_percent": args.target_reduction,
                    "amplitude_fraction": None if not math.isfinite(med) else med,
                    "amplitude_ci95": [x if math.isfinite(x) else None for x in (lo, hi)],
                    "statement": text,
                }
            )
    return out


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
