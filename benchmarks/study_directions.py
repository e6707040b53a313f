"""Study: does ``direction="auto"`` pick the direction a bench vibrates in, and do Kt and
mu land in the winner's 95% intervals?

For each registered direction of vibration and ``--seeds`` seeds each: simulate the
small bench of :mod:`idtool._simulate._direction_bench` (the example's physics, 2 loads x
4 amplitudes, 8 traces; the truth fixed, the noise drawn from the seed) vibrating in that
direction, fit it with ``idtool.fit(dataset, direction="auto")`` and the fit's other
defaults (the actuator, offset and level models chosen by BIC, the power-limited
coupling), then score:

* how often BIC chose the simulated direction, and the truth's mean BIC weight;
* how often the truth's Kt and mu lie inside the chosen fit's 95% intervals (when the
  direction chosen is wrong, its Kt means something else: still scored, as a user would
  read it), and the median ratio of Kt's estimate to its truth;
* how often the chosen fit warned that the physical model misses the data (codes
  ``misfit_*``): a wrong direction shows as misfit when nothing else can absorb it;
* seconds per fit.

``--starts`` sets the multi-start points of every fit (default 8, the fit's): on this
8-trace bench 8 starts sometimes miss the along model's optimum (the truth's basin), and
then another direction wins by BIC.

Not part of the test suite (tests/test_direction_auto.py checks one seed per direction).
Run: ``.venv/bin/python benchmarks/study_directions.py`` (10 seeds per direction, a few
minutes on 2 cores) or ``--seeds 3 --directions normal``. Prints a table per direction
(the one quoted in docs/model.md) and each fit's row as it finishes.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

import idtool
from idtool._diagnostic import MISFIT_CODES
from idtool._simulate._direction_bench import direction_params
from idtool._simulate._simulate import simulate_bench


def score(direction: str, seed: int, starts: int = 8) -> dict:
    """One bench in ``direction`` with noise seed ``seed``, fitted with direction="auto"."""
    dataset, truth = simulate_bench(direction_params(direction), seed)
    started = time.perf_counter()
    fit = idtool.fit(dataset, direction="auto", seed=seed, starts=starts)
    seconds = time.perf_counter() - started
    a = fit.artefact
    true = {
        "Kt": truth.params.contact.contact_stiffness_n_m,
        "mu": truth.params.contact.friction_coefficient,
    }
    inside = {}
    for name, value in true.items():
        lo, hi = a.estimates[name].ci95
        inside[name] = bool(lo <= value <= hi)
    weights = {d: float(e["bic_weight"]) for d, e in a.directions.items()}
    return {
        "direction": direction,
        "seed": seed,
        "chosen": a.model.direction.name,
        "truth_weight": weights.get(direction, 0.0),
        "kt_inside": inside["Kt"],
        "mu_inside": inside["mu"],
        "kt_ratio": a.estimates["Kt"].estimate / true["Kt"],
        "misfit": any(w.code in MISFIT_CODES for w in fit.warnings),
        "seconds": seconds,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seeds", type=int, default=10)
    parser.add_argument("--directions", default=",".join(idtool.DIRECTIONS.names()))
    parser.add_argument("--starts", type=int, default=8)
    args = parser.parse_args()
    rows = []
    for direction in args.directions.split(","):
        for seed in range(1, args.seeds + 1):
            row = score(direction, seed, args.starts)
            rows.append(row)
            print(
                f"{direction:10s} seed {seed:2d}: chose {row['chosen']:10s} (truth's weight "
                f"{row['truth_weight']:.3f}), Kt x{row['kt_ratio']:.3f} "
                f"{'in' if row['kt_inside'] else 'OUT'}, mu {'in' if row['mu_inside'] else 'OUT'}, "
                f"{'misfit warned, ' if row['misfit'] else ''}{row['seconds']:.1f} s",
                flush=True,
            )
    print()
    print(
        "| simulated direction | chosen right | truth's mean BIC weight | Kt in 95% | mu in 95% "
        "| median Kt / truth | misfit warned (wrong / right) | s per fit |"
    )
    print("|---|---|---|---|---|---|---|---|")
    for direction in args.directions.split(","):
        mine = [r for r in rows if r["direction"] == direction]
        n = len(mine)
        right = sum(r["chosen"] == direction for r in mine)
        print(
            f"| {direction} | {right}/{n} "
            f"| {np.mean([r['truth_weight'] for r in mine]):.3f} "
            f"| {sum(r['kt_inside'] for r in mine)}/{n} "
            f"| {sum(r['mu_inside'] for r in mine)}/{n} "
            f"| {np.median([r['kt_ratio'] for r in mine]):.3f} "
            f"| {sum(r['misfit'] for r in mine if r['chosen'] != direction)}/{n - right} "
            f"/ {sum(r['misfit'] for r in mine if r['chosen'] == direction)}/{right} "
            f"| {np.median([r['seconds'] for r in mine]):.1f} |"
        )


if __name__ == "__main__":
    main()
