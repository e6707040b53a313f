"""Parameters and their transforms: one definition for the fit and the sampler.

Every parameter lives on an unbounded internal scale ``z`` of order one, which is what
Levenberg-Marquardt's damping assumes and where the walkers move:

* ``"log"``: a positive bounded parameter, ``exp(log lo + (log hi - log lo) sigmoid(z))``;
* ``"tanh"``: a bounded one of either sign, ``lo + (hi - lo) (1 + tanh z) / 2``;
* ``"linear"``: ``centre + scale z`` (per-trace nuisances, centred on their start value).

The sampler adds :meth:`Param.log_jacobian` to the log-prior, so a prior on the physical
scale means what it says whatever the transform.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from idtool._model._xp import sigmoid, softplus, xp

__all__ = ["KINDS", "Param"]

KINDS = ("log", "tanh", "linear")


@dataclasses.dataclass(frozen=True)
class Param:
    """One parameter: name, unit, transform, and what it means.

    Attributes:
        name: the name in ``fit.json``, reports and priors (``Kt``, ``mu``, ...).
        unit: SI unit ("1" for dimensionless).
        kind: the transform (module docstring).
        lo, hi: range of a ``log`` or ``tanh`` parameter, physical units.
        centre, scale: of a ``linear`` one.
        physical: a parameter of the contact or coupling (reported first, profiled,
            predicted with); otherwise a bench or noise parameter.
        start: the fit's start value when the data suggest none.
        start_box: ``(lo, hi)`` of the multi-start's log-uniform draws, or ``None`` for
            a parameter the multi-start does not vary.
        nested_at: a value at which the law that declares it (all but) reduces to a
            simpler law, where a fit of the richer law starts from the simpler law's
            optimum (a saturating coupling's load scale far above every ``alpha N``: the
            constant coupling); ``None`` starts there at ``start``.
        nested_starts: values it starts from, each in turn, in such a nested fit (the
            best end point kept), for a parameter the simpler model's optimum says
            nothing about (a time constant whose effect vanishes there); ``None``: one
            start, ``nested_at``.
        description: what it is, in words, for reports.
    """

    name: str
    unit: str
    kind: str = "log"
    lo: float = 0.0
    hi: float = 0.0
    centre: float = 0.0
    scale: float = 1.0
    physical: bool = False
    start: float = 1.0
    start_box: tuple[float, float] | None = None
    nested_at: float | None = None
    nested_starts: tuple[float, ...] | None = None
    description: str = ""

    def __post_init__(self):
        if self.kind not in KINDS:
            raise ValueError(f"Param {self.name}: kind {self.kind!r} is not one of {KINDS}")
        if self.kind != "linear" and not self.lo < self.hi:
            raise ValueError(f"Param {self.name}: lo {self.lo} must be below hi {self.hi}")
        if self.kind == "log" and self.lo <= 0.0:
            raise ValueError(f"Param {self.name}: a log parameter needs lo > 0")

    @property
    def bounded(self) -> bool:
        return self.kind != "linear"

    def value(self, z):
        """Physical value of internal ``z`` (any shape; JAX for a JAX array or tracer,
        NumPy for numbers: :mod:`idtool._model._xp`)."""
        if self.kind == "log":
            a, b = math.log(self.lo), math.log(self.hi)
            return xp(z).exp(a + (b - a) * sigmoid(z))
        if self.kind == "tanh":
            return self.lo + (self.hi - self.lo) * 0.5 * (1.0 + xp(z).tanh(z))
        return self.centre + self.scale * z

    def transform(self) -> dict[str, str | float]:
        """How :meth:`value` maps the internal ``z`` to physical units, as data and as a
        formula (for files read without idtool: ``chain.h5`` records it)."""
        out: dict[str, str | float] = {"name": self.name, "unit": self.unit, "kind": self.kind}
        if self.kind == "log":
            return out | {
                "lo": self.lo,
                "hi": self.hi,
                "value": "exp(ln(lo) + (ln(hi) - ln(lo)) / (1 + exp(-z)))",
            }
        if self.kind == "tanh":
            return out | {"lo": self.lo, "hi": self.hi, "value": "lo + (hi - lo) (1 + tanh(z)) / 2"}
        return out | {"centre": self.centre, "scale": self.scale, "value": "centre + scale z"}

    def log_jacobian(self, z):
        """``log |d value / d z|``, stable for large ``|z|`` (JAX or NumPy as
        :meth:`value`)."""
        x = xp(z)
        if self.kind == "log":
            a, b = math.log(self.lo), math.log(self.hi)
            log_s, log_1ms = -softplus(-z), -softplus(z)
            return a + (b - a) * x.exp(log_s) + math.log(b - a) + log_s + log_1ms
        if self.kind == "tanh":
            # d/dz (1 + tanh z)/2 = sech(z)^2 / 2 = 2 / (e^z + e^-z)^2
            az = x.abs(z)
            return (
                math.log(self.hi - self.lo) + math.log(2.0) - 2.0 * (az + x.log1p(x.exp(-2.0 * az)))
            )
        return math.log(abs(self.scale)) + 0.0 * x.asarray(z, float)

    def slope(self, z: float) -> float:
        """``d value / d z`` at ``z`` (NumPy float, for the delta method)."""
        return float(np.exp(self.log_jacobian(float(z))))

    def internal(self, value: float) -> float:
        """Internal ``z`` of a physical value (clipped just inside the range)."""
        if self.kind == "log":
            a, b = math.log(self.lo), math.log(self.hi)
            u = float(np.clip((math.log(value) - a) / (b - a), 1e-12, 1 - 1e-12))
            return math.log(u / (1.0 - u))
        if self.kind == "tanh":
            u = float(np.clip((value - self.lo) / (self.hi - self.lo), 1e-12, 1 - 1e-12))
            return math.atanh(2.0 * u - 1.0)
        return (value - self.centre) / self.scale
