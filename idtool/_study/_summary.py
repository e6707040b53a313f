"""A study's summary from its records: coverage, SBC ranks, band half-widths, laws.

* Coverage: per physical parameter and per target's FR, the fraction of truths inside
  the 95% interval, with its exact binomial 95% interval and the two-sided binomial
  test's p-value against 0.95.
* SBC (Talts et al. 2018): each truth's rank among :data:`~idtool._study._task.
  RANK_DRAWS` draws is uniform on 0..L when the draws are calibrated; the ranks are
  binned into equal bins (as many as leave at least 5 expected per bin, at least 2) and
  tested against the uniform with Pearson's chi-square (``p`` small: not uniform; a
  U shape: intervals too narrow, a hump: too wide, a slope: biased).
* Half-width [FR]: per target, the achieved band's mean, median and 10-90% range beside
  the expected (the plan's value after its pulls, or today's linearised band).
* Laws: how often the chosen coupling law is the truth's, and the truth law's mean
  weight; for a plan with the goal ``laws`` also in how many truths that weight rose
  from the existing pulls' fit to the fit with the planned pulls (issue 29's target:
  on at least 80% of the truths).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["plot_study", "summarise", "summary_text"]

RANK_BINS = (10, 5, 4, 2)  # divide the 100 possible ranks evenly
CERTAIN = 0.95  # a weight that meets the laws goal (its default target, --weight 0.95): held


def _coverage(flags: list[bool], rate: float = 0.95) -> dict[str, Any]:
    """How many of ``flags`` hold, the fraction's exact 95% interval and the binomial
    test's p-value against ``rate``."""
    from scipy.stats import binomtest

    n, k = len(flags), int(sum(flags))
    if n == 0:
        return {"inside": 0, "n": 0}
    test = binomtest(k, n, rate)
    lo, hi = test.proportion_ci(0.95, method="exact")
    return {
        "inside": k,
        "n": n,
        "fraction": k / n,
        "ci95": [float(lo), float(hi)],
        "p_value": float(test.pvalue),
    }


def _sbc(ranks: list[int], draws: int) -> dict[str, Any]:
    from scipy.stats import chisquare

    n = len(ranks)
    bins = next((b for b in RANK_BINS if n >= 5 * b), 2)
    counts = np.histogram(ranks, bins=bins, range=(0, draws + 1))[0]
    out: dict[str, Any] = {"bins": bins, "counts": counts.tolist(), "n": n}
    if n >= 2:
        out["chi2"], out["p_value"] = (float(x) for x in chisquare(counts))
    out["enough"] = n >= 5 * bins
    return out


def summarise(records: list[dict], expected: dict[str, Any], wall_s: float) -> dict:
    """The summary document (module docstring) of ``records`` (failed ones listed
    apart); ``expected``: the expected half-widths per target and where they come from;
    ``wall_s`` [s] this run's wall time."""
    ok = [r for r in records if "error" not in r]
    failed = [{"task_id": r["task_id"], "error": r["error"]} for r in records if "error" in r]
    names = list(dict.fromkeys(n for r in ok for n in r["parameters"]))
    params = {}
    for name in names:
        rs = [r["parameters"][name] for r in ok if name in r["parameters"]]
        params[name] = {
            "coverage": _coverage([p["inside"] for p in rs]),
            "sbc": _sbc([p["rank"] for p in rs], rs[0]["draws"]) if rs else {},
            "median_relative_error": float(
                np.median([p["estimate"] / p["truth"] - 1.0 for p in rs])
            ),
        }
    targets = []
    n_targets = len(ok[0]["targets"]) if ok else 0
    for t in range(n_targets):
        rows = [r["targets"][t] for r in ok]
        hw = np.array([row["half_width"] for row in rows])
        exp = expected["half_width"][t] if t < len(expected.get("half_width", [])) else None
        targets.append(
            {
                "at": [rows[0]["normal_load_n"], rows[0]["amplitude_fraction"]],
                "pull_speed_m_s": rows[0]["pull_speed_m_s"],
                "coverage": _coverage([row["inside"] for row in rows]),
                "half_width_mean": float(hw.mean()),
                "half_width_median": float(np.median(hw)),
                "half_width_10_90": [float(np.quantile(hw, 0.1)), float(np.quantile(hw, 0.9))],
                "expected_half_width": exp,
                "achieved_over_expected": None if not exp else float(hw.mean() / exp),
            }
        )
    known = [r for r in ok if r["truth"]["law"] in r["law_weights"]]
    laws = {
        "n": len(known),
        "wins": int(sum(r["law"] == r["truth"]["law"] for r in known)),
        "truth_weight_mean": float(np.mean([r["law_weights"][r["truth"]["law"]] for r in known]))
        if known
        else None,
    }
    laws.update(_weights_moved(known))
    fits = [r["fit_s"] for r in ok]
    return {
        "tasks": len(records),
        "succeeded": len(ok),
        "failed": failed,
        "parameters": params,
        "targets": targets,
        "fr_coverage": _coverage([row["inside"] for r in ok for row in r["targets"]]),
        "laws": laws,
        "expected_source": expected.get("source", ""),
        "sampled": bool(ok and ok[0].get("sampled")),
        "fit_s_mean": float(np.mean(fits)) if fits else None,
        "task_s_mean": float(np.mean([r["task_s"] for r in ok])) if ok else None,
        "wall_s": float(wall_s),
    }


