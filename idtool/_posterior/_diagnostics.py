"""Convergence diagnostics of an ensemble chain (issue 5).

* acceptance fraction of every walker (the stretch move works best at about 0.2-0.5);
* integrated autocorrelation time tau of every parameter (emcee's estimator on the
  walker-averaged autocorrelation, ``c = 5``; stuck walkers left out), after discarding
  a burn-in of
  ``2 max(tau)`` steps (tau first estimated on the chain's second half);
* effective sample size ``walkers x kept steps / tau``;
* split R-hat (rank-normalised, ArviZ) across walker groups: the walkers are split into
  ``groups`` groups, each group's draws (time-major) treated as one chain, each split in
  two halves in time. Walkers of an ensemble are not independent chains, so groups of
  walkers, not single walkers, are compared.

A chain is converged when the kept part is at least ``50 tau`` long for every parameter
(emcee's advice; shorter chains give unreliable tau estimates) and every R-hat is below
1.01; otherwise :attr:`Diagnostics.steps_needed` says how many more steps to run.
"""

from __future__ import annotations

import dataclasses
import math
import warnings

import numpy as np

__all__ = ["Diagnostics", "diagnose", "import_arviz"]

TAU_FACTOR = 50  # chain length needed, in autocorrelation times
RHAT_MAX = 1.01
BURN_FACTOR = 2  # burn-in, in autocorrelation times


def import_arviz():
    """``import arviz`` without its once-a-day FutureWarning about a coming refactor."""
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message=r"\s*ArviZ is undergoing", category=FutureWarning)
        import arviz

    return arviz


@dataclasses.dataclass(frozen=True)
class Diagnostics:
    """What :func:`diagnose` found; per-parameter arrays follow ``names``."""

    names: tuple[str, ...]
    steps: int
    burn: int
    walkers: int
    acceptance: np.ndarray  # per walker
    tau: np.ndarray
    ess: np.ndarray
    rhat: np.ndarray
    converged: bool
    steps_needed: int
    messages: tuple[str, ...]

    @property
    def kept(self) -> int:
        return self.steps - self.burn

    def to_dict(self) -> dict:
        return {
            "steps": self.steps,
            "burn_in": self.burn,
            "walkers": self.walkers,
            "acceptance_fraction": {
                "mean": float(np.mean(self.acceptance)),
                "min": float(np.min(self.acceptance)),
                "max": float(np.max(self.acceptance)),
            },
            "parameters": {
                n: {"tau": float(t), "ess": float(e), "rhat": float(r)}
                for n, t, e, r in zip(self.names, self.tau, self.ess, self.rhat, strict=True)
            },
            "converged": self.converged,
            "steps_needed": self.steps_needed,
            "messages": list(self.messages),
        }

    def report(self) -> str:
        lines = [
            f"    {self.walkers} walkers x {self.steps} steps, burn-in {self.burn}, "
            f"acceptance {np.mean(self.acceptance):.3f} "
            f"(walkers {np.min(self.acceptance):.2f}-{np.max(self.acceptance):.2f})",
            f"    {'parameter':22s}{'tau':>8s}{'ESS':>9s}{'R-hat':>8s}",
        ]
        for n, t, e, r in zip(self.names, self.tau, self.ess, self.rhat, strict=True):
            lines.append(f"    {n:22s}{t:8.1f}{e:9.0f}{r:8.3f}")
        verdict = "converged" if self.converged else "NOT converged"
        lines.append(f"    {verdict}" + "".join(f"\n    - {m}" for m in self.messages))
        return "\n".join(lines)


