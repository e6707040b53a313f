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
# # 02 — Characterise a new webbing material from a dataset folder
#
# The workflow of a bench session: a folder in the v1 format (`datasets_schema/`), its
# validation, the joint fit of Kt, mu and the coupling, and a look at what the data
# do and do not tell. Here the "new material" is simulated (so the truth is known); with
# real data, point `DATA` at your folder and skip the simulation cell.

# %%
import json
import tempfile
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

import idtool
from idtool._report._fit_text import fit_report
from idtool._fit._run import fit_dataset

# %% [markdown]
# ## A bench session on a stiffer, slipperier webbing (simulated)

# %%
params = json.loads(idtool.example_params_path().read_text())
params["name"] = "webbing-B"
params["contact"]["friction_coefficient"] = 0.22
params["contact"]["contact_stiffness_n_m"] = 3e9
params["experiments"]["normal_loads_n"] = [270.0, 450.0, 670.0]
params["experiments"]["on_durations_s"] = [1.0, 2.5]
workdir = Path(tempfile.mkdtemp(prefix="idtool-nb02-"))
dataset, truth = idtool.simulate_bench(params, seed=42)
DATA = idtool.write_dataset(dataset, workdir / "webbing-B")
print(DATA)

# %% [markdown]
# ## Validate: every problem at once, located by file, row and column

# %%
ds = idtool.load_dataset(DATA)
for tr in ds.traces[:4]:
    print(tr.id, tr.normal_load_n, tr.amplitude_fraction, f"{tr.duration_s:.1f} s",
          tr.on_windows_s)
print("warnings:", [str(w) for w in ds.warnings] or "none")

# %% [markdown]
# ## Fit, letting the data choose the coupling law

# %%
run = fit_dataset(ds, coupling="auto", seed=0)
print(fit_report(run))

# %% [markdown]
# Against the truth the simulator used:

# %%
true = {"Kt": 3e9, "mu": 0.22, "coupling_gain": params["coupling"]["gain"],
        "power_load_n": params["coupling"]["power_load_n"]}
for name, value in true.items():
    e = run.chosen.estimates.get(name)
    if e is not None:
        inside = e.ci95[0] <= value <= e.ci95[1]
        print(f"{name:14s} truth {value:10.4g}  fit {e.estimate:10.4g}  "
              f"95% [{e.ci95[0]:.4g}, {e.ci95[1]:.4g}]  {'inside' if inside else 'OUTSIDE'}")

# %% [markdown]
# ## The friction ratio at each operating point, and a look at one trace

# %%
r, d = run.chosen, run.data
fig, ax = plt.subplots(figsize=(6, 4))
for alpha in np.unique(d.amplitude_fraction):
    sel = d.amplitude_fraction == alpha
    ax.errorbar(d.normal_load_n[sel], r.friction_ratio[sel], 1.96 * r.friction_ratio_se[sel],
                fmt="o", label=f"{100 * alpha:.0f}% amplitude")
ax.set(xlabel="normal load [N]", ylabel="friction ratio FR (fit, 95%)")
ax.legend()
fig.savefig(workdir / "fr_vs_load.png", dpi=80)
print(sorted(p.name for p in workdir.iterdir()))
