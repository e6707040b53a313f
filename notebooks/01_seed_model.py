# ---
# jupyter:
#   jupytext:
#     formats: ipynb,py:percent
#     text_representation:
#       extension: .py
#       format_name: percent
#   kernelspec:
#     display_name: Python 3
#     language: python
#     name: python3
# ---

# %% [markdown]
# # 01 — The seed model: friction laws, analytic limits, and the paper's sweeps
#
# This notebook explores the physics idtool is built on (Bharadwaj & Dapino, SPIE 7645,
# 2010; restated in `shared/reference/model-notes.md`):
#
# 1. the prescribed-vibration contact against its closed-form limits (notes §4);
# 2. the paper's single-degree-of-freedom transducer (eqs. 6-7) and its energy balance;
# 3. the Table 2 parameter sweeps of Section 3.6 (Figures 8-11).
#
# Everything here uses idtool's public API only (`import idtool`, then the names it
# exports). Open it in Jupyter with jupytext installed (it is a paired
# `py:percent` notebook), or run it as a script: `python notebooks/01_seed_model.py`.
# Figures are also saved into a fresh temporary folder, printed below.

# %%
import tempfile
from pathlib import Path

import jax
import matplotlib.pyplot as plt
import numpy as np

import idtool

out_dir = Path(tempfile.mkdtemp(prefix="idtool-nb01-"))
print("figures go to", out_dir)

# %% [markdown]
# ## 1. Friction ratio against velocity ratio
#
# Dimensionless contact: amplitude a = 1, frequency w = 1, Coulomb level Fc = 1, so the
# sliding speed is VR and the bristle stiffness is Lambda = Kt a / Fc.

# %%
vr = np.linspace(0.02, 1.2, 120)
fig, ax = plt.subplots(figsize=(6, 4))
for lam in (0.3, 1.0, 3.0, 10.0, 100.0):
    out = idtool.cycle_average_curve(idtool.Dahl(fc_n=1.0, kt_n_m=lam), vr)
    ax.plot(vr, out.friction_ratio, label=f"Dahl, Lambda = {lam:g}")
ax.plot(vr, idtool.coulomb_friction_ratio(vr), "k--", label="Coulomb (2/pi) arcsin VR")
ax.plot(vr, np.minimum(idtool.dahl_small_lambda_friction_ratio(vr), 1), "k:",
        label="Dahl, Lambda -> 0")
ax.set(xlabel="velocity ratio VR", ylabel="friction ratio FR")
ax.legend(fontsize=8)
fig.savefig(out_dir / "curves.png", dpi=80)
plt.show()

# %% [markdown]
# The notes' spot values, computed here and printed next to the stated ones:

# %%
for (v, lam), stated in {(0.1, 1): 0.122, (0.5, 1): 0.600, (0.5, 5): 0.379,
                         (0.9, 2): 0.946, (0.3, 100): 0.195}.items():
    fr = idtool.prescribed_cycle_average(idtool.Dahl(fc_n=1.0, kt_n_m=lam), v, 1.0, 1.0)
    print(f"VR {v:.1f}  Lambda {lam:>3}:  FR = {float(fr.friction_ratio):.4f}  (notes {stated})")
    assert abs(float(fr.friction_ratio) - stated) < 2e-3

# %% [markdown]
# ## 2. The SDOF transducer (Table 2)
#
# The periodic orbit at the forcing period, found by Newton shooting; the energy
# balance of eq. 25 closes to integration accuracy.

# %%
p = idtool.table2()
vt = 0.4 * float(p.linear_amplitude_m * p.angular_frequency_rad_s)
st = idtool.transducer_steady_state(p, vt)
b = st.balance
print(f"VR = {float(st.velocity_ratio):.4f}, FR = {float(b.friction_ratio):.4f}, "
      f"PDR = {float(b.power_ratio):.4f}")
print(f"phi_iu = {float(b.input_power_ratio):.4f}, phi_su = {float(b.system_power_ratio):.4f}, "
      f"balance residual = {float(b.balance_residual):.1e}")

# %% [markdown]
# Marching from rest, as the paper did: without damping the free oscillation at
# sqrt(Ks/m) stays in the signal, which is why the paper's signals are not pure sinusoids.

# %%
run = idtool.simulate_transducer(p, vt, periods=6, steps_per_period=400)
fig, ax = plt.subplots(figsize=(7, 3))
ax.plot(np.asarray(run.time_s) * 1e6, np.asarray(run.friction_n) / float(p.fc_n))
ax.set(xlabel="time [us]", ylabel="F_D / Fc")
fig.savefig(out_dir / "march.png", dpi=80)
plt.show()

# %% [markdown]
# ## 3. Section 3.6 sweeps (a subset, to keep the notebook quick)
#
# `idtool.seed_study` solves every steady state of the chosen figures in one compiled
# call and returns a pandas table (one row per figure, swept value and VR).

# %%
figures = idtool.SEED_FIGURES[:2]
print("figures:", [(f.figure, f.parameter, f.values) for f in figures])
table = idtool.seed_study(velocity_ratios=np.linspace(0.05, 1.1, 8), figures=figures)
print(table.groupby(["figure", "parameter", "value"]).friction_ratio.mean().round(3).to_string())

# %%
fig, axes = plt.subplots(1, len(figures), figsize=(5 * len(figures), 4), squeeze=False)
for ax, f in zip(axes[0], figures, strict=True):
    for value, g in table[table.figure == f.figure].groupby("value"):
        ax.plot(g.velocity_ratio, g.friction_ratio, marker=".", label=f"{f.parameter} = {value:g}")
    ax.plot(vr, idtool.coulomb_friction_ratio(vr), "k--", lw=0.8, label="Coulomb")
    ax.set(xlabel="VR", ylabel="FR", title=f.figure)
    ax.legend(fontsize=8)
fig.tight_layout()
fig.savefig(out_dir / "seed_study.png", dpi=80)
plt.show()

# %% [markdown]
# Figure 8: the friction ratio falls as the excitation force Fe rises; Figure 9: it rises
# with the friction coefficient mu.
#
# Gradients come for free: the sensitivity of FR to the contact stiffness at a
# bench-like operating point.

# %%
def fr_of_kt(kt):
    law = idtool.Dahl(fc_n=0.3 * 450.0, kt_n_m=kt)
    return idtool.prescribed_cycle_average(law, 0.025, 4e-7, 2 * np.pi * 20e3).friction_ratio


print("dFR/dlog(Kt) =", float(jax.grad(lambda lk: fr_of_kt(jax.numpy.exp(lk)))(np.log(1e9))))
print(sorted(f.name for f in out_dir.iterdir()))
