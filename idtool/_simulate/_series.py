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

``departure`` adds what a real measuring chain does and the fit does not model (issue
30's recovery study, ``benchmarks/study_benches.py``):

* ``"coloured"``: the noise AR(1) with lag-one correlation 0.9 (same sd), as a load
  cell's amplifier gives;
* ``"hum"``: the coloured noise plus mains hum, a 60 Hz sine of amplitude
  ``2 noise_n`` (random phase);
* ``"drift"``: the coloured noise plus a load-cell offset drifting linearly from 0 to
  ``5 noise_n`` over the record;
* ``"lag"``: the force low-passed (first order, time constant 0.5 ms: a 320 Hz
  bandwidth) before the white noise: a sensor not much faster than the sampling.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from idtool._data._series import Series
from idtool._model._series_force import series_force
from idtool._model._series_law import series_law

__all__ = ["KINDS", "LUGRE_TRUTH", "SERIES_DEPARTURES", "simulate_series"]

KINDS = ("presliding", "sliding")
SERIES_DEPARTURES = ("coloured", "hum", "drift", "lag")
HUM_HZ = 60.0
LAG_S = 0.5e-3
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
    departure: str | None = None,
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
        departure: None (white noise) or one of :data:`SERIES_DEPARTURES` (module
            docstring).
        seed: of the noise.
    """
    if kind not in KINDS:
        raise ValueError(f"kind {kind!r}: one of {KINDS}")
    if departure is not None and departure not in SERIES_DEPARTURES:
        raise ValueError(f"departure {departure!r}: None or one of {SERIES_DEPARTURES}")
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
    measured = np.asarray(force)
    if departure == "lag":
        # first-order sensor, exact for a force linear between the fine grid's samples
        h = t[1] - t[0]
        e = np.exp(-h / LAG_S)
        c1 = 1.0 - LAG_S / h * (1.0 - e)  # weight of the step's end sample
        lagged = np.empty_like(measured)
        lagged[0] = measured[0]
        for k in range(1, measured.size):
            lagged[k] = e * lagged[k - 1] + (1.0 - e - c1) * measured[k - 1] + c1 * measured[k]
        measured = lagged
    keep = slice(None, None, oversample)
    rng = np.random.default_rng(seed)
    t_out = t[keep]
    n_out = t_out.size
    white = rng.standard_normal(n_out)
    if departure in ("coloured", "hum", "drift"):
        phi = 0.9  # AR(1) at the output rate, stationary sd noise_n
        coloured = np.empty(n_out)
        coloured[0] = white[0]
        for k in range(1, n_out):
            coloured[k] = phi * coloured[k - 1] + np.sqrt(1.0 - phi**2) * white[k]
        white = coloured
    noisy = measured[keep] + noise_n * white
    if departure == "hum":
        noisy = noisy + 2.0 * noise_n * np.sin(
            2.0 * np.pi * HUM_HZ * t_out + rng.uniform(0, 2 * np.pi)
        )
    if departure == "drift":
        noisy = noisy + 5.0 * noise_n * (t_out - t_out[0]) / (t_out[-1] - t_out[0])
    return Series(
        time_s=t[keep],
        force_n=noisy,
        velocity_m_s=v[keep] if slip_input == "velocity" else None,
        displacement_m=x[keep] if slip_input == "displacement" else None,
        normal_load_n=None if normal_load_n is None else np.full(t[keep].size, load),
        source=f"simulated {law} {kind}{f' {departure}' if departure else ''} (seed {seed})",
    )
