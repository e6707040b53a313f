"""Friction laws: Coulomb, Dahl and LuGre (model notes §1, paper eqs. 1-5).

Every law is written on the *bristle force* ``fb = Kt z`` [N] (Kt the tangential
contact stiffness [N/m], z the mean bristle deflection [m]). Along a stretch of slip
``du`` [m] of constant sign ``s`` and at slip velocity ``V`` [m/s], the bristle
equation ``dz/dt = V - |V| z / g(V)`` becomes, with ``L(V) = Kt g(V)``,

    d fb / du = Kt (1 - s fb / L(V)),

which is linear in ``fb``. For a level ``L`` held constant over the stretch it has the
exact solution (model notes §4)

    fb <- s L + (fb - s L) exp(-Kt |du| / L),

an affine map ``fb -> A fb + B`` that is exact for Dahl (``L = Fc``) whatever the size
of ``du``; the rigid Coulomb limit is ``A = 0``. The contact solvers compose these
maps, so no law needs a small time step near the sign switch of V.

The friction force is ``F = fb + s1 dz/dt + s2 V`` with ``dz/dt = V (1 - s fb / L)``
(paper eq. 3).
"""

from __future__ import annotations

import abc
from collections.abc import Mapping
from typing import ClassVar

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

from idtool._model._params import Param
from idtool._model._truth_fields import TruthField
from idtool._registry import Registry

__all__ = [
    "FRICTION_LAWS",
    "KT",
    "MU",
    "TRUTH_NAMES",
    "AbstractFrictionLaw",
    "Coulomb",
    "Dahl",
    "LuGre",
]

FRICTION_LAWS: Registry[type[AbstractFrictionLaw]] = Registry("friction law")

# The parameters the fit identifies. mu sets every law's level (Fc = mu N) and the OFF
# force, so the bench model owns it; each law declares the rest (``fit_params``).
MU = Param(
    "mu",
    "1",
    "log",
    1e-3,
    3.0,
    physical=True,
    start=0.3,
    description="friction coefficient: OFF level mu N",
)
KT = Param(
    "Kt",
    "N/m",
    "log",
    1e4,
    1e13,
    physical=True,
    start=1e8,
    start_box=(1e6, 1e11),
    description="tangential contact (bristle) stiffness",
)
# The simulator's parameter file names mu and Kt as it did before the registries.
TRUTH_NAMES = {"mu": "friction_coefficient", "Kt": "contact_stiffness_n_m"}


class AbstractFrictionLaw(eqx.Module):
    """A rate-independent-in-form friction law on the bristle force ``fb`` [N]."""

    fc_n: eqx.AbstractVar[Float[ArrayLike, ""]]
    # True when the level L does not depend on V (Coulomb, Dahl): the slip update is
    # then exact over any stretch of one sign, which lets the contact solver write the
    # whole cycle in closed form instead of composing step maps in sequence.
    constant_level: ClassVar[bool] = True
    # Registered name, and the parameters a fit identifies beyond mu (in this order).
    name: ClassVar[str] = ""
    fit_params: ClassVar[tuple[Param, ...]] = ()

    @classmethod
    @abc.abstractmethod
    def at_load(
        cls, values: Mapping[str, ArrayLike], normal_load_n: Float[ArrayLike, "*b"]
    ) -> AbstractFrictionLaw:
        """The law of the contact under ``normal_load_n`` [N], from parameter values by
        name (``mu`` and this law's ``fit_params``): ``Fc = mu N`` (notes §5)."""

    @classmethod
    def truth_fields(cls) -> tuple[TruthField, ...]:
        """The law's numbers in the simulator's parameter file: mu and its
        ``fit_params``, mu and Kt under their :data:`TRUTH_NAMES`."""
        return tuple(TruthField.of(p, TRUTH_NAMES.get(p.name)) for p in (MU, *cls.fit_params))

    @classmethod
    def truth_at_load(
        cls, values: Mapping[str, ArrayLike], normal_load_n: Float[ArrayLike, "*b"]
    ) -> AbstractFrictionLaw:
        """:meth:`at_load` from the values of :meth:`truth_fields` by their file names."""
        back = {v: k for k, v in TRUTH_NAMES.items()}
        return cls.at_load({back.get(k, k): v for k, v in values.items()}, normal_load_n)

    def level_n(self, v_m_s: Float[ArrayLike, "*b"]) -> Float[Array, "*b"]:
        """Steady bristle force ``L(V) = Kt g(V)`` [N] at slip velocity V [m/s] (eq. 2).

        Constant ``Fc`` for Coulomb and Dahl; LuGre adds the Stribeck curve.
        """
        return jnp.broadcast_to(jnp.asarray(self.fc_n, float), jnp.shape(v_m_s))

    @abc.abstractmethod
    def stiffness_n_m(self) -> Float[Array, ""]:
        """Tangential contact stiffness Kt [N/m] (infinite for Coulomb)."""

    def decay_exponent(
        self, du_abs_m: Float[ArrayLike, "*b"], level_n: Float[ArrayLike, "*b"]
    ) -> Float[Array, "*b"]:
        """Exponent ``kappa = Kt |du| / L``: ``fb - s L`` shrinks by ``exp(-kappa)`` over |du|."""
        return self.stiffness_n_m() * jnp.asarray(du_abs_m) / jnp.asarray(level_n)

    def bristle_damping_n_s_m(self) -> Float[Array, ""]:
        """Bristle damping s1 [N s/m]; zero unless the law is LuGre."""
        return jnp.zeros(())

    def viscous_n_s_m(self) -> Float[Array, ""]:
        """Viscous coefficient s2 [N s/m]; zero unless the law is LuGre."""
        return jnp.zeros(())

    def off_force_n(self, v_m_s: Float[ArrayLike, "*b"]) -> Float[Array, "*b"]:
        """Friction force [N] in steady sliding at constant speed ``v_m_s`` > 0."""
        v = jnp.asarray(v_m_s)
        return self.level_n(v) + self.viscous_n_s_m() * v


