"""``fit-law --posterior``: an emcee run over the fit's own likelihood.

The likelihood is the fit's: Gaussian force residuals (AR(1) innovations when the fit
whitened them), the noise sd held at the fit's estimate. Priors: uniform in the log of
each positive parameter over its range (a ``log`` :class:`~idtool._model._params.Param`),
uniform in value for the initial-state fraction. Walkers start in a small ball around
the optimum (the Gauss-Newton covariance, shrunk); the first third of the steps is
discarded. A short run for a look at the posterior's shape (a parameter the series does
not inform spreads over its range), not a converged-chain certificate: the integrated
autocorrelation time is reported beside the steps, to judge that.
"""

from __future__ import annotations

import functools
import math

import jax
import jax.numpy as jnp
import numpy as np

from idtool._lawfit._problem import Data, Model

__all__ = ["sample_posterior"]


@functools.partial(jax.jit, static_argnums=0)
def _log_prob(model: Model, data: Data, z, phi, sigma2):
    def one(zz):
        r = model.residuals(data, zz, phi)
        loglik = -0.5 * (r @ r) / sigma2
        prior = 0.0
        for k, p in enumerate(model.params):
            prior += p.log_jacobian(zz[k])
            if p.kind == "log":
                prior -= jnp.log(p.value(zz[k]))
        return loglik + prior

    return jax.vmap(one)(z)


def sample_posterior(fit, *, seed: int = 0, steps: int = 1500) -> dict:
    """Sample the posterior of a :class:`~idtool._lawfit._result.SeriesFit`'s
    parameters; returns each physical parameter's median and 95% interval, the
    acceptance fraction and the autocorrelation times."""
    import emcee

    problem, opt = fit.problem, fit.optimum
    p = opt.z.size
    walkers = max(4 * p, 16)
    rng = np.random.default_rng(seed)
    cov = np.where(np.isfinite(opt.cov_z), opt.cov_z, 0.0)
    sd = np.sqrt(np.clip(np.diag(cov), 1e-12, 1.0))
    start = opt.z + 0.1 * sd * rng.standard_normal((walkers, p))

    def log_prob(z):
        out = _log_prob(problem.model, problem.data, jnp.asarray(z), opt.phi, opt.sigma2)
        return np.asarray(out)

    sampler = emcee.EnsembleSampler(walkers, p, log_prob, vectorize=True)
    sampler.random_state = np.random.RandomState(seed).get_state()  # its own draws
    sampler.run_mcmc(start, steps, progress=False)
    chain = sampler.get_chain(discard=steps // 3, flat=True)
    try:
        tau = sampler.get_autocorr_time(discard=steps // 3, quiet=True)
    except Exception:  # emcee raises on chains too short to estimate it
        tau = np.full(p, math.nan)
    rows = {}
    for k in range(problem.n_physical):
        param = problem.params[k]
        values = np.asarray(param.value(chain[:, k]))
        q = np.percentile(values, [2.5, 50.0, 97.5])
        rows[param.name] = {"median": q[1], "q2.5": q[0], "q97.5": q[2]}
    rows = {k: {a: float(b) for a, b in v.items()} for k, v in rows.items()}
    return {
        "parameters": rows,
        "walkers": walkers,
        "steps": steps,
        "discarded": steps // 3,
        "acceptance_fraction": float(np.mean(sampler.acceptance_fraction)),
        "autocorrelation_time_steps": [None if not math.isfinite(t) else float(t) for t in tau],
        "noise_sd_n": fit.noise_sd_n,
    }
