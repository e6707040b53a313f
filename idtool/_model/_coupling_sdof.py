"""The seed's SDOF transducer as a coupling law (paper eqs. 6-7, notes §2).

The horn is a single-degree-of-freedom resonator driven at the bench frequency ``w`` by
``Fe = alpha Fe_max`` and loaded by the contact's friction ``F_D`` (paper eq. 6, the
contact's Fc = mu N for the pressed webbing):

    m x'' + c x' + Ks x = Fe cos(w t + psi) + F_D(t),        slip u = v t - x.

The slip amplitude is then not a law of its own: it is whatever amplitude the resonator
settles at while the friction it drives takes energy out of it. More normal load means a
larger friction force on the horn, a smaller amplitude and less friction reduction: the
loss of reduction at high load emerges from the physics instead of a fitted power law.

Harmonic balance. At 20 kHz the resonator filters the friction's higher harmonics (they
drive it far off resonance, at ``k w``, ``k >= 2``), so its motion is the fundamental
``x = -a sin(theta)``, ``theta = w t``, and the contact sees the prescribed slip of
:func:`idtool.prescribed_cycle_average` (Dahl, LuGre or Coulomb). Balancing the
fundamental with the friction's first Fourier coefficients ``Fc1, Fs1``
(:class:`idtool.CycleAverage`) gives one real equation for ``a``:

    (alpha Fe_max)^2 = (D a - Fs1(a))^2 + (R a + Fc1(a))^2,

with the resonator's impedance at ``w`` split into the detuning ``D = m (w^2 - wn^2)``
[N/m] (zero when driven at resonance; ``wn^2 = Ks / m``) and the loss stiffness
``R = c w`` [N/m] (``m wn w / Q``, about ``Ks / Q`` at resonance). Friction-free it is
the linear response ``a = alpha Fe_max / |D + i R|``. The check against the
time-domain periodic orbit of :func:`idtool.transducer_steady_state` (Newton shooting,
every harmonic kept) is in ``tests/test_coupling_sdof.py``.

Solve and derivative. Below ``a = v / w`` (VR >= 1) the slip never reverses, the
friction has no harmonic and the horn is unloaded: the amplitude is the free one if that
lies there. Above, ``g = log|...| - log(alpha Fe_max)`` is solved in
``y = sqrt(1 - VR)`` (the friction's harmonic switches on steeply as the backward slip
begins) inside the bracket ``[VR = 1, |D + iR| a = drive + 2 max|F|]``, from the free
amplitude, by a fixed count of safeguarded Newton steps (bisection where a step would
leave the bracket or stall) on a coarse phase grid and then on the full one, all
without derivatives with respect to the parameters; one last Newton step, with ``g'``
frozen, then carries the exact derivative of the root with respect to every parameter
by the implicit function theorem (as :func:`idtool.transducer_steady_state` does for
its orbit), so the fit's Jacobians are exact and ``vmap`` over operating points costs
one solve each (a fixed count keeps it one program).

Parameters: ``coupling_gain`` (the friction-free slip amplitude per commanded amplitude,
over ``A_max``, as in the kinematic laws), ``loss_stiffness_n_m`` (``R``) and
``detuning_n_m`` (``D``); the drive ``Fe_max = gain A_max |D + iR|`` (the effective
coupling from commanded amplitude to the contact) follows, and is reported with them.
The fit works on the gain rather than ``Fe_max`` because the data inform the amplitude
``a ~ alpha gain A_max - Fc1 / R`` (at resonance) through the gain and ``1 / R`` nearly
independently, where ``Fe_max`` and ``R`` came out correlated at 0.999 (one scales the
other) and Levenberg-Marquardt crawled. ``R -> inf`` at a fixed gain is the constant
law (the friction no longer loads the horn), so this law nests it like the saturating
ones.
``D`` and, where the quality factor is given, ``R`` come from the dataset's optional
``rig.transducer`` block (modal mass, natural frequency, quality factor); without it the
horn is taken as driven at resonance (``D = 0``), and a warning says so (a welder's
generator tracks the stack's resonance; ``D`` can be freed in a parameter table).
"""

from __future__ import annotations

import functools
from typing import ClassVar

import jax
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

from idtool._model._contact import CycleAverage, prescribed_cycle_average
from idtool._model._coupling import COUPLINGS, GAIN, AbstractCoupling
from idtool._model._laws import AbstractFrictionLaw
from idtool._model._params import Param
from idtool._model._settings import ParameterSetting
from idtool._model._truth_fields import TruthField

__all__ = ["SdofCoupling", "sdof_detuning_n_m", "sdof_loss_stiffness_n_m"]

