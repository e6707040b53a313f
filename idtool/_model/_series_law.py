"""A registered friction law's parameters on a velocity-force series (``idtool fit-law``).

A law of :data:`idtool._model._laws.FRICTION_LAWS` names the parameters a bench fit
identifies (``mu`` and its ``fit_params``). On a series of slip velocity and friction
force the law's every term is seen, so a series law adds:

* the level: ``mu`` when the series has a normal load (``Fc = mu N``), else ``Fc`` [N]
  itself (the law is then built at a load of 1 N, so ``mu`` carries Fc in newtons);
* ``sigma1`` [N s/m], the bristle damping, for a law with a field ``s1_n_s_m`` (LuGre);
* ``sigma2`` [N s/m], the viscous coefficient, for a law with a field ``s2_n_s_m``
  (LuGre), or as an extra term ``sigma2 V`` for a name ending in ``-viscous``
  (``coulomb-viscous``: ``F = Fc sgn(V) + sigma2 V``).

Their ranges scale with the series (its force and velocity scales, :func:`scale_of`),
as a lab rig's ``sigma1`` may be 1e-2 or 1e4 N s/m. Any other registered law works by
its registration alone: its ``fit_params`` and ``at_load`` are used as they are.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping

import equinox as eqx
from jaxtyping import ArrayLike

from idtool._errors import IdtoolError
from idtool._model._laws import FRICTION_LAWS, MU, AbstractFrictionLaw
from idtool._model._params import Param

__all__ = [
    "FC",
    "SIGMA1",
    "SIGMA2",
    "VISCOUS_SUFFIX",
    "SeriesLaw",
    "scale_of",
    "scaled",
    "series_law",
    "series_law_names",
]

VISCOUS_SUFFIX = "-viscous"


def series_law_names() -> tuple[str, ...]:
    """The laws ``fit-law`` takes: every registered law, and each with ``-viscous``."""
    names = list(FRICTION_LAWS.names())
    return tuple(names + [n + VISCOUS_SUFFIX for n in names if not _has(n, "s2_n_s_m")])


def _has(name: str, field: str) -> bool:
    cls = FRICTION_LAWS.get(name)
    return field in {f.name for f in dataclasses.fields(cls)}


@dataclasses.dataclass(frozen=True)
class SeriesLaw:
    """A friction law and its parameters on a series.

    Attributes:
        name: as given (``lugre``, ``dahl``, ``coulomb-viscous``, ...).
        law: the registered law class.
        params: the parameters in the fit's order (level, the law's, sigma1, sigma2).
        with_load: True when the level is ``mu`` (the series has a normal load).
        extra_viscous: True when ``sigma2`` is the extra term of a ``-viscous`` name.
    """

    name: str
    law: type[AbstractFrictionLaw]
    params: tuple[Param, ...]
    with_load: bool
    extra_viscous: bool

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(p.name for p in self.params)

    def law_values(self, values: Mapping[str, ArrayLike]) -> dict[str, ArrayLike]:
        """The values ``at_load`` reads (``Fc`` passed as ``mu`` at a load of 1 N)."""
        out = dict(values)
        if not self.with_load:
            out["mu"] = out.pop("Fc")
        return out

    def law_at(self, values: Mapping[str, ArrayLike], normal_load_n) -> AbstractFrictionLaw:
        """The law at ``normal_load_n`` [N] (1 N without a load), damping and viscous
        fields set from ``sigma1``/``sigma2`` where the law has them."""
        law = self.law.at_load(self.law_values(values), normal_load_n)
        if "sigma1" in values and hasattr(law, "s1_n_s_m"):
            law = eqx.tree_at(lambda lw: lw.s1_n_s_m, law, values["sigma1"])
        if "sigma2" in values and not self.extra_viscous and hasattr(law, "s2_n_s_m"):
            law = eqx.tree_at(lambda lw: lw.s2_n_s_m, law, values["sigma2"])
        return law

    def extra_viscous_n_s_m(self, values: Mapping[str, ArrayLike]):
        """``c_v`` of :func:`idtool._model._series_force.series_force` [N s/m]."""
        return values["sigma2"] if self.extra_viscous else 0.0


def series_law(name: str, *, with_load: bool) -> SeriesLaw:
    """The :class:`SeriesLaw` called ``name``.

    ``Fc``, ``sigma1`` and ``sigma2`` are declared on the series' scales (``Fc`` in units
    of its force scale, the sigmas in force scale over velocity scale: :func:`scale_of`),
    so their ranges suit any rig, and one compiled fit serves every series of a length.
    """
    base = name.removesuffix(VISCOUS_SUFFIX)
    extra = name != base
    if base not in FRICTION_LAWS or (extra and _has(base, "s2_n_s_m")):
        raise IdtoolError(f"unknown law {name!r}: choose one of {', '.join(series_law_names())}")
    cls = FRICTION_LAWS.get(base)
    params = [MU if with_load else FC, *cls.fit_params]
    if _has(base, "s1_n_s_m"):
        params.append(SIGMA1)
    if extra or _has(base, "s2_n_s_m"):
        params.append(SIGMA2)
    return SeriesLaw(name, cls, tuple(params), with_load, extra)


def scale_of(name: str, force_scale_n: float, velocity_scale_m_s: float) -> float:
    """The factor from a parameter's declared value to its value in SI units on a series
    whose force and velocity reach about ``force_scale_n`` and ``velocity_scale_m_s``."""
    if name in ("Fc", "offset_n", "drift_n"):
        return force_scale_n
    if name in ("sigma1", "sigma2"):
        return force_scale_n / velocity_scale_m_s
    return 1.0


def scaled(param: Param, factor: float) -> Param:
    """``param`` in SI units: its range and start multiplied by ``factor``."""
    if factor == 1.0:
        return param
    return dataclasses.replace(
        param, lo=param.lo * factor, hi=param.hi * factor, start=param.start * factor,
        centre=param.centre * factor, scale=param.scale * factor,
    )  # fmt: skip


# Declared on the series' scales (scale_of): Fc over the force scale, the sigmas over
# force scale / velocity scale.
FC = Param(
    "Fc",
    "N",
    "log",
    1e-3,
    1e2,
    physical=True,
    start=0.5,
    description="Coulomb (kinetic) level Fc",
)
SIGMA1 = Param(
    "sigma1",
    "N s/m",
    "log",
    1e-5,
    1e3,
    physical=True,
    start=1e-2,
    description="bristle damping sigma1",
)
SIGMA2 = Param(
    "sigma2",
    "N s/m",
    "log",
    1e-5,
    1e2,
    physical=True,
    start=1e-2,
    description="viscous coefficient sigma2",
)
