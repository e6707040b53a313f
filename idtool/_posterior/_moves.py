"""emcee's moves and the batch size of the compiled log-posterior, by posterior (the
levels model's or the traces' own), chosen by measured autocorrelation times (issue 26;
``benchmarks/bench_sample.py``)."""

from __future__ import annotations

from typing import Any

from idtool._posterior._record import LEVELS
from idtool._posterior._snooker import snooker_move

__all__ = ["batch_rows", "levels_moves", "sampler_moves"]


def batch_rows(walkers: int, noise: str) -> int:
    """Rows of the compiled log-posterior. The levels model's: a quarter of the ensemble
    (rounded up), the snooker move's subsets; the DE move's halves run as two batches (its
    cost is linear in the rows, 1.0, 2.0 and 3.8 ms for 8, 16 and 32: a padded batch would
    be time lost). The traces' own (noise-only) posterior: half the ensemble, DE's halves."""
    return -(-walkers // 4) if noise == LEVELS else -(-walkers // 2)


def sampler_moves(noise: str = LEVELS, ridge: Any = None):
    """The levels model's moves (:func:`levels_moves`); on the traces' own (noise-only)
    posterior DE alone, measured better there: largest tau 27 against 48 with the snooker
    on the example (32 x 3000, benchmarks/bench_sample.py), whose 8 parameters (the
    actuator's slopes and the noise's sd and phi among them) are near-Gaussian.

    Sampled along a ridge (``ridge``, a :class:`~idtool._posterior._ridge.RidgeTarget`),
    a tenth of the steps (taken from DE and the snooker alike) redraw the profiled
    parameter along it (:mod:`idtool._posterior._ridge_jump`): without them the walkers
    gather in the peak between Kt's plateaus and never return to the plateaus, which
    hold most of its mass on the coupling bench (seed 503)."""
    import emcee

    if noise != LEVELS:
        return [(emcee.moves.DEMove(), 1.0)]
    if ridge is None:
        return levels_moves()
    (de, w_de), (snooker, w_snooker), jump = levels_moves()
    return [(de, w_de - 0.05), (snooker, w_snooker - 0.05), jump, (ridge.jump_move(), 0.1)]


def levels_moves():
    """emcee's differential-evolution move (ter Braak 2006) and the snooker variant (ter
    Braak & Vrugt 2008, :mod:`idtool._posterior._snooker`: emcee 3.1.6's own does not
    sample its target), half and half.

    The mixture was chosen by autocorrelation times measured with emcee's snooker,
    whose chains contracted: on the example its Kt interval was half the width that DE
    alone and the corrected snooker agree on, with a tau of 27 against 104 (6398 steps
    to converge instead of 1932). The table below is that measurement, kept as the
    record of why the mixture is what it is; ``benchmarks/bench_sample.py`` measures
    today's (32 walkers x 4000 steps, seed 0; the example and the departure benches
    "scatter", "coupling" and "all", seed 1). Largest tau per bench, emcee's snooker:

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
        (snooker_move(), 0.45),
        (emcee.moves.DEMove(gamma0=1.0), 0.1),
    ]
