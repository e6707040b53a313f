"""``idtool curve``: friction and power ratio against velocity ratio (notes §4).

Dimensionless: the prescribed-vibration contact with a = 1, w = 1, Fc = 1, so
``v = VR`` and ``Kt = Lambda``.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
from typing import TYPE_CHECKING

import numpy as np

from idtool._cli._args import registry_names
from idtool._errors import IdtoolError

if TYPE_CHECKING:
    from idtool._model._laws import AbstractFrictionLaw

__all__ = ["dimensionless_law", "friction_curve", "parse_number_list", "register"]


def parse_number_list(text: str, option: str) -> np.ndarray:
    """Parse ``"0.1,0.5,0.9"`` or ``"start:stop:count"`` into a float array."""
    try:
        if ":" in text:
            start, stop, count = text.split(":")
            values = np.linspace(float(start), float(stop), int(count))
        else:
            values = np.array([float(x) for x in text.split(",") if x.strip()])
    except ValueError:
        raise IdtoolError(
            f"{option} {text!r}: give numbers separated by commas (0.1,0.5,0.9) "
            "or start:stop:count (0.05:0.95:41)"
        ) from None
    if values.size == 0 or not np.all(np.isfinite(values)):
        raise IdtoolError(f"{option} {text!r}: give at least one finite number")
    return values


def dimensionless_law(
    name: str,
    lam: float,
    fs_ratio: float = 1.5,
    stribeck_vr: float = 0.1,
    s1: float = 0.0,
    s2: float = 0.0,
) -> AbstractFrictionLaw:
    """The law ``name`` with Fc = 1 and Kt = Lambda (a = w = 1).

    For LuGre: ``fs_ratio`` = Fs/Fc, ``stribeck_vr`` = Vs/(a w), ``s1`` = sigma1 w / Kt,
    ``s2`` = sigma2 a w / Fc.
    """
    # The registered law from its fit parameters, at unit load with mu = 1 (Fc = 1).
    values = {"mu": 1.0, "Kt": lam, "static_ratio": fs_ratio, "stribeck_velocity_m_s": stribeck_vr}
    # local, as in every command: JAX and the figures load only when a command needs them
    import jax.numpy as jnp

    from idtool._model._laws import FRICTION_LAWS

    law = FRICTION_LAWS.get(name).at_load({k: jnp.asarray(v) for k, v in values.items()}, 1.0)
    if s1 or s2:  # LuGre's damping terms, which the fit does not identify
        damping = {"s1_n_s_m": s1 * lam, "s2_n_s_m": s2}
        try:
            law = dataclasses.replace(law, **damping)  # type: ignore[arg-type]
        except TypeError:
            raise IdtoolError(f"--s1 and --s2 apply to LuGre, not to {name}") from None
    return law


def friction_curve(law: AbstractFrictionLaw, vr: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Friction ratio and power ratio of the dimensionless contact at each VR."""
    # local, as in every command: JAX and the figures load only when a command needs them
    import jax.numpy as jnp

    from idtool._model._contact import cycle_average_curve

    out = cycle_average_curve(law, jnp.asarray(vr))
    return np.asarray(out.friction_ratio), np.asarray(out.power_ratio)


def _run(args: argparse.Namespace) -> int:
    vr = parse_number_list(args.vr, "--vr")
    if np.any(vr <= 0):
        raise IdtoolError(f"--vr {args.vr!r}: velocity ratios must be > 0")
    if not args.lam > 0:
        raise IdtoolError(f"--lambda {args.lam}: Lambda = Kt a / Fc must be > 0")
    law = dimensionless_law(args.law, args.lam, args.fs_ratio, args.stribeck_vr, args.s1, args.s2)
    fr, pr = friction_curve(law, vr)
    if args.json:
        rows = [
            {"vr": float(v), "friction_ratio": float(f), "power_ratio": float(p)}
            for v, f, p in zip(vr, fr, pr, strict=True)
        ]
        print(json.dumps(rows, indent=1))
        return 0
    title = f"law {args.law}" + (
        "" if args.law == "coulomb" else f", Lambda = Kt a / Fc = {args.lam:g}"
    )
    print(title)
    print(f"{'VR':>8}  {'friction_ratio':>14}  {'power_ratio':>11}")
    for v, f, p in zip(vr, fr, pr, strict=True):
        print(f"{v:8.4f}  {f:14.5f}  {p:11.5f}")
    return 0


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "curve",
        help="friction and power ratio against velocity ratio (prescribed vibration)",
        description="Cycle-averaged friction ratio FR and power dissipation ratio PDR of a "
        "contact whose slip is sliding at v plus a sinusoid of amplitude a, against the "
        "velocity ratio VR = v / (a w) (model notes §3-4).",
    )
    p.add_argument(
        "--law",
        choices=registry_names("FRICTION_LAWS"),
        metavar="LAW",
        default="dahl",
        help="friction law: %(choices)s (default dahl)",
    )
    p.add_argument("--vr", default="0.1,0.3,0.5,0.7,0.9", help="0.1,0.5,0.9 or start:stop:count")
    p.add_argument(
        "--lambda", dest="lam", type=float, default=5.0, help="Lambda = Kt a / Fc (default 5)"
    )
    p.add_argument("--fs-ratio", type=float, default=1.5, help="LuGre: Fs / Fc (default 1.5)")
    p.add_argument("--stribeck-vr", type=float, default=0.1, help="LuGre: Vs / (a w) (default 0.1)")
    p.add_argument("--s1", type=float, default=0.0, help="LuGre: sigma1 w / Kt (default 0)")
    p.add_argument("--s2", type=float, default=0.0, help="LuGre: sigma2 a w / Fc (default 0)")
    p.add_argument("--json", action="store_true", help="print a JSON list instead of a table")
    p.set_defaults(func=_run)