# Safeguarded Newton steps (a Newton step that leaves the bracket or stalls is replaced
# by bisection) on a coarse phase grid, then on the full one from the coarse root (within
# ~1e-4 of it). Over gains 0.003-0.3, R 1e6-1e12 N/m and loads 50-1000 N (Dahl,
# D = 0.2 R), from an unloaded horn to one held just above VR = 1, 12 coarse steps and 3
# fine ones solved the balance to 5e-10 in log force everywhere, as did 24 and 8
# (tests/test_coupling_sdof.py); 16 and 3 leave a margin.
_STEPS = 16
_FINE_STEPS = 3
_COARSE_PHASE = 32

LOSS_STIFFNESS = Param(
    "loss_stiffness_n_m",
    "N/m",
    "log",
    1e3,
    1e14,
    physical=True,
    start=1e9,
    start_box=(1e7, 1e11),
    # far above any friction's pull on a bench amplitude: Fc1 / R ~ 1e-12 m
    nested_at=5e13,
    description="transducer loss stiffness R = c w at the drive frequency (Ks/Q at resonance)",
)
DETUNING = Param(
    "detuning_n_m",
    "N/m",
    "tanh",
    -1e11,
    1e11,
    physical=True,
    start=0.0,
    description="transducer detuning D = m (w^2 - wn^2) (0: driven at resonance)",
)


def sdof_detuning_n_m(
    modal_mass_kg: float, natural_frequency_hz: float, drive_frequency_hz: float
) -> float:
    """``D = m (w^2 - wn^2)`` [N/m] of a transducer of modal mass ``m`` [kg] and natural
    frequency ``fn`` [Hz] driven at ``f`` [Hz] (positive above resonance)."""
    two_pi = 2.0 * jnp.pi
    return float(
        modal_mass_kg * ((two_pi * drive_frequency_hz) ** 2 - (two_pi * natural_frequency_hz) ** 2)
    )


def sdof_loss_stiffness_n_m(
    modal_mass_kg: float,
    natural_frequency_hz: float,
    drive_frequency_hz: float,
    quality_factor: float,
) -> float:
    """``R = c w = m wn w / Q`` [N/m] (``c = m wn / Q = 2 zeta m wn``)."""
    two_pi = 2.0 * jnp.pi
    return float(
        modal_mass_kg
        * (two_pi * natural_frequency_hz)
        * (two_pi * drive_frequency_hz)
        / quality_factor
    )


