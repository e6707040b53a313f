"""``fit_law.png``: measured and fitted force against time, and against slip
displacement (the hysteresis loop)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from idtool._plotting import save_figure, subplots

__all__ = ["plot_fit"]

_MAX_POINTS = 4000  # drawn per line: a 10,000-sample series thinned evenly


def plot_fit(fit, path: str | Path) -> Path:
    """The figure of a :class:`idtool._lawfit._result.SeriesFit` at ``path``."""
    s = fit.problem.series
    t, f, m = s.time_s, s.force_n, fit.force_model_n
    x = s.displacement()
    unit, factor = ("mm", 1e3) if np.ptp(x) > 1e-3 else ("um", 1e6)
    x_um = x * factor
    keep = slice(None, None, max(1, s.n_samples // _MAX_POINTS))
    fig, (a1, a2, a3) = subplots(
        1, 3, figsize=(11.0, 3.6), gridspec_kw={"width_ratios": [2.0, 1.2, 1.2]}
    )
    a1.plot(t[keep], f[keep], ".", ms=2.0, color="0.55", label="measured")
    lag = fit.sensor_lag_s
    what = fit.law if lag is None else f"{fit.law}, sensor lag {lag * 1e3:.2g} ms"
    a1.plot(t[keep], m[keep], "-", lw=1.2, color="C3", label=f"fitted ({what})")
    a1.set(xlabel="time [s]", ylabel="friction force [N]", title="force against time")
    a1.legend(loc="upper right", fontsize=8)
    a2.plot(x_um[keep], f[keep], ".", ms=2.0, color="0.55")
    a2.plot(x_um[keep], m[keep], "-", lw=1.0, color="C3")
    a2.set(
        xlabel=f"slip displacement [{unit}]", ylabel="friction force [N]", title="hysteresis loop"
    )
    r = fit.residuals_n
    a3.plot(t[keep], r[keep], ".", ms=2.0, color="C0")
    a3.axhline(0.0, color="k", lw=0.8)
    a3.set(
        xlabel="time [s]",
        ylabel="measured - fitted [N]",
    )
    a3.set_title(f"residuals: sd {np.std(r):.3g} N, lag-1 {fit.optimum.phi_white:+.2f}", fontsize=9)
    return save_figure(fig, path)
