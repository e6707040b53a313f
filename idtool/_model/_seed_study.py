"""The paper's Section 3.6 parameter study (Figures 8-11) on the SDOF transducer.

Each figure sweeps one Table 2 parameter over four values and, for each, the sliding
speed so that the velocity ratio spans 0.05-1.2; the velocity ratio reported is the one
of the periodic orbit (the friction changes the vibration slightly). The values chosen
bracket Table 2: Fe up to its stated maximum of 1920 N; Ks from a quarter of Table 2 to
just below the stiffness that puts the natural frequency at the 60 kHz excitation
(Ks = m w^2 = 2.84e9 N/m), where the paper says friction reduction is strongest.
"""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pandas as pd
from jaxtyping import Array

from idtool._model._limits import coulomb_friction_ratio
from idtool._model._transducer import Transducer, table2, transducer_steady_state
from idtool._plotting import subplots

__all__ = ["SEED_FIGURES", "SeedFigure", "plot_seed_study", "seed_study"]


@dataclasses.dataclass(frozen=True)
class SeedFigure:
    """One of the paper's Figures 8-11: which Table 2 field is swept, and over what."""

    figure: str
    parameter: str
    label: str
    values: tuple[float, ...]


SEED_FIGURES = (
    SeedFigure("fig8", "force_amplitude_n", "Fe [N]", (480.0, 960.0, 1440.0, 1920.0)),
    SeedFigure("fig9", "friction_coefficient", "mu", (0.05, 0.1, 0.2, 0.4)),
    SeedFigure("fig10", "mass_kg", "m [kg]", (0.01, 0.02, 0.04, 0.08)),
    SeedFigure("fig11", "stiffness_n_m", "Ks [N/m]", (33.25e6, 133e6, 1.33e9, 2.4e9)),
)


@jax.jit
def _solve(batch: Transducer, vr_targets: Array):
    """Steady states for every transducer in ``batch`` (stacked) at every target VR."""

    def one(p, vr_target):
        vt = vr_target * p.linear_amplitude_m * p.angular_frequency_rad_s
        r = transducer_steady_state(p, vt)
        b = r.balance
        return (
            r.velocity_ratio,
            b.friction_ratio,
            b.power_ratio,
            b.balance_residual,
            b.input_power_ratio,
        )

    return jax.vmap(jax.vmap(one, (None, 0)), (0, None))(batch, vr_targets)


def seed_study(
    velocity_ratios: np.ndarray | None = None,
    figures: tuple[SeedFigure, ...] = SEED_FIGURES,
) -> pd.DataFrame:
    """Run the study; one row per (figure, value, velocity ratio).

    Columns: ``figure, parameter, value, velocity_ratio, friction_ratio, power_ratio``.
    All figures are solved in one vectorised, compiled call. Raises if any steady state
    fails to close the energy balance (eq. 25) within 1e-3 of the input
    ``1 + phi_iu`` (eq. 22).
    """
    vr = jnp.linspace(0.05, 1.2, 24) if velocity_ratios is None else jnp.asarray(velocity_ratios)
    cases = [(fig, value) for fig in figures for value in fig.values]
    models = [table2(**{fig.parameter: value}) for fig, value in cases]
    batch = jax.tree.map(lambda *xs: jnp.stack([jnp.asarray(x, float) for x in xs]), *models)
    got_vr, fr, pdr, resid, phi_in = (np.asarray(a) for a in _solve(batch, vr))
    worst = np.max(np.abs(resid) / (1.0 + np.abs(phi_in)))
    if worst > 1e-3:
        raise RuntimeError(f"seed study: energy balance off by {worst:.1e} of the input")
    n = vr.size
    return pd.DataFrame(
        {
            "figure": np.repeat([fig.figure for fig, _ in cases], n),
            "parameter": np.repeat([fig.parameter for fig, _ in cases], n),
            "value": np.repeat([value for _, value in cases], n),
            "velocity_ratio": got_vr.ravel(),
            "friction_ratio": fr.ravel(),
            "power_ratio": pdr.ravel(),
        }
    )


def plot_seed_study(table: pd.DataFrame, out_dir, figures=SEED_FIGURES) -> list:
    """One PNG per figure: (a) FR and (b) PDR against VR, a curve per value."""
    paths = []
    for fig in figures:
        rows = table[table.figure == fig.figure]
        f, (ax_fr, ax_pd) = subplots(1, 2, figsize=(10, 4), layout="constrained")
        for value, group in rows.groupby("value"):
            ax_fr.plot(group.velocity_ratio, group.friction_ratio, marker=".", label=f"{value:g}")
            ax_pd.plot(group.velocity_ratio, group.power_ratio, marker=".", label=f"{value:g}")
        ref = np.linspace(0.0, 1.2, 200)
        ax_fr.plot(ref, np.asarray(coulomb_friction_ratio(ref)), "k:", label="Coulomb")
        ax_fr.set(xlabel="velocity ratio VR", ylabel="friction ratio FR", title=f"(a) {fig.figure}")
        ax_pd.set(xlabel="velocity ratio VR", ylabel="power dissipation ratio PDR", title="(b)")
        ax_fr.legend(title=fig.label)
        ax_pd.legend(title=fig.label)
        path = f"{out_dir}/{fig.figure}_{fig.parameter}.png"
        f.savefig(path, dpi=110)
        paths.append(path)
    return paths
