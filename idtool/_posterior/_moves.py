"""emcee's moves and the batch size of the compiled log-posterior, by posterior (the
levels model's or the traces' own), chosen by measured autocorrelation times (issue 26;
``benchmarks/bench_sample.py``)."""

from __future__ import annotations

from idtool._posterior._record import LEVELS

__all__ = ["batch_rows", "levels_moves", "sampler_moves"]


def batch_rows(walkers: int, noise: str) -> int:
    """Rows of the compiled log-posterior. The levels model's: a quarter of the ensemble
    (rounded up), the snooker move's subsets; the DE move's halves run as two batches (its
    cost is linear in the rows, 1.0, 2.0 and 3.8 ms for 8, 16 and 32: a padded batch would
    be time lost). The traces' own (noise-only) posterior: half the ensemble, DE's halves."""
    return -(-walkers // 4) if noise == LEVELS else -(-walkers // 2)


def sampler_moves(noise: str = LEVELS):
    """The levels model's moves (:func:`levels_moves`); on the traces' own (noise-only)
    posterior DE alone, measured better there: largest tau 27 against 48 with the snooker
    on the example (32 x 3000, benchmarks/bench_sample.py), whose 8 parameters (the
    actuator's slopes and the noise's sd and phi among them) are near-Gaussian."""
    import emcee

    if noise == LEVELS:
        return levels_moves()
    return [(emcee.moves.DEMove(), 1.0)]


def levels_moves():
    """emcee's differential-evolution move (ter Braak 2006) and its snooker variant (ter
    Braak & Vrugt 2008), half and half, chosen by measured autocorrelation times on levels
    posteriors (32 walkers x 4000 steps, seed 0): the example and the departure benches
    "scatter", "coupling" and "all" (seed 1). Largest tau per bench:

    ============  =======  ==========  ==========  ==========
    bench         DE       DE + 35% S  DE + 50% S  DE + 65% S
    ============  =======  ==========  ==========  ==========
    example       101      34          32          36
    coupling      254      37          38          38
    all           192      51          44          38
    scatter       -        37          33          37
    ============  =======  ==========  ==========  ==========

    DE alone stalls on the curved ridge of the saturating coupling's gain and load scale
    (acceptance 0.09-0.16) and on the skewed log-sd of the discrepancy; the snooker's
    jumps along the line through another walker follow both. With the log-posterior
    compiled for a quarter of the ensemble (:func:`batch_rows`) a snooker step costs what a
    DE step costs. Folding the sds onto a signed linear scale (sd = |s|) was measured too:
    it helped the sds but slowed the physical parameters (largest tau 72).

    A tenth of the steps are DE with its scale fixed at 1, ter Braak's (2006) mode jump:
    ``x_i + (x_j - x_k)`` with ``j`` and ``k`` in different modes moves ``x_i`` to its
    place in the other mode, where the tuned scale (2.38 / sqrt(2 ndim), 0.64 here)
    lands in the valley between. Kt's creep and Coulomb plateaus on a bench whose
    coupling law the fit does not ship (:mod:`idtool._posterior._ridge`) are such modes."""
    import emcee

    return [
        (emcee.moves.DEMove(), 0.45),
        (emcee.moves.DESnookerMove(), 0.45),
        (emcee.moves.DEMove(gamma0=1.0), 0.1),
    ]
