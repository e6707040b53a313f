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
# # 03 — Uncertainty and design maps
#
# From a fit to a posterior (emcee), and from the posterior to the questions a seat-belt
# designer asks: how much does the friction drop at this load and amplitude, how sure
# are we, and what amplitude does a target reduction need at each load?

# %%
import tempfile
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

import idtool
from idtool._cli._main import main
from idtool._fit._store import load_fit
from idtool._predict._predict import amplitude_for_reduction, prediction_draws, predict_friction_ratio

# %% [markdown]
# ## Fit and sample the shipped example dataset
# (the same commands as `idtool fit` and `idtool sample`; a short chain keeps the notebook
# quick: read its convergence diagnostics before trusting the bands)

# %%
work = Path(tempfile.mkdtemp(prefix="idtool-nb03-"))
fit_dir = work / "example"
assert main(["fit", str(idtool.example_dataset_path()), "--out", str(fit_dir)]) == 0
assert main(["sample", str(fit_dir), "--steps", "800", "--no-progress"]) == 0

# %%
fit = load_fit(fit_dir)
draws = prediction_draws(fit, max_draws=400)
print(draws.note)

# %% [markdown]
# ## Friction reduction at the bench's operating points, with 95% bands

# %%
for p in predict_friction_ratio(draws, [270, 450, 670], [0.5, 0.7], [0.025]):
    red, (lo, hi) = p.reduction_percent
    print(f"{p.normal_load_n:5.0f} N, {100 * p.amplitude_fraction:3.0f}%:  "
          f"reduction {red:5.1f}% (95% {lo:5.1f}-{hi:5.1f}%)")

# %% [markdown]
# ## Design map: friction ratio over load and amplitude (posterior median)

# %%
loads = np.linspace(200, 900, 8)
amps = np.linspace(0.1, 1.0, 8)
preds = predict_friction_ratio(draws, loads, amps, [0.025])
fr = np.array([p.median for p in preds]).reshape(loads.size, amps.size)
width = np.array([p.ci95[1] - p.ci95[0] for p in preds]).reshape(loads.size, amps.size)
fig, (a1, a2) = plt.subplots(1, 2, figsize=(10, 4))
c1 = a1.contourf(amps, loads, fr, levels=12)
fig.colorbar(c1, ax=a1, label="FR (median)")
c2 = a2.contourf(amps, loads, width, levels=12, cmap="magma")
fig.colorbar(c2, ax=a2, label="width of the 95% band")
for ax in (a1, a2):
    ax.set(xlabel="amplitude fraction", ylabel="normal load [N]")
fig.tight_layout()
fig.savefig(work / "design_map.png", dpi=80)

# %% [markdown]
# The band widens away from the loads and amplitudes that were measured: extrapolation
# is honest about itself.
#
# ## Amplitude needed for a 50% reduction, against load

# %%
for r in amplitude_for_reduction(draws, 50.0, [300, 500, 700, 800], [0.025]):
    print(r.statement())
