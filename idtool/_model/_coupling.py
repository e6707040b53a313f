"""Coupling laws: commanded horn amplitude -> effective contact slip amplitude (notes §5).

The bench vibrates the webbing normal to the sliding, while the contact model
(:func:`idtool.prescribed_cycle_average`) needs a slip amplitude along it. The link is
an effective coupling to identify from the traces. This module holds the interface
(:class:`AbstractCoupling`) and the registry (:data:`COUPLINGS`); each law is one module
that registers itself:

* ``constant`` (:mod:`idtool._model._coupling_constant`): ``a = gain * alpha * A_max``;
* ``power-limited`` (:mod:`idtool._model._coupling_power_limited`):
  ``a = gain * alpha * A_max / sqrt(1 + (alpha N / P)^2)``;
* ``exponential`` (:mod:`idtool._model._coupling_exponential`):
  ``a = gain * A_max * (P / N) * (1 - exp(-alpha N / P))``;
* ``sdof`` (:mod:`idtool._model._coupling_sdof`): the seed's transducer (paper eqs. 6-7)
  driven by ``alpha Fe_max`` and loaded by the contact's friction, solved by harmonic
  balance: the amplitude follows from the physics, not from a fitted shape.

The two saturating laws are the constant one at small ``alpha N`` and saturate at
``gain * A_max * P / N`` at large ``alpha N`` (the welder's power limits the effect;
50% and 70% amplitude differ little at 450 N in the paper), the power limit through an
algebraic knee, the exponential one through a softer one; ``P -> inf`` recovers the
constant law, so each nests it. ``alpha`` is the commanded amplitude fraction in
[0, 1], ``A_max`` the horn's maximum amplitude [m], ``N`` the normal load [N].
"""

from __future__ import annotations

import abc
from collections.abc import Mapping
from typing import ClassVar

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

from idtool._data._dataset import TransducerSpec
from idtool._model._contact import CycleAverage
from idtool._model._laws import AbstractFrictionLaw
from idtool._model._params import Param
from idtool._model._settings import ParameterSetting
from idtool._model._truth_fields import TruthField
from idtool._registry import Registry

__all__ = [
    "COUPLINGS",
    "GAIN",
    "AbstractCoupling",
    "ConstantCoupling",
    "ExponentialCoupling",
    "LoadPowerCoupling",
    "PowerLimitedCoupling",
    "SdofCoupling",
    "load_scale_param",
    "reacts_on_vibration",
]

COUPLINGS: Registry[type[AbstractCoupling]] = Registry("coupling law")

GAIN: Param = Param(
    "coupling_gain",
    "1",
    "log",
    1e-5,
    1.0,
    physical=True,
    start=0.01,
    description="slip amplitude per commanded horn amplitude (small-signal)",
)


