"""traces.png draws at most MAX_TRACE_PANELS panels (issue 28): every trace up to it,
else the traces with the largest rms residual, in trace order."""

from __future__ import annotations

import numpy as np

from idtool._report._fit_text import MAX_TRACE_PANELS, shown_traces


def test_every_trace_up_to_the_bound():
    block_trace = np.repeat(np.arange(MAX_TRACE_PANELS), 5)
    resid = np.random.default_rng(0).normal(size=block_trace.size)
    np.testing.assert_array_equal(
        shown_traces(resid, block_trace, MAX_TRACE_PANELS), np.arange(MAX_TRACE_PANELS)
    )


def test_beyond_it_the_worst_traces_by_rms_residual_in_trace_order():
    n = 4 * MAX_TRACE_PANELS
    rng = np.random.default_rng(1)
    blocks = rng.integers(3, 9, n)  # traces of different lengths: rms, not sum
    rms = rng.permutation(np.linspace(1.0, 2.0, n))
    # per trace a residual of exactly that rms: +-rms alternating, an even count
    block_trace = np.repeat(np.arange(n), 2 * blocks)
    resid = np.concatenate([rms[i] * np.resize([1.0, -1.0], 2 * blocks[i]) for i in range(n)])
    shown = shown_traces(resid, block_trace, n)
    want = np.sort(np.argsort(rms)[-MAX_TRACE_PANELS:])
    np.testing.assert_array_equal(shown, want)
