"""Quantities derived from a fit's parameters (the sdof law's drive force Fe_max), with
their standard errors and 95% intervals by the delta method on the log scale (each is
positive), from the fit's final covariance (a quadratic form on its blocks)."""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np

from idtool._fit._result import Z95, Estimate, FitResult

__all__ = ["derived_estimates"]


def derived_estimates(r: FitResult) -> dict[str, tuple[Estimate, str]]:
    """name -> (estimate, what it is) of every quantity the coupling law derives
    (:meth:`idtool.AbstractCoupling.derived`); empty for the kinematic laws."""
    model = r.model
    a_max = model.data.max_amplitude_m
    z = jnp.asarray(r.z)
    # the values in NumPy: in JAX, op by op, they compiled ~20 one-operation programs in
    # every process, for the kinematic laws too (which derive nothing)
    described = model.coupling_of(model.values(np.asarray(r.z, float))).derived(a_max)
    out: dict[str, tuple[Estimate, str]] = {}
    for name, (value, unit, what) in described.items():

        def log_value(zz, name=name):
            return jnp.log(model.coupling_of(model.values(zz)).derived(a_max)[name][0])

        grad = np.asarray(jax.grad(log_value)(z))
        se_log = math.sqrt(max(r.cov_z.quad(grad), 0.0))
        v = float(value)
        ci = (v * math.exp(-Z95 * se_log), v * math.exp(Z95 * se_log))
        out[name] = (Estimate(name, unit, v, v * se_log, ci), what)
    return out
