"""Direction of vibration: the interface and the registry (issue 30, item 2).

The contact kernel needs to know how the vibration moves the contact relative to the
sliding (speed ``v`` [m/s] along x). Each direction is one module that registers a
subclass of :class:`AbstractDirection` in :data:`DIRECTIONS`
(:mod:`idtool._model._directions` imports them all, so its registry is full):

* ``along`` (:mod:`idtool._model._direction_along`, the default): the vibration is
  parallel to the sliding, slip ``u = v t + a sin(w t)`` (model notes §3-4;
  :func:`idtool.prescribed_cycle_average`, unchanged);
* ``transverse`` (:mod:`idtool._model._direction_transverse`): in the contact plane,
  perpendicular to the sliding, slip velocity ``(v, a w cos(w t))``, friction opposite
  the slip velocity (isotropic 2-D bristle model);
* ``normal`` (:mod:`idtool._model._direction_normal`): out of the plane, the
  indentation oscillates and modulates the normal force (the quasi-static
  Amontons-and-contact-stiffness model of Popov, Popov & Popov 2017).

A direction has no parameters of its own: it reads the friction law (its level Fc =
mu N, its stiffness Kt) and the slip amplitude ``a`` [m] the coupling law gives, and
returns the same :class:`~idtool._model._contact.CycleAverage` record, so the fit,
the predictions and the reports do not depend on which one it is. A coupling law in
which the contact loads the horn (``sdof``) solves its balance with the along kernel, so
it is offered with ``along`` only (:func:`idtool._model._benchmodel.bench_model`).
"""

from __future__ import annotations

import abc
from typing import ClassVar

import equinox as eqx
from jaxtyping import ArrayLike, Float

from idtool._model._contact import CycleAverage
from idtool._model._laws import AbstractFrictionLaw
from idtool._registry import Registry

__all__ = ["DIRECTIONS", "AbstractDirection"]

DIRECTIONS: Registry[type[AbstractDirection]] = Registry("direction of vibration")


class AbstractDirection(eqx.Module):
    """A direction of vibration: how the cycle-averaged contact follows from the law.

    Used as a class (static in the compiled programs, like the laws' classes); the one
    method is a classmethod. ``description`` says it in words for the reports.
    """

    name: ClassVar[str] = ""
    description: ClassVar[str] = ""

    @classmethod
    @abc.abstractmethod
    def cycle_average(
        cls,
        law: AbstractFrictionLaw,
        sliding_speed_m_s: Float[ArrayLike, ""],
        amplitude_m: Float[ArrayLike, ""],
        angular_frequency_rad_s: Float[ArrayLike, ""],
        normal_load_n: Float[ArrayLike, ""],
    ) -> CycleAverage:
        """Steady cycle averages at sliding speed ``v`` > 0 [m/s], vibration amplitude
        ``a`` >= 0 [m] (``a = 0``: FR = 1), angular frequency ``w`` > 0 [rad/s] and
        static normal load ``N0`` > 0 [N] (``law`` carries ``Fc = mu N0``; only the
        normal direction reads ``N0`` itself); scalar inputs (``jax.vmap`` for sweeps),
        jittable and differentiable."""