@FRICTION_LAWS.register("coulomb")
class Coulomb(AbstractFrictionLaw):
    """Coulomb friction ``F = Fc sgn(V)``: the rigid limit Kt -> infinity (notes §1)."""

    fc_n: Float[ArrayLike, ""]

    @classmethod
    def at_load(cls, values, normal_load_n):
        return cls(fc_n=values["mu"] * normal_load_n)

    def stiffness_n_m(self):
        return jnp.asarray(jnp.inf)

    def decay_exponent(self, du_abs_m, level_n):
        # inf * 0 is nan; the rigid law forgets its state over any slip, even none.
        return jnp.full(jnp.broadcast_shapes(jnp.shape(du_abs_m), jnp.shape(level_n)), jnp.inf)


@FRICTION_LAWS.register("dahl")
class Dahl(AbstractFrictionLaw):
    """Dahl friction ``dF/dt = Kt V (1 - sgn(V) F / Fc)`` (paper eq. 5, notes §1).

    Attributes:
        fc_n: Coulomb level Fc [N] (``mu * normal load``).
        kt_n_m: tangential contact (bristle) stiffness Kt [N/m].
    """

    fc_n: Float[ArrayLike, ""]
    kt_n_m: Float[ArrayLike, ""]
    fit_params: ClassVar[tuple[Param, ...]] = (KT,)

    @classmethod
    def at_load(cls, values, normal_load_n):
        return cls(fc_n=values["mu"] * normal_load_n, kt_n_m=values["Kt"])

    def stiffness_n_m(self):
        return jnp.asarray(self.kt_n_m, float)


@FRICTION_LAWS.register("lugre")
class LuGre(AbstractFrictionLaw):
    """LuGre friction in full (paper eqs. 1-3, notes §1).

    ``dz/dt = V - |V| z / g(V)``, ``g(V) = (Fc + (Fs - Fc) exp(-(V/Vs)^2)) / Kt``,
    ``F = Kt z + s1 dz/dt + s2 V``. With ``s1 = s2 = 0`` and ``Fs = Fc`` it is Dahl.

    Fields come in the order of the abstract base (``fc_n`` first); pass them by name.

    Attributes:
        fc_n: Coulomb (kinetic) level Fc [N].
        kt_n_m: bristle stiffness Kt (sigma0) [N/m].
        fs_n: static level Fs [N].
        vs_m_s: Stribeck velocity Vs [m/s].
        s1_n_s_m: bristle damping sigma1 [N s/m].
        s2_n_s_m: viscous coefficient sigma2 [N s/m].
    """

    fc_n: Float[ArrayLike, ""]
    kt_n_m: Float[ArrayLike, ""]
    fs_n: Float[ArrayLike, ""]
    vs_m_s: Float[ArrayLike, ""]
    s1_n_s_m: Float[ArrayLike, ""] = 0.0
    s2_n_s_m: Float[ArrayLike, ""] = 0.0
    constant_level: ClassVar[bool] = False
    # The fit identifies the Stribeck curve; the damping terms stay zero: on block means
    # of a 20 kHz contact they are not identifiable apart from the level.
    fit_params: ClassVar[tuple[Param, ...]] = (
        KT,
        Param(
            "static_ratio",
            "1",
            "log",
            1.0,
            5.0,
            physical=True,
            start=1.2,
            start_box=(1.0, 2.0),
            description="static over kinetic level Fs/Fc",
        ),
        Param(
            "stribeck_velocity_m_s",
            "m/s",
            "log",
            1e-4,
            10.0,
            physical=True,
            start=0.01,
            start_box=(1e-3, 0.1),
            description="Stribeck velocity Vs",
        ),
    )

    @classmethod
    def at_load(cls, values, normal_load_n):
        fc = values["mu"] * normal_load_n
        return cls(
            fc_n=fc,
            kt_n_m=values["Kt"],
            fs_n=values["static_ratio"] * fc,
            vs_m_s=values["stribeck_velocity_m_s"],
        )

    def level_n(self, v_m_s):
        v = jnp.asarray(v_m_s)
        fc, fs = jnp.asarray(self.fc_n), jnp.asarray(self.fs_n)
        return fc + (fs - fc) * jnp.exp(-((v / self.vs_m_s) ** 2))

    def stiffness_n_m(self):
        return jnp.asarray(self.kt_n_m, float)

    def bristle_damping_n_s_m(self):
        return jnp.asarray(self.s1_n_s_m, float)

    def viscous_n_s_m(self):
        return jnp.asarray(self.s2_n_s_m, float)