@COUPLINGS.register("sdof")
class SdofCoupling(AbstractCoupling):
    """The SDOF transducer driven by ``alpha Fe_max`` and loaded by the contact's friction,
    solved by harmonic balance (module docstring).

    Attributes:
        gain: friction-free slip amplitude per commanded amplitude, over ``A_max`` [-].
        loss_stiffness_n_m: R = c w [N/m].
        detuning_n_m: D = m (w^2 - wn^2) [N/m].
    """

    gain: Float[ArrayLike, ""]
    loss_stiffness_n_m: Float[ArrayLike, ""]
    detuning_n_m: Float[ArrayLike, ""] = 0.0
    fit_params: ClassVar[tuple[Param, ...]] = (GAIN, LOSS_STIFFNESS, DETUNING)

    @classmethod
    def rig_settings(cls, vibration_frequency_hz, transducer):
        """``D`` (and ``R`` where the quality factor is given) from ``rig.transducer``;
        without it ``D = 0``, the horn driven at its resonance."""
        if transducer is None:
            return (
                ParameterSetting(
                    "detuning_n_m",
                    estimate=False,
                    nominal=0.0,
                    source="assumed: no rig.transducer in the dataset, the horn is taken "
                    "as driven at its resonance",
                ),
            )
        m, fn = transducer.modal_mass_kg, transducer.natural_frequency_hz
        source = "rig.transducer"
        out = [
            ParameterSetting(
                "detuning_n_m",
                estimate=False,
                nominal=sdof_detuning_n_m(m, fn, vibration_frequency_hz),
                source=source,
            )
        ]
        if transducer.quality_factor is not None:
            r = sdof_loss_stiffness_n_m(m, fn, vibration_frequency_hz, transducer.quality_factor)
            out.append(ParameterSetting("loss_stiffness_n_m", False, r, source=source))
        return tuple(out)

    @classmethod
    def from_values(cls, values):
        return cls(
            gain=values["coupling_gain"],
            loss_stiffness_n_m=values["loss_stiffness_n_m"],
            detuning_n_m=values["detuning_n_m"],
        )

    @classmethod
    def truth_fields(cls):
        """The drive force at full command, R and D (default 0: driven at resonance);
        the gain follows from them (:meth:`from_drive`)."""
        return (
            TruthField(
                "drive_force_max_n",
                "N",
                "drive force amplitude Fe_max on the transducer at 100% command",
            ),
            TruthField.of(LOSS_STIFFNESS),
            TruthField.of(DETUNING, default=0.0),
        )

    @classmethod
    def from_truth(cls, values, max_amplitude_m):
        return cls.from_drive(
            values["drive_force_max_n"],
            values["loss_stiffness_n_m"],
            values.get("detuning_n_m", 0.0),
            max_amplitude_m,
        )

    @classmethod
    def from_drive(
        cls,
        drive_force_max_n: float,
        loss_stiffness_n_m: float,
        detuning_n_m: float = 0.0,
        max_amplitude_m: float = 85e-6,
    ) -> SdofCoupling:
        """The law of a drive ``Fe_max`` [N] on a horn of maximum amplitude ``A_max``
        [m]: ``gain = Fe_max / (A_max |D + iR|)``."""
        impedance = float(jnp.hypot(detuning_n_m, loss_stiffness_n_m))
        gain = drive_force_max_n / (max_amplitude_m * impedance)
        return cls(gain=gain, loss_stiffness_n_m=loss_stiffness_n_m, detuning_n_m=detuning_n_m)

    def derived(self, max_amplitude_m):
        return {
            "drive_force_max_n": (
                self.drive_force_max_n(max_amplitude_m),
                "N",
                "drive force amplitude at 100% command, Fe_max = gain A_max |D + iR|",
            )
        }

    def drive_force_max_n(self, max_amplitude_m: Float[ArrayLike, ""]) -> Float[Array, ""]:
        """``Fe_max = gain A_max |D + iR|`` [N], the drive at 100% command."""
        impedance = jnp.hypot(self.detuning_n_m, self.loss_stiffness_n_m)
        return jnp.asarray(self.gain * max_amplitude_m * impedance)

    def amplitude_m(self, amplitude_fraction, normal_load_n, max_amplitude_m):
        """The friction-free amplitude ``alpha gain A_max = alpha Fe_max / |D + i R|``
        [m] (the loaded one is :meth:`slip_amplitude_m`)."""
        alpha = jnp.asarray(amplitude_fraction)
        shape = jnp.broadcast_shapes(alpha.shape, jnp.shape(normal_load_n))
        return jnp.broadcast_to(self.gain * alpha * max_amplitude_m, shape)

    def drive_fraction(
        self,
        law: AbstractFrictionLaw,
        slip_amplitude_m: Float[ArrayLike, ""],
        cycle: CycleAverage,
        normal_load_n: Float[ArrayLike, ""],
        angular_frequency_rad_s: Float[ArrayLike, ""],
        max_amplitude_m: Float[ArrayLike, ""],
    ) -> Float[Array, ""]:
        """The command that holds the horn at slip amplitude ``a``, in closed form: the
        balance read the other way, ``alpha = |(D a - Fs1) + i (R a + Fc1)| / Fe_max``
        (module docstring), ``cycle`` the contact's harmonics at ``a``."""
        del law, normal_load_n, angular_frequency_rad_s
        a = jnp.asarray(slip_amplitude_m)
        force = jnp.hypot(
            self.detuning_n_m * a - cycle.harmonic_sin_n,
            self.loss_stiffness_n_m * a + cycle.harmonic_cos_n,
        )
        return force / self.drive_force_max_n(max_amplitude_m)

    def slip_amplitude_m(
        self,
        law: AbstractFrictionLaw,
        amplitude_fraction: Float[ArrayLike, ""],
        normal_load_n: Float[ArrayLike, ""],
        sliding_speed_m_s: Float[ArrayLike, ""],
        angular_frequency_rad_s: Float[ArrayLike, ""],
        max_amplitude_m: Float[ArrayLike, ""],
    ) -> Float[Array, ""]:
        """The amplitude ``a`` [m] of the loaded resonator (harmonic balance, module
        docstring); scalar operating point."""
        driven = jnp.asarray(amplitude_fraction) > 0.0
        alpha = jnp.where(driven, jnp.asarray(amplitude_fraction), 1.0)
        drive = alpha * self.drive_force_max_n(max_amplitude_m)
        d, r = self.detuning_n_m, self.loss_stiffness_n_m
        # Below a = v / w (VR >= 1) the slip never reverses, the friction has no
        # harmonic and the horn is unloaded: a is the free amplitude if that lies there.
        # Above it the balance is solved in y = sqrt(1 - VR), a = (v / w) / (1 - y^2):
        # where the backward slip begins (VR -> 1) the friction's harmonic grows as
        # sqrt(1 - VR), a square-root kink in a that y straightens out, so Newton does
        # not overshoot across it.
        kink = jnp.asarray(sliding_speed_m_s) / jnp.asarray(angular_frequency_rad_s)

        def residual(y, law, drive, d, r, n_phase=256):
            a = kink / (1.0 - y**2)
            c = prescribed_cycle_average(
                law, sliding_speed_m_s, a, angular_frequency_rad_s, n_phase=n_phase
            )
            # on a log scale: of order one whatever the units
            force = jnp.hypot(d * a - c.harmonic_sin_n, r * a + c.harmonic_cos_n)
            return jnp.log(force) - jnp.log(drive)

        args = (law, drive, d, r)
        frozen = jax.lax.stop_gradient(args)
        free = frozen[1] / jnp.hypot(frozen[2], frozen[3])
        loaded = free > kink

        def value_and_slope(y, n_phase=256):  # forward mode: one scalar direction
            return jax.jvp(lambda u: residual(u, *frozen, n_phase=n_phase), (y,), (1.0,))

        def safeguarded(n_phase, state):
            # Numerical Recipes' rtsafe: Newton, unless its step would leave the bracket
            # or would not halve the step before last, then bisection
            y, lo, hi, dy_old, done = state
            g, slope = value_and_slope(y, n_phase)
            lo, hi = jnp.where(g > 0.0, lo, y), jnp.where(g > 0.0, y, hi)
            newton = y - g / slope
            bad = (
                ~jnp.isfinite(newton)
                | (newton < lo)
                | (newton > hi)
                | (jnp.abs(2.0 * g) > jnp.abs(dy_old * slope))
            )
            step = jnp.where(bad, 0.5 * (lo + hi), newton)
            # converged: stay there for good. Round-off leaves |g| ~ 3e-13 (a relative
            # error of 3e-13 in the force balance); a step that cannot halve that would
            # otherwise pass for a stalled Newton step, whose bisection leaves the root
            done = done | (jnp.abs(g) < 1e-11)
            step = jnp.where(done, y, step)
            return step, lo, hi, jnp.where(bad, 0.5 * (hi - lo), g / slope), done

        # Bracket: g < 0 at the kink (y = 0: unloaded, a below the free amplitude); g > 0
        # once |D + iR| a exceeds the drive by 2 max|F| >= |F1| (max|F|: the level for
        # Dahl and Coulomb; LuGre's static peak is at most 5x it, and its viscous terms
        # only add to R). Start at the free amplitude.
        force_bound = 2.0 * 5.0 * jnp.abs(jax.lax.stop_gradient(law.level_n(sliding_speed_m_s)))
        a_hi = (frozen[1] + force_bound) / jnp.hypot(frozen[2], frozen[3])

        def y_of(a):
            return jnp.sqrt(jnp.clip(1.0 - kink / a, 0.0, 1.0 - 1e-15))

        y_hi = y_of(jnp.maximum(a_hi, kink))
        start = (y_of(free), 0.0, y_hi, y_hi, False)
        y = _iterate(functools.partial(safeguarded, _COARSE_PHASE), _STEPS, start)
        # the full grid's root is within ~1e-4 of the coarse one: Newton from there,
        # safeguarded in the whole bracket (the coarse one need not hold the fine root)
        y = _iterate(functools.partial(safeguarded, 256), _FINE_STEPS, (y, 0.0, y_hi, y_hi, False))
        _, slope = value_and_slope(y)
        y = y - residual(y, *args) / slope  # the implicit derivative (module docstring)
        a = jnp.where(loaded, kink / (1.0 - y**2), self.amplitude_m(alpha, 0.0, max_amplitude_m))
        return jnp.where(driven, a, 0.0)


def _iterate(step, max_steps: int, state: tuple) -> Array:
    """``y`` (the state's first entry) after at most ``max_steps`` safeguarded Newton
    steps, stopping once the state says done (its last entry): a converged ``y`` stays
    put, so stopping there gives the ``y`` the full budget gives, bit for bit, without
    the steps after convergence (under ``vmap``, until every operating point is done).
    Its start does not depend on the parameters (``stop_gradient``): nothing is
    differentiated through the loop, the derivative is the implicit one after it."""

    def more(carry):
        i, s = carry
        return (i < max_steps) & ~s[-1]

    _, out = jax.lax.while_loop(more, lambda c: (c[0] + 1, step(c[1])), (0, state))
    return out[0]