class AbstractCoupling(eqx.Module):
    """Maps an operating point to the effective slip amplitude [m].

    Every law declares its parameters in ``fit_params``; the one named by ``gain_param``
    (``coupling_gain`` unless the law says otherwise) scales the friction-free amplitude
    :meth:`amplitude_m` in proportion, which is how the fit places its start (through a
    velocity ratio below 1, see :func:`idtool._fit._fit._start_point`). A law in which
    the contact reacts on the vibration (``sdof``) also overrides
    :meth:`slip_amplitude_m`.
    """

    name: ClassVar[str] = ""
    fit_params: ClassVar[tuple[Param, ...]] = (GAIN,)
    gain_param: ClassVar[str] = "coupling_gain"

    def derived(self, max_amplitude_m: Float[ArrayLike, ""]) -> dict[str, tuple[Array, str, str]]:
        """Quantities that follow from the parameters, reported with them: name ->
        (value, unit, what it is). None for the kinematic laws."""
        del max_amplitude_m
        return {}

    @classmethod
    def rig_settings(
        cls, vibration_frequency_hz: float, transducer: TransducerSpec | None
    ) -> tuple[ParameterSetting, ...]:
        """The parameters the rig's data fix for this law (the user's settings win):
        none, unless the law models the transducer."""
        del vibration_frequency_hz, transducer
        return ()

    @classmethod
    @abc.abstractmethod
    def from_values(cls, values: Mapping[str, ArrayLike]) -> AbstractCoupling:
        """The law from parameter values by name (its ``fit_params``)."""

    @classmethod
    def truth_fields(cls) -> tuple[TruthField, ...]:
        """The law's numbers in the simulator's parameter file: its ``fit_params``, the
        one named by ``gain_param`` as ``gain``. A law whose simulation is set by other
        numbers (``sdof``: its drive force) overrides this and :meth:`from_truth`."""
        return tuple(
            TruthField.of(p, "gain" if p.name == cls.gain_param else None) for p in cls.fit_params
        )

    @classmethod
    def from_truth(cls, values: Mapping[str, float], max_amplitude_m: float) -> AbstractCoupling:
        """The law from the values of :meth:`truth_fields` by their file names;
        ``max_amplitude_m`` [m], the rig's horn amplitude at 100% command."""
        del max_amplitude_m
        return cls.from_values(
            {(cls.gain_param if k == "gain" else k): v for k, v in values.items()}
        )

    @abc.abstractmethod
    def amplitude_m(
        self,
        amplitude_fraction: Float[ArrayLike, "*b"],
        normal_load_n: Float[ArrayLike, "*b"],
        max_amplitude_m: Float[ArrayLike, ""],
    ) -> Float[Array, "*b"]:
        """Effective slip amplitude [m] seen by the contact model, before the contact
        reacts on the vibration (for a kinematic law, the amplitude itself)."""

    def slip_amplitude_m(
        self,
        law: AbstractFrictionLaw,
        amplitude_fraction: Float[ArrayLike, ""],
        normal_load_n: Float[ArrayLike, ""],
        sliding_speed_m_s: Float[ArrayLike, ""],
        angular_frequency_rad_s: Float[ArrayLike, ""],
        max_amplitude_m: Float[ArrayLike, ""],
    ) -> Float[Array, ""]:
        """The slip amplitude [m] at one operating point with the contact ``law`` (its
        ``Fc = mu N`` for this load) in place: :meth:`amplitude_m` unless the law models
        the contact's reaction."""
        del law, sliding_speed_m_s, angular_frequency_rad_s
        return self.amplitude_m(amplitude_fraction, normal_load_n, max_amplitude_m)

    def drive_fraction(
        self,
        law: AbstractFrictionLaw,
        slip_amplitude_m: Float[ArrayLike, ""],
        cycle: CycleAverage,
        normal_load_n: Float[ArrayLike, ""],
        angular_frequency_rad_s: Float[ArrayLike, ""],
        max_amplitude_m: Float[ArrayLike, ""],
    ) -> Float[Array, ""]:
        """The inverse of :meth:`slip_amplitude_m`: the commanded amplitude fraction in
        [0, 1] at which the slip amplitude is ``slip_amplitude_m`` [m] (at most the one
        of full command), ``cycle`` the contact's cycle average at that amplitude (a law
        in which the contact loads the horn reads its harmonics). This default bisects
        the friction-free amplitude (monotone in the command for every shipped
        kinematic law; 2^-52 resolution, a few flops a step); a loaded law overrides it
        (the inverse prediction, :mod:`idtool._predict._amplitude`, searches the slip
        amplitude and calls this once a step)."""
        del law, cycle, angular_frequency_rad_s
        target = jnp.asarray(slip_amplitude_m)

        def step(_, bounds):
            lo, hi = bounds
            mid = 0.5 * (lo + hi)
            below = self.amplitude_m(mid, normal_load_n, max_amplitude_m) < target
            return jnp.where(below, mid, lo), jnp.where(below, hi, mid)

        lo, hi = jax.lax.fori_loop(0, 52, step, (jnp.asarray(0.0), jnp.asarray(1.0)))
        return 0.5 * (lo + hi)


def reacts_on_vibration(coupling: type[AbstractCoupling]) -> bool:
    """Whether the contact loads the vibration in ``coupling``: it overrides
    :meth:`AbstractCoupling.slip_amplitude_m` (``sdof``, whose balance reads the along
    kernel's harmonics, so it goes with vibration along the sliding only)."""
    return coupling.slip_amplitude_m is not AbstractCoupling.slip_amplitude_m


def load_scale_param(name: str, description: str, hi: float = 1e5) -> Param:
    """The load scale ``P`` [N] of a saturating law, from 1 N to ``hi`` (same multi-start
    box for every law, so that their fits start alike). A fit nested in the constant
    law starts at ``P = hi / 2``, where ``x = alpha N / P`` is below ``2000 / hi`` on any
    bench (loads below 1 kN): the power limit deviates from the constant law by
    ``x^2 / 2`` (2e-4 at ``hi = 1e5``), the exponential saturation by ``x / 2`` (it
    takes ``hi = 1e7`` for 1e-4), a start in the constant law's basin."""
    return Param(
        name,
        "N",
        "log",
        1.0,
        hi,
        physical=True,
        start=300.0,
        start_box=(20.0, 2000.0),
        nested_at=hi / 2.0,
        description=description,
    )


# The laws register themselves on import, the registry listing them in import order
# (the constant law first: the simplest). Imported last: each imports the interface.
from idtool._model._coupling_constant import ConstantCoupling  # noqa: E402
from idtool._model._coupling_exponential import ExponentialCoupling  # noqa: E402
from idtool._model._coupling_load_power import LoadPowerCoupling  # noqa: E402
from idtool._model._coupling_power_limited import PowerLimitedCoupling  # noqa: E402
from idtool._model._coupling_sdof import SdofCoupling  # noqa: E402