def _weights_moved(known: list[dict]) -> dict[str, Any]:
    """With the existing pulls' fit in the records (a plan for the goal ``laws``): in how
    many the true law's weight rose with the planned pulls (``rose`` of ``n_before``);
    in how many it rose or stayed at least :data:`CERTAIN` (``held``: a weight of 1.0
    before cannot rise); its mean weight before, and the truth's law chosen before."""
    pairs = [r for r in known if r["truth"]["law"] in r.get("law_weights_before", {})]
    if not pairs:
        return {}
    before = np.array([r["law_weights_before"][r["truth"]["law"]] for r in pairs])
    after = np.array([r["law_weights"][r["truth"]["law"]] for r in pairs])
    chosen = [max(r["law_weights_before"], key=r["law_weights_before"].get) for r in pairs]
    return {
        "n_before": len(pairs),
        "rose": int(np.sum(after > before)),
        "held": int(np.sum((after > before) | ((before >= CERTAIN) & (after >= CERTAIN)))),
        "rose_rate": _coverage(list(after > before), 0.8),
        "truth_weight_mean_before": float(before.mean()),
        "wins_before": int(sum(c == r["truth"]["law"] for c, r in zip(chosen, pairs, strict=True))),
    }


def _cov_text(c: dict) -> str:
    if not c.get("n"):
        return "-"
    lo, hi = c["ci95"]
    return (
        f"{c['inside']}/{c['n']} = {c['fraction']:.0%} [{lo:.0%}, {hi:.0%}], p {c['p_value']:.2g}"
    )


def summary_text(s: dict) -> str:
    """The summary for a person (summary.txt)."""
    lines = [
        f"tasks: {s['tasks']}, succeeded {s['succeeded']}, failed {len(s['failed'])}"
        f" ({'fit and posterior' if s['sampled'] else 'fit only, covariance draws'})"
    ]
    for f in s["failed"]:
        lines.append(f"  task {f['task_id']} failed: {f['error']}")
    lines.append("coverage of the 95% intervals (truths inside; exact 95% interval; p vs 0.95):")
    for name, p in s["parameters"].items():
        sbc = p["sbc"]
        chi = (
            f"SBC ranks {sbc['counts']} chi2 p {sbc['p_value']:.2g}"
            + ("" if sbc["enough"] else " (too few truths for the test)")
            if "p_value" in sbc
            else "SBC -"
        )
        lines.append(
            f"  {name:14s} {_cov_text(p['coverage'])}; median rel. error "
            f"{p['median_relative_error']:+.2%}; {chi}"
        )
    lines.append(f"  {'FR (targets)':14s} {_cov_text(s['fr_coverage'])}")
    lines.append(f"FR band half-width at the targets (expected: {s['expected_source']}):")
    lines.append("  (achieved: over the truths)")
    lines.append(
        f"  {'load [N]':>8s} {'amp':>5s} {'expected':>9s} {'mean':>9s}"
        f" {'median':>9s} {'10-90%':>17s}"
    )
    for t in s["targets"]:
        exp = "-" if t["expected_half_width"] is None else f"{t['expected_half_width']:.4g}"
        lo, hi = t["half_width_10_90"]
        lines.append(
            f"  {t['at'][0]:8.1f} {t['at'][1]:5.2f} {exp:>9s} {t['half_width_mean']:9.4g} "
            f"{t['half_width_median']:9.4g} "
            f"{lo:8.3g}-{hi:<8.3g} FR {_cov_text(t['coverage'])}"
        )
    law = s["laws"]
    if law["n"]:
        lines.append(
            f"coupling law: the truth's chosen in {law['wins']}/{law['n']}; the true law's "
            f"mean weight {law['truth_weight_mean']:.3g}"
        )
    if law.get("n_before"):
        lines.append(
            f"  with the planned pulls the true law's weight rose in {law['rose']}/"
            f"{law['n_before']} (rose or stayed >= {CERTAIN}: {law['held']}/{law['n_before']}); "
            "without them (the existing pulls' fit) it was chosen in "
            f"{law['wins_before']}/{law['n_before']}, mean weight "
            f"{law['truth_weight_mean_before']:.3g}"
        )
    if s["fit_s_mean"] is not None:
        lines.append(
            f"time: fit {s['fit_s_mean']:.1f} s, task {s['task_s_mean']:.1f} s on average; "
            f"this run {s['wall_s']:.0f} s"
        )
    return "\n".join(lines)


