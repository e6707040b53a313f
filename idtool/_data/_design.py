"""What the experiment's design lets a fit tell apart: operating points pulled at several
speeds.

The friction ratio depends on ``VR = v / (a w)`` and ``Lambda = Kt a / (mu N)`` alone
(notes §4) and the slip amplitude ``a`` is not measured, so at one pull speed a measured
FR fixes only a curve in (``a``, Kt): Kt is then read through the coupling law's shape
across loads and amplitudes (:func:`idtool._fit._run.kt_through_coupling`). Pulled at two
speeds, a load and amplitude give two friction ratios at one ``a`` (a kinematic coupling
does not depend on the speed): two equations for ``a`` and Kt, whatever the law.
"""

from __future__ import annotations

import numpy as np

__all__ = ["speed_resolved_pairs"]


def speed_resolved_pairs(
    op_load_n: np.ndarray, op_alpha: np.ndarray, op_speed_m_s: np.ndarray
) -> list[tuple[float, float]]:
    """The (load [N], amplitude fraction) pairs with ultrasound pulled at two or more
    distinct speeds, from a dataset's operating points (one entry per distinct load,
    amplitude fraction and speed [m/s]); sorted."""
    speeds: dict[tuple[float, float], set[float]] = {}
    for n, a, v in zip(
        np.asarray(op_load_n, float).tolist(),
        np.asarray(op_alpha, float).tolist(),
        np.asarray(op_speed_m_s, float).tolist(),
        strict=True,
    ):
        if a > 0.0:
            speeds.setdefault((n, a), set()).add(v)
    return sorted(pair for pair, vs in speeds.items() if len(vs) >= 2)
