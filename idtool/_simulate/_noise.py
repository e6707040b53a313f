"""What a real load cell adds to the bench model's force: noise, hum and quantisation.

Pure NumPy; every random draw comes from the generator passed in, so a seed fixes the
output exactly.
"""

from __future__ import annotations

import numpy as np

__all__ = ["ar1_noise", "lsb_decimals", "mains_hum", "quantise", "white_noise"]


def white_noise(rng: np.random.Generator, n: int, std_n: float) -> np.ndarray:
    """``n`` independent Gaussian samples of standard deviation ``std_n`` [N]."""
    return rng.normal(0.0, std_n, n) if std_n > 0 else np.zeros(n)


def ar1_noise(
    rng: np.random.Generator, n: int, std_n: float, correlation_time_s: float, sample_rate_hz: float
) -> np.ndarray:
    """Stationary AR(1) noise [N]: exponentially correlated over ``correlation_time_s``.

    ``x[k] = phi x[k-1] + e[k]`` with ``phi = exp(-1 / (fs tau))``; the innovations have
    standard deviation ``std_n sqrt(1 - phi^2)`` and ``x[-1]`` is drawn from the stationary
    law, so every sample has standard deviation ``std_n``.
    """
    if std_n <= 0 or n == 0:
        return np.zeros(n)
    phi = float(np.exp(-1.0 / (sample_rate_hz * correlation_time_s)))
    start = rng.normal(0.0, std_n)
    innovations = rng.normal(0.0, std_n * np.sqrt(1.0 - phi**2), n)
    import scipy.signal  # here, not at the top: 0.2 s of import that only simulation needs

    out, _ = scipy.signal.lfilter([1.0], [1.0, -phi], innovations, zi=[phi * start])
    return np.asarray(out, dtype=np.float64)


def mains_hum(
    time_s: np.ndarray, amplitude_n: float, frequency_hz: float, phase_rad: float
) -> np.ndarray:
    """Mains pick-up ``A sin(2 pi f t + phase)`` [N]."""
    return amplitude_n * np.sin(2.0 * np.pi * frequency_hz * time_s + phase_rad)


def lsb_decimals(lsb_n: float) -> int:
    """Decimals that write every multiple of ``lsb_n`` exactly (at most 12)."""
    for decimals in range(13):
        scaled = lsb_n * 10**decimals
        if abs(scaled - round(scaled)) < 1e-9 * max(scaled, 1.0):
            return decimals
    return 12


def quantise(force_n: np.ndarray, lsb_n: float) -> np.ndarray:
    """Round to the ADC step ``lsb_n`` [N] (0: unchanged).

    The result is also rounded to :func:`lsb_decimals` decimals, so each value is the
    double nearest its short decimal form and a CSV holds it exactly in few characters.
    """
    if lsb_n <= 0:
        return np.asarray(force_n, dtype=np.float64)
    steps = np.round(np.asarray(force_n) / lsb_n)
    return np.round(steps * lsb_n, lsb_decimals(lsb_n))
