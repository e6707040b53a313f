"""Checks of the Gauss-Newton intervals against the likelihood itself.

The Gauss-Newton covariance takes the loss as quadratic with curvature ``J^T J``. Where
a parameter is only weakly identified (short ON windows that never reach the ON level,
few loads) the loss can be nearly flat over a range that ``J^T J`` at the optimum does
not see: the second-order terms of the residuals cancel its curvature. The reported
interval is then far too narrow. For every physical parameter this module refits all
the others at both ends of its 95% interval; the rise of ``-2 log L`` there should be
3.84. Where it stays below 1 on a side (far too narrow) or exceeds 3.84^2 (far too
wide: on a one-sided parameter whose Gauss-Newton interval runs off the range's top, its
other end can lie decades beyond the data's), that end is replaced by the profile
likelihood's, found by walking outward in doubling steps until the rise
reaches 3.84 or the parameter's bound (and an end at the bound checked the same way),
and a warning says so.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from idtool._diagnostic import Diagnostic
from idtool._fit._program import run_lm
from idtool._fit._result import Z95, Z_AT_BOUND, FitResult, one_sided, uninformed

__all__ = [
    "Profile",
    "check_intervals",
    "profile_interval",
    "profile_parameter",
    "profile_start",
    "refit_with_fixed",
]

_CHI2_95 = 3.84  # -2 log L rise at the ends of a 95% interval, one parameter
_TOO_FLAT = 1.0  # a rise below this at an end means the interval is far too narrow
# ... and above this, far too wide: on a quadratic profile the end is then at least
# twice as far as the profile's (the mirror of _TOO_FLAT's half)
_TOO_STEEP = _CHI2_95**2
# halvings of the last step of a profile walk: the end to 1/64 of that step
_BISECTIONS = 6
# A refit stops once its Gauss-Newton decrement is below this many residual variances,
# the fit's own test of an optimum (_fit._DECREMENT_AT_OPTIMUM): its -2 log L rise is
# then within 0.01 of the converged one, beside the 3.84 and 1 the checks compare it
# with. With LM's default 1e-8, on 48 traces every refit ran 63-83 steps until its
# damping gave up (a kink of the loss at the OFF switch, since rounded: _fit.py), for
# rises within 0.003 of those at 1e-2, reached in 0-24 steps (check_intervals 10.4 s ->
# 3.4 s).
REFIT_TOL = 1e-2


def refit_with_fixed(
    result: FitResult, i: int, zi: float, z_start=None
) -> tuple[float, np.ndarray]:
    """Refit every parameter but ``i`` (held at ``zi``, internal scale), same noise state.

    Starts from ``z_start`` (default: the optimum) moved along the Gauss-Newton profile
    path (:func:`profile_start`). Returns the rise of ``-2 log L`` over the optimum,
    ``(RSS - RSS_min) / sigma^2``, and the refitted vector (a warm start for the next
    point of a profile).
    """
    z = profile_start(result, i, zi, z_start)
    mask = np.ones(z.size, bool)
    mask[i] = False
    out = run_lm(result.model, z, mask, result.noise_state, 100, REFIT_TOL)
    sigma2 = result.rss / (result.n_data - result.z.size)
    return (2.0 * float(out.loss) - result.rss) / sigma2, np.asarray(out.z)


def profile_start(result: FitResult, i: int, zi: float, z_from=None) -> np.ndarray:
    """Where a refit with parameter ``i`` held at ``zi`` starts: ``z_from`` (default: the
    optimum) with ``z_i`` set to ``zi`` and the others moved by what the quadratic loss
    predicts, ``cov[:, i] / cov[i, i]`` per unit of ``z_i`` (the conditional mean of the
    Gaussian approximation). Along a long correlated valley (Kt with the load-power
    coupling's exponent, +0.98) the others then start near their refitted values instead
    of across the valley: 70-90 LM steps per refit on 48 traces before, most of them
    crawling back along it."""
    z = np.array(result.z if z_from is None else z_from, float)
    column = result.cov_z.column(i)  # (p,): the rest of the matrix is not needed
    if column[i] > 0.0:
        z += column / column[i] * (zi - z[i])
    z[i] = zi
    return z


def _profile_end(
    result: FitResult, i: int, side: float, se: float, z_from: float | None = None
) -> float:
    """Internal-scale point on ``side`` (+1 or -1) where the profile rise reaches 3.84
    (linear interpolation), walking from ``z_from`` (default: the optimum) in doubling
    steps; the bound it walks towards if never (the last step stops at the bound)."""
    z0 = float(result.z[i]) if z_from is None else z_from
    z_prev, d_prev, warm = z0, 0.0, None  # warm: the refit at z_prev, to start from
    step = se
    while side * z_prev < Z_AT_BOUND:
        z_next = min(side * (z0 + side * step), Z_AT_BOUND) * side
        d_next, warm_next = refit_with_fixed(result, i, z_next, warm)
        if d_next >= _CHI2_95:
            # the rise can grow by decades within one doubled step (0.6 to 4500 on a
            # saturation's load scale): halve the bracket before interpolating, each
            # refit from the inner side's solution
            for _ in range(_BISECTIONS):
                z_mid = 0.5 * (z_prev + z_next)
                d_mid, warm_mid = refit_with_fixed(result, i, z_mid, warm)
                if d_mid >= _CHI2_95:
                    z_next, d_next = z_mid, d_mid
                else:
                    z_prev, d_prev, warm = z_mid, d_mid, warm_mid
            return float(np.interp(_CHI2_95, [d_prev, d_next], [z_prev, z_next]))
        z_prev, d_prev, warm = z_next, max(d_next, d_prev), warm_next
        step *= 2.0
    return side * Z_AT_BOUND


def check_intervals(result: FitResult) -> FitResult:
    """``result`` with each physical parameter's 95% interval checked against the
    likelihood (module docstring); replaced by the profile interval where far off."""
    model = result.model
    estimates = dict(result.estimates)
    warnings = list(result.warnings)
    for name in model.physical_names:
        i = model.names.index(name)
        spec = model.params[i]
        se = float(np.sqrt(result.cov_z.diagonal()[i]))
        if not spec.bounded or not se > 0.0:
            continue
        est = estimates[name]
        if est.at_bound:
            estimates[name] = _from_the_bound(result, i, est)
            continue
        # the rise of -2 log L at each Gauss-Newton end, the others refitted (None: that
        # end is the range's bound)
        z_wald = [float(result.z[i]) + side * Z95 * se for side in (-1.0, 1.0)]
        rises = [
            refit_with_fixed(result, i, zi)[0] if abs(zi) < Z_AT_BOUND else None for zi in z_wald
        ]
        off = [r is not None and not _TOO_FLAT <= r <= _TOO_STEEP for r in rises]
        if not any(off):
            continue
        # the profile's end replaces each end that is far off, and an end at the bound
        # (is the profile flat up to it?); an end whose rise is near 3.84 stays. A load
        # scale bounded from below only: its Gauss-Newton lower end, 1.05 N, rose 1.8e7
        # and its upper end ran off the range; the profile's lower end is 4,150 N
        z_ends = [
            _profile_end(result, i, side, se) if bad or r is None else zi
            for side, bad, r, zi in zip((-1.0, 1.0), off, rises, z_wald, strict=True)
        ]
        lo, hi = (float(spec.value(z)) for z in z_ends)
        # a profile that reaches the parameter's bound leaves that side open
        estimates[name] = dataclasses.replace(
            est, ci95=(lo, hi), one_sided=one_sided(z_ends[0], z_ends[1])
        )
        said = " and ".join("(the bound)" if r is None else f"{r:.3g}" for r in rises)
        warnings = [w for w in warnings if not _uninformed_about(w, name)]
        warnings.append(
            Diagnostic(
                "profile_interval",
                f"{name}: the Gauss-Newton 95% interval [{est.ci95[0]:.4g}, "
                f"{est.ci95[1]:.4g}] {spec.unit} does not follow the likelihood: refitting "
                f"the others at its ends, -2 log L rises {said} (3.84 expected); the "
                f"profile-likelihood interval [{lo:.4g}, {hi:.4g}] is reported instead",
                parameter=name,
                wald_ci95=est.ci95,
                profile_ci95=(lo, hi),
            )
        )
        if (weak := uninformed(spec, lo, hi)) is not None:
            warnings.append(weak)
    return dataclasses.replace(result, estimates=estimates, warnings=warnings)


def _uninformed_about(warning: str, name: str) -> bool:
    """True for the fit's "uninformed" warning about ``name`` (from its Gauss-Newton
    interval: the profile's replaces it)."""
    code = getattr(warning, "code", None)
    values = getattr(warning, "values", {})
    return code == "uninformed" and values.get("parameter") == name


def _from_the_bound(result: FitResult, i: int, est):
    """A parameter at a bound of its range (the data push it there): its Gauss-Newton
    interval is meaningless (the transform is flat there), and the data bound it on the
    other side only. That end is where the profile, walking inward from the bound in
    doubling steps of 0.25 on the internal scale, rises by 3.84; the estimate is then
    stated one-sided (``Kt < 2e6 N/m``), or over its whole range if it never rises."""
    spec = result.model.params[i]
    inward = -1.0 if result.z[i] > 0.0 else 1.0
    # from the edge of the bound (beyond it the transform is flat: the same model)
    z_end = _profile_end(result, i, inward, 0.25, z_from=-inward * Z_AT_BOUND)
    end = float(spec.value(z_end))
    bound = spec.hi if inward < 0.0 else spec.lo
    lo, hi = sorted((float(bound), end))
    reached = abs(z_end) < Z_AT_BOUND
    side = ("upper" if inward > 0.0 else "lower") if reached else ""
    return dataclasses.replace(est, ci95=(lo, hi), one_sided=side)


@dataclasses.dataclass(frozen=True)
class Profile:
    """Profile likelihood of one parameter: values, -2 log L rise, 95% interval."""

    name: str
    values: np.ndarray
    delta: np.ndarray
    ci95: tuple[float, float]


def profile_parameter(result: FitResult, name: str, n_points: int = 9) -> Profile:
    """Profile likelihood: fix ``name`` on a grid, refit all the others (same AR(1)).

    The grid spans +-3 standard errors on the internal scale; the 95% interval is where
    the rise of -2 log L (``(RSS - RSS_min) / sigma^2``) stays below 3.84.
    """
    model = result.model
    i = model.names.index(name)
    se = float(np.sqrt(result.cov_z.diagonal()[i]))
    grid = result.z[i] + se * np.linspace(-3.0, 3.0, n_points)
    delta = np.empty(n_points)
    mid = n_points // 2
    # Walk outward from the optimum in both directions, each refit starting from its
    # neighbour's solution: a handful of LM steps per point instead of a cold start.
    for order in (range(mid, n_points), range(mid, -1, -1)):
        z = None
        for j in order:
            delta[j], z = refit_with_fixed(result, i, grid[j], z)
    values = [float(model.params[i].value(float(zi))) for zi in grid]
    v, d = np.array(values), delta
    return Profile(name, v, d, profile_interval(v, d))


def profile_interval(v: np.ndarray, d: np.ndarray, level: float = 3.84) -> tuple[float, float]:
    """Where the profile crosses ``level`` on each side of its minimum (linear
    interpolation); the grid's end if it never does (the interval is then open)."""
    m = int(np.argmin(d))
    lo, hi = float(v[0]), float(v[-1])
    for j in range(m, 0, -1):
        if d[j - 1] >= level:
            lo = float(np.interp(level, [d[j], d[j - 1]], [v[j], v[j - 1]]))
            break
    for j in range(m, v.size - 1):
        if d[j + 1] >= level:
            hi = float(np.interp(level, [d[j], d[j + 1]], [v[j], v[j + 1]]))
            break
    return lo, hi
