"""Priors of the posterior (issue 5): default table, overrides from TOML or JSON.

The sampler works on an unbounded internal scale (:mod:`idtool._model._params`), the
priors are densities on the physical scale; the log-posterior adds the log-Jacobian of the
transform, so a prior means what it says whatever the transform.

Default priors (weakly informative; each is proper and confined to the physical range
the fit allows, the ``Param`` ranges of :mod:`idtool._model`):

=====================  =============================  ==========================================
parameter              default prior                  why
=====================  =============================  ==========================================
Kt [N/m]               log-uniform [1e4, 1e13]        scale parameter, unknown to decades
mu                     log-uniform [1e-3, 3]          any dry friction coefficient
coupling_gain          log-uniform [1e-5, 1]          a gain of at most 1 (no amplification)
power_load_n [N]       log-uniform [1, 1e5]           from no power limit to an extreme one
load_exponent          uniform [-2, 4]                load-power: coupling ~ N^-beta, from rising
                                                      with the load to falling steeply
drive_force_max_n [N]  log-uniform [1e-3, 1e7]        sdof: the drive, unknown to decades
loss_stiffness_n_m     log-uniform [1e3, 1e14] N/m    sdof: Q from ~1 to ~1e7 for any stack
detuning_n_m (sdof)    uniform [-1e11, 1e11] N/m      when estimated (usually fixed)
static_ratio (LuGre)   log-uniform [1, 5]             Fs >= Fc
stribeck_velocity      log-uniform [1e-4, 10] m/s     decades around the pull speed
slope_n_s [N/s]        log-uniform [1, 1e5]           actuator slopes, unknown to decades
startup_slope_n_s      log-uniform [1, 1e5]
sigma_n [N]            log-uniform [1e-6, 1e4]        noise scale (Jeffreys-like)
phi (AR(1))            uniform [-1, 1]                any stationary AR(1)
nu (Student-t)         gamma(shape 2, rate 0.1)       Juarez & Steel (2010): mean 20,
                       on [1, 1000]                   heavy tails allowed, not forced
=====================  =============================  ==========================================

Overrides: a TOML or JSON file with one table per parameter, e.g. ::

    [mu]
    dist = "normal"
    mean = 0.3
    sd = 0.1

    [Kt]
    dist = "loguniform"
    lo = 1e7
    hi = 1e11

Distributions and their fields: ``uniform`` (lo, hi), ``loguniform`` (lo, hi),
``normal`` (mean, sd), ``lognormal`` (median, sigma: sd of the natural log), ``gamma``
(shape, rate). Every prior is truncated to the parameter's physical range.
"""

from __future__ import annotations

import dataclasses
import json
import math
import os
import tomllib
from pathlib import Path

import jax.numpy as jnp

from idtool._errors import IdtoolError
from idtool._model._params import Param

__all__ = [
    "DISTRIBUTIONS",
    "Prior",
    "default_prior",
    "read_priors",
]

DISTRIBUTIONS = {
    "uniform": ("lo", "hi"),
    "loguniform": ("lo", "hi"),
    "normal": ("mean", "sd"),
    "lognormal": ("median", "sigma"),
    "gamma": ("shape", "rate"),
}


@dataclasses.dataclass(frozen=True)
class Prior:
    """A prior density on the physical scale: ``dist`` and its two numbers."""

    dist: str
    a: float
    b: float

    def __post_init__(self):
        if self.dist not in DISTRIBUTIONS:
            raise ValueError(f"unknown distribution {self.dist!r}")

    def logpdf(self, x):
        """Log density at physical ``x`` (up to a constant); -inf outside the support."""
        a, b = self.a, self.b
        if self.dist == "uniform":
            return jnp.where((x >= a) & (x <= b), -math.log(b - a), -jnp.inf)
        if self.dist == "loguniform":
            inside = (x >= a) & (x <= b)
            return jnp.where(inside, -jnp.log(x) - math.log(math.log(b / a)), -jnp.inf)
        if self.dist == "normal":
            return -0.5 * ((x - a) / b) ** 2 - math.log(b * math.sqrt(2 * math.pi))
        if self.dist == "lognormal":
            lx = jnp.log(x)
            return -0.5 * ((lx - math.log(a)) / b) ** 2 - lx - math.log(b * math.sqrt(2 * math.pi))
        # gamma(shape a, rate b)
        return (a - 1.0) * jnp.log(x) - b * x + a * math.log(b) - math.lgamma(a)

    def to_dict(self) -> dict[str, float | str]:
        k1, k2 = DISTRIBUTIONS[self.dist]
        return {"dist": self.dist, k1: self.a, k2: self.b}

    def describe(self) -> str:
        k1, k2 = DISTRIBUTIONS[self.dist]
        return f"{self.dist}({k1}={self.a:g}, {k2}={self.b:g})"


