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
#
# Only idtool's public API is used (`import idtool`, then the names it exports).
# Files are written into a fresh temporary folder, printed below.

# %%
import tempfile
from pathlib import Path

import arviz as az
import matplotlib.pyplot as plt
import numpy as np
import pandas as pd

import idtool

work = Path(tempfile.mkdtemp(prefix="idtool-nb03-"))
print("working in", work)

# %% [markdown]
# ## Fit and sample the shipped example dataset
#
# `idtool.fit` and `Fit.sample` do what `idtool fit` and `idtool sample` do. A short
# chain keeps the notebook quick: read its convergence diagnostics before trusting the
# bands (for real work, sample the default 3000 steps, or more if the diagnostics ask).

# %%
ds = idtool.load_dataset(idtool.example_dataset_path())
fit = idtool.fit(ds, seed=0)
print(fit)
post = fit.sample(walkers=32, steps=800, seed=0)
print(post.diagnostics.report())
print("converged:", post.diagnostics.converged)

# %% [markdown]
# The posterior against the fit's Gauss-Newton intervals: with this much data they
# agree closely, which is itself a check on the fit.

# %%
summary = post.summary()
rows = []
for name, s in summary.items():
    e = fit.estimates.get(name)
    rows.append({"parameter": name, "unit": s["unit"], "posterior median": s["median"],
                 "posterior 95% low": s["ci95"][0], "posterior 95% high": s["ci95"][1],
                 "fit": np.nan if e is None else e.estimate,
                 "fit 95% low": np.nan if e is None else e.ci95[0],
                 "fit 95% high": np.nan if e is None else e.ci95[1]})
print(pd.DataFrame(rows).set_index("parameter").to_string(float_format=lambda x: f"{x:.5g}"))

# %% [markdown]
# The chain is also available as ArviZ `InferenceData`, for ArviZ's own summaries and
# plots:

# %%
idata = post.to_arviz()
print(az.summary(idata, kind="diagnostics"))

# %% [markdown]
# ## Friction reduction at the bench's operating points, with 95% bands
#
# Once a posterior is sampled, `fit.predict` draws from it (the table says where its
# draws came from).

# %%
preds = fit.predict(load_n=[270, 450, 670], amplitude=[0.5, 0.7], max_draws=400)
print("draws:", preds.note)
t = preds.to_frame()
reduction = pd.DataFrame({
    "load [N]": t.normal_load_n,
    "amplitude": t.amplitude_fraction,
    "FR": t["friction_ratio.median"],
    "reduction [%]": t["reduction_percent.median"],
    "95% low [%]": t["reduction_percent.ci95.lo"],
    "95% high [%]": t["reduction_percent.ci95.hi"],
})
print(reduction.round(3).to_string(index=False))

# %% [markdown]
# ## Design map: friction ratio over load and amplitude (posterior median)
#
# The same predictions over a grid of loads x amplitudes, with the width of the 95%
# band beside them; the dots are the operating points that were measured.

# %%
loads = np.linspace(200, 900, 8)
amps = np.linspace(0.1, 1.0, 8)
grid = fit.predict(load_n=loads, amplitude=amps, max_draws=400)
for w in grid.warnings:
    print("warning:", w)
fr = np.array([p.median for p in grid]).reshape(loads.size, amps.size)
width = np.array([p.ci95[1] - p.ci95[0] for p in grid]).reshape(loads.size, amps.size)
measured = np.array([(tr.amplitude_fraction, tr.normal_load_n) for tr in ds.traces])
fig, (a1, a2) = plt.subplots(1, 2, figsize=(10, 4))
c1 = a1.contourf(amps, loads, fr, levels=12)
fig.colorbar(c1, ax=a1, label="FR (median)")
c2 = a2.contourf(amps, loads, width, levels=12, cmap="magma")
fig.colorbar(c2, ax=a2, label="width of the 95% band")
for ax in (a1, a2):
    ax.plot(measured[:, 0], measured[:, 1], "wo", mec="k", label="measured")
    ax.set(xlabel="amplitude fraction", ylabel="normal load [N]")
a1.legend(loc="upper left", fontsize=8)
fig.tight_layout()
fig.savefig(work / "design_map.png", dpi=80)
plt.show()

# %% [markdown]
# The band widens away from the loads and amplitudes that were measured: extrapolation
# is honest about itself (and the predictions warn about it, above).
#
# ## Amplitude needed for a 50% reduction, against load

# %%
needed = fit.amplitude_for(50, load_n=np.arange(250.0, 851.0, 50.0), max_draws=400)
for r in needed:
    print(r.statement())
for w in needed.warnings:
    print("warning:", w)

# %%
ok = [r for r in needed if r.reachable]
med = np.array([r.amplitude[0] for r in ok])
yerr = np.array([[r.amplitude[0] - r.amplitude[1], r.amplitude[2] - r.amplitude[0]] for r in ok]).T
fig, ax = plt.subplots(figsize=(6, 3.5))
ax.errorbar([r.normal_load_n for r in ok], med, yerr=yerr, fmt="o-", capsize=3,
            label="needed amplitude (95% band)")
out_of_reach = [r.normal_load_n for r in needed if not r.reachable]
if out_of_reach:
    ax.axvspan(min(out_of_reach) - 25, max(out_of_reach) + 25, color="r", alpha=0.1,
               label="out of reach at full amplitude")
ax.axhspan(0.5, 0.7, color="grey", alpha=0.15, label="measured amplitudes")
ax.set(xlabel="normal load [N]", ylabel="amplitude fraction", ylim=(0, 1.05),
       title="amplitude for a 50% friction reduction")
ax.legend(fontsize=8, loc="upper left")
fig.tight_layout()
fig.savefig(work / "amplitude_for_50.png", dpi=80)
plt.show()

# %% [markdown]
# Most needed amplitudes lie below the measured 50-70%, and the heaviest loads beyond
# the measured ones: there the answers lean on the model's shape rather than on data,
# and say so (the warnings above). A bench run at 20-30% amplitude would test them.
#
# ## Keep the result
#
# `fit.save` writes the fit folder (as `idtool fit --out` does) and `fit.save_posterior`
# adds the posterior (`posterior.nc`, `sample.json`, `report_sample.txt`, `ppc.png`).
# `idtool.load_fit` reads both back, so later predictions come from the same posterior.
# (`idtool.write_report(fit_dir)` would add an HTML report with figures; it takes about
# half a minute, so it is left out here.)

# %%
fit_dir = fit.save(work / "example", plots=False)
sample_report = fit.save_posterior()
# the posterior's report repeats the diagnostics above; its predictive check is new:
print(sample_report[sample_report.index("[[Posterior predictive check]]"):].split("\n[[")[0])
again = idtool.load_fit(fit_dir)
print(again, "- predictions from:", again.predict(450, 0.7, max_draws=400).source)
print(sorted(f.name for f in fit_dir.iterdir()))
