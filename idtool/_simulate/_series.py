"""Simulated velocity-force series, for tests, benchmarks and the docs of ``fit-law``.

The slip is prescribed, ``x(t) = A (1 - cos(w t))`` [m] (at rest at t = 0, bristles
relaxed), ``V = A w sin(w t)``:

* ``"presliding"``: an amplitude A of a fraction of the presliding length Fc / Kt, so
  the contact sticks and traces the bristles' hysteresis loop;
* ``"sliding"``: an amplitude of many presliding lengths, so every half cycle slides
  through the Stribeck region into the Coulomb level.

The force is the law's (:func:`idtool._model._series_force.series_force`) computed on a
grid ``oversample`` times finer than the output (then decimated), so a fit at the
output's rate does not reuse the simulator's discretisation; white Gaussian noise of
sd ``noise_n`` [N] is added, from ``seed``.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from idtool._data._series import Series
from idtool._model._series_force import series_force
from idtool._model._series_law import series_law

__all__ = ["KINDS", "LUGRE_TRUTH", "simulate_series"]

KINDS = ("presliding", "sliding")
# A LuGre contact of a small lab rig (after Canudas de Wit et al. 1995, with a viscous
# term large enough to matter at these speeds): values by fit-law's parameter names.
LUGRE_TRUTH: dict[str, float] = {
    "Fc": 1.0,
    "Kt": 1e5,
    "static_ratio": 1.5,
    "stribeck_velocity_m_s": 2e-3,
    "sigma1": 300.0,
    "sigma2": 20.0,
}


def simulate_series(
    law: str = "lugre",
    truth: Mapping[str, float] | None = None,
    kind: str = "sliding",
    *,
    amplitude_m: float | None = None,
    frequency_hz: float = 1.0,
    duration_s: float = 3.0,
    rate_hz: float = 1000.0,
    noise_n: float = 0.01,
    normal_load_n: float | None = None,
    slip_input: str = "velocity",
    oversample: int = 8,
    seed: int = 0,
) -> Series:
    """A series of slip and friction force (module docstring).

    Args:
        law: a :func:`idtool._model._series_law.series_law` name.
        truth: parameter values by name (default :data:`LUGRE_TRUTH`'s, those the law
            takes; ``mu`` instead of ``Fc`` with a normal load).
        kind: ``"presliding"`` or ``"sliding"``.
        amplitude_m: slip amplitude A [m]; default 0.3 Fc/Kt (presliding) or
            30 Vs / w, but at least 20 Fc/Kt (sliding).
        frequency_hz: of the slip oscillation [Hz].
        duration_s: length [s]; rate_hz: samples per second [Hz].
        noise_n: sd of the white force noise [N].
        normal_load_n: a constant normal load [N] (then the level is ``mu``), or None.
        slip_input: ``"velocity"`` or ``"displacement"``: which the series carries.
        oversample: simulation grid over output grid.
        seed: of the noise.
    """
    if kind not in KINDS:
        raise ValueError(f"kind {kind!r}: one of {KINDS}")
    values = dict(truth or LUGRE_TRUTH)
    spec = series_law(law, with_load=normal_load_n is not None)
    values = {k: float(values[k]) for k in spec.names}
    w = 2.0 * np.pi * frequency_hz
    fc = values["Fc"] if normal_load_n is None else values["mu"] * normal_load_n
    length_m = fc / values.get("Kt", np.inf)  # presliding length Fc / Kt
    if amplitude_m is None:
        vs = values.get("stribeck_velocity_m_s", 1e-3)
        amplitude_m = 0.3 * length_m if kind == "presliding" else max(30 * vs / w, 20 * length_m)
    n_fine = round(duration_s * rate_hz) * oversample + 1
    t = np.linspace(0.0, duration_s, n_fine)
    v = amplitude_m * w * np.sin(w * t)
    x = amplitude_m * (1.0 - np.cos(w * t))
    load = 1.0 if normal_load_n is None else normal_load_n
    force, _ = series_force(
        spec.law_at,
        values,
        t,
        v,
        load,
        extra_viscous_n_s_m=spec.extra_viscous_n_s_m(values),
        substeps=4,
    )
    keep = slice(None, None, oversample)
    rng = np.random.default_rng(seed)
    noisy = np.asarray(force)[keep] + noise_n * rng.standard_normal(t[keep].size)
    return Series(
        time_s=t[keep],
        force_n=noisy,
        velocity_m_s=v[keep] if slip_input == "velocity" else None,
        displacement_m=x[keep] if slip_input == "displacement" else None,
        normal_load_n=None if normal_load_n is None else np.full(t[keep].size, load),
        source=f"simulated {law} {kind} (seed {seed})",
    )