def plot_study(s: dict, records: list[dict], path: Path) -> None:
    """study.png: the achieved half-widths per target against the expected; the SBC rank
    histograms; the coverages with their 95% intervals."""
    from idtool._plotting import save_figure, subplots

    ok = [r for r in records if "error" not in r]
    names = list(s["parameters"])
    fig, axes = subplots(1, 3, figsize=(11.0, 4.0))
    ax = axes[0]
    for t, target in enumerate(s["targets"]):
        hw = [r["targets"][t]["half_width"] for r in ok]
        ax.scatter(np.full(len(hw), t) + np.linspace(-0.15, 0.15, len(hw)), hw, s=12, alpha=0.6)
        if target["expected_half_width"]:
            ax.hlines(target["expected_half_width"], t - 0.3, t + 0.3, color="k", lw=2)
    ax.set_xticks(range(len(s["targets"])))
    ax.set_xticklabels([f"{t['at'][0]:g} N\n{t['at'][1]:g}" for t in s["targets"]], fontsize=8)
    ax.set_yscale("log")
    ax.set_ylabel("FR band half-width [FR]")
    ax.set_title("achieved (dots) vs expected (bars)", fontsize=10)
    ax = axes[1]
    for name in names:
        sbc = s["parameters"][name]["sbc"]
        if sbc.get("counts"):
            edges = np.linspace(0, 1, sbc["bins"] + 1)
            ax.stairs(np.asarray(sbc["counts"]) / max(sbc["n"], 1), edges, label=name)
    if names and s["parameters"][names[0]]["sbc"].get("bins"):
        ax.axhline(1 / s["parameters"][names[0]]["sbc"]["bins"], color="k", ls=":")
    ax.set_xlabel("rank of the truth among the draws (fraction)")
    ax.set_ylabel("fraction of truths")
    ax.set_title("SBC ranks (uniform if calibrated)", fontsize=10)
    ax.legend(fontsize=8)
    ax = axes[2]
    rows = [(n, s["parameters"][n]["coverage"]) for n in names]
    rows += [(f"FR {t['at'][0]:g},{t['at'][1]:g}", t["coverage"]) for t in s["targets"]]
    rows = [(n, c) for n, c in rows if c.get("n")]
    for i, (_, c) in enumerate(rows):
        lo, hi = c["ci95"]
        ax.errorbar(
            c["fraction"], i, xerr=[[c["fraction"] - lo], [hi - c["fraction"]]], fmt="o", color="C0"
        )
    ax.axvline(0.95, color="k", ls=":")
    ax.set_yticks(range(len(rows)))
    ax.set_yticklabels([n for n, _ in rows], fontsize=8)
    ax.set_xlim(0, 1.02)
    ax.set_xlabel("coverage of the 95% intervals")
    ax.set_title(f"coverage over {s['succeeded']} truths", fontsize=10)
    save_figure(fig, path)
