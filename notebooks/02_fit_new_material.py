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
#
# Only idtool's public API is used (`import idtool`, then the names it exports).
# Everything is written into a fresh temporary folder, printed below.

# %%
import json
import tempfile
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np
import pandas as pd

import idtool

workdir = Path(tempfile.mkdtemp(prefix="idtool-nb02-"))
print("working in", workdir)

# %% [markdown]
# ## A bench session on a stiffer, slipperier webbing (simulated)
#
# Start from the shipped simulator parameters (the example bench) and change the
# material; `idtool.simulate_bench` returns the dataset and the truth behind it.

# %%
params = json.loads(idtool.example_params_path().read_text())
params["name"] = "webbing-B"
params["contact"]["friction_coefficient"] = 0.22
params["contact"]["contact_stiffness_n_m"] = 3e9
params["experiments"]["normal_loads_n"] = [270.0, 450.0, 670.0]
params["experiments"]["on_durations_s"] = [1.0, 2.5]
dataset, truth = idtool.simulate_bench(params, seed=42)
DATA = idtool.write_dataset(dataset, workdir / "webbing-B")
print(DATA)

# %% [markdown]
# ## Validate: every problem at once, located by file, row and column
#
# `idtool.load_dataset` checks the folder against the schema and the bench's
# plausibility rules, and raises `idtool.IdtoolError` listing every problem it found.

# %%
ds = idtool.load_dataset(DATA)
print(f"{ds.name}: {len(ds.traces)} traces")
print(pd.DataFrame(
    [{"trace": tr.id, "load [N]": tr.normal_load_n, "amplitude": tr.amplitude_fraction,
      "duration [s]": round(tr.duration_s, 1), "ON windows [s]": tr.on_windows_s}
     for tr in ds.traces]
).to_string(index=False))
print("warnings:", [str(w) for w in ds.warnings] or "none")

# %% [markdown]
# One raw trace: the pull starts, the force climbs to the sliding level mu N, and
# drops while the horn is ON (shaded).

# %%
tr = ds.traces[-1]
fig, ax = plt.subplots(figsize=(7, 3))
ax.plot(tr.time_s, tr.force_n, lw=0.5)
for start, end in tr.on_windows_s:
    ax.axvspan(start, end, color="orange", alpha=0.2, label="ultrasound ON")
ax.set(xlabel="time [s]", ylabel="load cell [N]",
       title=f"{tr.id}: {tr.normal_load_n:g} N, {100 * tr.amplitude_fraction:.0f}% amplitude")
ax.legend(loc="lower right")
fig.savefig(workdir / "raw_trace.png", dpi=80)
plt.show()

# %% [markdown]
# ## Fit, letting the data choose the coupling law
#
# `coupling="auto"` fits every coupling law and keeps the one with the lowest BIC; the
# report lists the estimates, their intervals and correlations, the model comparison,
# the friction ratio at each operating point, and warnings. The actuator and the
# load-cell offset are the simulator's here (constant slopes, a constant offset), so
# they are given rather than chosen: the comparison is the coupling laws' alone, five
# fits instead of twenty. On bench data leave them at their default, `"auto"`.

# %%
fit = idtool.fit(ds, coupling="auto", actuator="slope", offset="constant", seed=0)
print(fit)
print(f"(fitted in {fit.seconds:.1f} s)\n")
print(fit.report())

# %% [markdown]
# The physical parameters as a table, against the truth the simulator used:

# %%
t = truth.to_dict()
true = {"Kt": t["contact_stiffness_n_m"], "mu": t["friction_coefficient"],
        "coupling_gain": t["coupling"]["gain"], "power_load_n": t["coupling"]["power_load_n"]}
rows = []
for name in fit.model.physical_names:
    e = fit.estimates[name]
    value = true.get(name, np.nan)
    rows.append({"parameter": name, "unit": e.unit, "truth": value, "estimate": e.estimate,
                 "std error": e.std_error, "95% low": e.ci95[0], "95% high": e.ci95[1],
                 "truth inside": bool(e.ci95[0] <= value <= e.ci95[1])})
comparison = pd.DataFrame(rows).set_index("parameter")
print(comparison.to_string(float_format=lambda x: f"{x:.4g}"))
print("\nfit warnings:", fit.warnings or "none")

# %% [markdown]
# Kt is the hardest to pin down (its interval is the widest, relative to its value): at
# these loads the friction ratio depends on it only weakly. The coupling gain and the
# power load trade off against each other (see the correlation warning).
#
# ## The friction ratio at each operating point
#
# Per-trace friction ratio from the fit, with 95% error bars, against the truth (black
# bars); the lines are the fitted model's prediction between and beyond the measured
# loads (`fit.predict`: median and 95% band from draws on the fit's covariance, until a
# posterior is sampled; notebook 03).

# %%
d, r = fit.model.data, fit.result
true_fr = {tt.id: tt.friction_ratio for tt in truth.traces}
loads = np.asarray(d.normal_load_n)
alphas = np.asarray(d.amplitude_fraction)
curve = fit.predict(load_n=np.linspace(200.0, 800.0, 13), amplitude=np.unique(alphas).tolist(),
                    max_draws=400)
print("predictions from:", curve.source)
for w in curve.warnings:
    print("  -", w)
table = curve.to_frame()
fig, ax = plt.subplots(figsize=(6, 4))
for k, alpha in enumerate(np.unique(alphas)):
    colour = f"C{k}"
    c = table[np.isclose(table.amplitude_fraction, alpha)]
    ax.plot(c.normal_load_n, c["friction_ratio.median"], color=colour, lw=1)
    ax.fill_between(c.normal_load_n, c["friction_ratio.ci95.lo"], c["friction_ratio.ci95.hi"],
                    color=colour, alpha=0.2)
    sel = alphas == alpha
    ax.errorbar(loads[sel], r.friction_ratio[sel], 1.96 * r.friction_ratio_se[sel],
                fmt="o", color=colour, capsize=3, label=f"fit, {100 * alpha:.0f}% amplitude")
ax.plot(loads, [true_fr[i] for i in d.trace_ids], "k_", ms=14, mew=2, label="truth", zorder=5)
ax.axvspan(loads.min(), loads.max(), color="grey", alpha=0.08, label="measured loads")
ax.set(xlabel="normal load [N]", ylabel="friction ratio FR (95%)")
ax.legend(fontsize=8)
fig.tight_layout()
fig.savefig(workdir / "fr_vs_load.png", dpi=80)
plt.show()

# %% [markdown]
# At the measured points the error bars are smaller than the markers: the data pin the
# friction ratio down there. Away from them only the model carries the answer, and the
# predictions say so (the extrapolation warnings above).
#
# ## Save the fit, and read it back
#
# `fit.save` writes the same folder as `idtool fit --out` (`fit.json`, `report.txt`,
# the fit state and plots); a simulated dataset that lives only in memory is written
# inside it. `idtool.load_fit` reads it back, estimates and all.

# %%
fit_dir = fit.save(workdir / "fit-webbing-B")
print(sorted(f.name for f in fit_dir.iterdir()))
again = idtool.load_fit(fit_dir)
print(again)
for name in again.model.physical_names:
    assert np.isclose(again.estimates[name].estimate, fit.estimates[name].estimate, rtol=1e-9)

# %% [markdown]
# The fit's own figure of every trace against the model, from the saved folder:

# %%
fig, ax = plt.subplots(figsize=(10, 7))
ax.imshow(plt.imread(fit_dir / "traces.png"))
ax.set_axis_off()
plt.show()
print(sorted(f.name for f in workdir.iterdir()))