_DEFAULTS = {"phi": Prior("uniform", -1.0, 1.0), "nu": Prior("gamma", 2.0, 0.1)}


def default_prior(param: Param) -> Prior:
    """The default prior of a parameter (module docstring): log-uniform over the range
    of a positive one, uniform for phi, gamma(2, 0.1) for nu."""
    if param.name in _DEFAULTS:
        return _DEFAULTS[param.name]
    if param.kind == "log":
        return Prior("loguniform", param.lo, param.hi)
    if param.kind == "tanh":
        return Prior("uniform", param.lo, param.hi)
    return Prior("normal", param.centre, 100.0 * abs(param.scale))


def _positive_number(value, where: str) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        raise IdtoolError(f"{where}: {value!r} is not a finite number")
    return float(value)


def parse_priors(doc: dict, params: tuple[Param, ...], source: str) -> dict[str, Prior]:
    """Validate a priors document (``{name: {dist, ...}}``) against the sampled params."""
    by_name = {p.name: p for p in params}
    out: dict[str, Prior] = {}
    problems = []
    if not isinstance(doc, dict):
        raise IdtoolError(f"{source}: expected a table of parameters")
    for name, entry in doc.items():
        if name not in by_name:
            problems.append(f"unknown parameter {name!r}; sampled: {', '.join(by_name)}")
            continue
        if not isinstance(entry, dict) or entry.get("dist") not in DISTRIBUTIONS:
            problems.append(f"{name}: give dist = one of {', '.join(DISTRIBUTIONS)}")
            continue
        keys = DISTRIBUTIONS[entry["dist"]]
        extra = set(entry) - {"dist", *keys}
        missing = [k for k in keys if k not in entry]
        if missing or extra:
            problems.append(f"{name}: {entry['dist']} takes exactly {', '.join(keys)}")
            continue
        try:
            a, b = (_positive_number(entry[k], f"{name}.{k}") for k in keys)
        except IdtoolError as err:
            problems.append(str(err))
            continue
        p = by_name[name]
        bad = None
        if entry["dist"] in ("uniform", "loguniform") and not a < b:
            bad = "lo must be below hi"
        elif entry["dist"] in ("loguniform", "lognormal", "gamma") and min(a, b) <= 0:
            bad = "needs positive numbers"
        elif entry["dist"] == "normal" and b <= 0:
            bad = "sd must be positive"
        elif (
            p.kind in ("log", "tanh")
            and entry["dist"] in ("uniform", "loguniform")
            and (b <= p.lo or a >= p.hi)
        ):
            bad = f"[{a:g}, {b:g}] misses the allowed range [{p.lo:g}, {p.hi:g}]"
        if bad:
            problems.append(f"{name}: {bad}")
            continue
        out[name] = Prior(entry["dist"], a, b)
    if problems:
        raise IdtoolError(f"{source}: bad priors\n  " + "\n  ".join(problems))
    return out


def read_priors(path: str | os.PathLike, params: tuple[Param, ...]) -> dict[str, Prior]:
    """Read prior overrides from a ``.toml`` or ``.json`` file (module docstring)."""
    path = Path(path)
    try:
        text = path.read_text()
    except OSError as err:
        raise IdtoolError(f"{path}: cannot read ({err.strerror})") from None
    try:
        doc = tomllib.loads(text) if path.suffix.lower() != ".json" else json.loads(text)
    except (tomllib.TOMLDecodeError, json.JSONDecodeError) as err:
        kind = "JSON" if path.suffix.lower() == ".json" else "TOML"
        raise IdtoolError(f"{path}: not valid {kind} ({err})") from None
    return parse_priors(doc, params, str(path))
