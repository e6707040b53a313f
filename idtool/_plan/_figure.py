"""The plan's figure: the proposed pulls on the load x amplitude plane over today's band
half-width map, and the goal's expected value against the number of pulls beside a
uniform grid of the same size."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from idtool._plotting import save_figure, subplots

__all__ = ["plot_plan"]

_UNITS = {"band": "FR", "parameters": "-", "laws": "-"}


def plot_plan(plan, band_map: np.ndarray, traces: np.ndarray, path: Path) -> Path:
    """Write the figure of ``plan`` (:class:`~idtool._plan._plan.Plan`) to ``path``
    (PNG). ``band_map``: today's mean-FR band half-width
    [FR] at each candidate (the candidates' order); ``traces`` (n, 2): the fitted
    traces' loads [N] and amplitudes."""
    fig, (left, right) = subplots(1, 2, figsize=(10.0, 4.2))
    n_l, n_a, n_s = plan.grid_shape
    c = plan.candidates
    loads = c.normal_load_n.reshape(n_l, n_a, n_s)[:, 0, 0]
    amps = c.amplitude_fraction.reshape(n_l, n_a, n_s)[0, :, 0]
    z = band_map.reshape(n_l, n_a, n_s)[:, :, 0]
    if n_l > 1 and n_a > 1:
        mesh = left.contourf(loads, amps, z.T, levels=12, cmap="viridis")
        fig.colorbar(mesh, ax=left, label="today's 95% FR band half-width [FR]")
    left.scatter(
        traces[:, 0], traces[:, 1], marker="x", color="k", s=40, label="fitted traces", zorder=3
    )
    pts, counts = np.unique(
        np.array([(p.normal_load_n, p.amplitude_fraction) for p in plan.pulls]),
        axis=0,
        return_counts=True,
    )
    left.scatter(
        pts[:, 0],
        pts[:, 1],
        s=60 + 40 * counts,
        facecolor="none",
        edgecolor="red",
        linewidth=2,
        label="proposed pulls (size: repeats)",
        zorder=4,
    )
    for n, a, _ in plan.at:
        left.plot(
            n,
            a,
            marker="*",
            color="orange",
            markersize=14,
            linestyle="none",
            label="target",
            zorder=5,
        )
    span_n = max(float(np.ptp(loads)), 1.0)
    span_a = max(float(np.ptp(amps)), 0.01)
    left.set_xlim(loads.min() - 0.06 * span_n, loads.max() + 0.06 * span_n)
    left.set_ylim(amps.min() - 0.06 * span_a, amps.max() + 0.06 * span_a)
    left.set_xlabel("normal load [N]")
    left.set_ylabel("amplitude [fraction of maximum]")
    # below the map, where it hides none of it
    left.legend(
        loc="upper center",
        bbox_to_anchor=(0.5, -0.16),
        ncol=3,
        fontsize=9,
        markerscale=0.6,
        frameon=False,
    )
    n = np.arange(len(plan.values))
    right.plot(n, plan.values, "o-", color="red", label="planned (greedy)")
    right.plot(n, plan.uniform, "s--", color="grey", label="uniform grid")
    values = np.concatenate([np.asarray(plan.values, float), np.asarray(plan.uniform, float)])
    lo, hi = float(np.min(values)), float(np.max(values))
    if plan.target <= hi + 2.0 * (hi - lo):  # a target far above the curves would flatten them
        right.axhline(plan.target, color="k", linestyle=":", label=f"target {plan.target:g}")
    else:
        right.set_title(f"target {plan.target:g}: met before any pull", fontsize=9)
    right.set_xlabel("pulls added [count]")
    # the laws goal's unit is an expectation already ("expected weight of ...")
    what = plan.unit if plan.unit.startswith("expected") else f"expected {plan.unit}"
    right.set_ylabel(f"{what} [{_UNITS[plan.goal]}]")
    right.legend(fontsize=9)
    fig.suptitle(f"idtool plan: goal {plan.goal}")
    save_figure(fig, path)
    return path