def _tau(x: np.ndarray, c: float = 5.0) -> np.ndarray:
    """Integrated autocorrelation time of every column of ``x`` (steps, walkers, ndim).

    emcee's estimator (walker-averaged autocorrelation, automatic window ``c tau``),
    except that a walker that never moved (zero variance: no autocorrelation defined)
    is left out of the average instead of turning it into NaN; with no moving walker
    at all, tau is the chain length.
    """
    from emcee.autocorr import auto_window

    steps, _, ndim = x.shape
    out = np.full(ndim, float(steps))
    if steps < 4:
        return out
    n = 1 << (2 * steps - 1).bit_length()
    centred = x - x.mean(axis=0, keepdims=True)
    f = np.fft.fft(centred, n=n, axis=0)
    acf = np.fft.ifft(f * np.conjugate(f), axis=0)[:steps].real  # (steps, walkers, ndim)
    var = acf[0]
    for j in range(ndim):
        moving = var[:, j] > 0
        if not moving.any():
            continue
        rho = np.mean(acf[:, moving, j] / var[moving, j], axis=1)
        taus = 2.0 * np.cumsum(rho) - 1.0
        out[j] = float(taus[auto_window(taus, c)])
    return out


def split_rhat(x: np.ndarray, groups: int) -> np.ndarray:
    """Rank-normalised split R-hat of every parameter across walker groups."""
    az = import_arviz()
    steps, walkers, ndim = x.shape
    groups = max(2, min(groups, walkers // 2))
    per = walkers // groups
    out = np.empty(ndim)
    for j in range(ndim):
        # (group, step * walker-in-group), time-major so halves split in time
        g = x[:, : groups * per, j].reshape(steps, groups, per).transpose(1, 0, 2)
        with np.errstate(divide="ignore", invalid="ignore"), warnings.catch_warnings():
            # a group that never moved has no within-group variance: R-hat is NaN
            warnings.simplefilter("ignore", RuntimeWarning)
            out[j] = float(az.rhat(g.reshape(groups, steps * per)))
    return out


def diagnose(
    chain: np.ndarray,
    acceptance: np.ndarray,
    names: tuple[str, ...],
    groups: int = 4,
) -> Diagnostics:
    """Diagnostics of ``chain`` (steps, walkers, ndim); module docstring."""
    steps, walkers, _ = chain.shape
    if steps < 8:
        raise ValueError(f"{steps} steps: too short to diagnose")
    tau0 = _tau(chain[steps // 2 :])
    burn = min(math.ceil(BURN_FACTOR * float(np.max(tau0))), steps // 2)
    kept = chain[burn:]
    tau = _tau(kept)
    ess = kept.shape[0] * walkers / tau
    rhat = split_rhat(kept, groups)
    messages = []
    worst = int(np.argmax(tau))
    needed_len = TAU_FACTOR * float(tau[worst])
    steps_needed = max(0, math.ceil(needed_len + BURN_FACTOR * tau[worst] - steps))
    if kept.shape[0] < needed_len:
        messages.append(
            f"the kept chain ({kept.shape[0]} steps) is shorter than {TAU_FACTOR} "
            f"autocorrelation times of {names[worst]} (tau = {tau[worst]:.0f}): run about "
            f"{steps_needed} more steps (idtool sample --resume --steps "
            f"{steps + steps_needed})"
        )
    bad = [n for n, r in zip(names, rhat, strict=True) if not r < RHAT_MAX]
    if bad:
        messages.append(
            f"split R-hat across walker groups above {RHAT_MAX} for {', '.join(bad)}: "
            "the walker groups disagree; run longer"
        )
        steps_needed = max(steps_needed, steps)  # doubling the chain is the usual remedy
    acc = float(np.mean(acceptance))
    if not 0.15 <= acc <= 0.7:
        messages.append(
            f"mean acceptance fraction {acc:.2f} is outside 0.15-0.7: the posterior may be "
            "multimodal or badly scaled"
        )
    return Diagnostics(
        names=tuple(names),
        steps=steps,
        burn=burn,
        walkers=walkers,
        acceptance=np.asarray(acceptance, float),
        tau=tau,
        ess=ess,
        rhat=rhat,
        converged=kept.shape[0] >= needed_len and not bad,
        steps_needed=steps_needed if (kept.shape[0] < needed_len or bad) else 0,
        messages=tuple(messages),
    )
