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

* bulk effective sample size (rank-normalised, ArviZ's ``ess``, each walker a chain).

A chain is converged (:data:`RULE`) when the kept part is at least ``50 tau`` long for
every parameter and the longest tau moved by less than 2% between the kept chain's first
90% and all of it (emcee's recipe: tau re-estimated as the chain grows, stopping when it
is long against tau and tau has settled; shorter chains give unreliable tau estimates),
and the rank-normalised split R-hat is at most 1.01 and the bulk ESS at least 400 for
every parameter (Vehtari et al. 2021, the thresholds ArviZ documents). The settling is
asked of the longest tau, which sets the length the chain needs, not of every
parameter's: one parameter's estimate from the last 10% of the chain has a sampling
spread of 3-10% on the example (32 walkers, 1000-6000 steps), so a per-parameter 2% test
passes by chance and tripled the runs (6400 steps instead of 2000-2400, the longest tau
then 43 against 36-38). Otherwise :attr:`Diagnostics.steps_needed` says about how
many more steps to run. The rule is a function of the chain alone, so a stored chain is
judged the same whether it was sampled to convergence, for a fixed length, or resumed.
"""

from __future__ import annotations

import dataclasses
import math
import warnings

import numpy as np

from idtool._diagnostic import Diagnostic

__all__ = [
    "RULE",
    "STOP_REASONS",
    "Diagnostics",
    "bulk_ess",
    "diagnose",
    "import_arviz",
    "kept_tau",
]

TAU_FACTOR = 50  # chain length needed, in autocorrelation times
TAU_CHANGE_MAX = 0.02  # change of the longest tau over the chain's last 10%, relative to it
TAU_EARLIER = 0.9  # the earlier estimate: on this fraction of the chain
RHAT_MAX = 1.01
ESS_MIN = 400.0  # bulk ESS, each parameter
BURN_FACTOR = 2  # burn-in, in autocorrelation times
RULE = (
    f"kept chain >= {TAU_FACTOR} tau of every parameter, the longest tau changed < "
    f"{100 * TAU_CHANGE_MAX:.0f}% over the last {100 * (1 - TAU_EARLIER):.0f}% of the chain, "
    f"split R-hat <= {RHAT_MAX} and bulk ESS >= {ESS_MIN:.0f} for every parameter"
)


def import_arviz():
    """``import arviz`` without its once-a-day FutureWarning about a coming refactor."""
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message=r"\s*ArviZ is undergoing", category=FutureWarning)
        import arviz

    return arviz


@dataclasses.dataclass(frozen=True)
class Diagnostics:
    """What :func:`diagnose` found; per-parameter arrays follow ``names``.

    ``stopped_by`` says what ended the run: ``"converged"`` (:data:`RULE` met),
    ``"max_steps"``, ``"max_minutes"``, ``"steps"`` (a fixed length asked for) or ``""``
    (a chain diagnosed outside a sampling run).
    """

    names: tuple[str, ...]
    steps: int
    burn: int
    walkers: int
    acceptance: np.ndarray  # per walker
    tau: np.ndarray
    tau_change: np.ndarray  # change of tau over the chain's last 10%, relative to the longest
    ess: np.ndarray  # walkers x kept steps / tau (emcee's)
    ess_bulk: np.ndarray  # rank-normalised bulk ESS (ArviZ), each walker a chain
    rhat: np.ndarray
    converged: bool
    steps_needed: int
    messages: tuple[str, ...]
    stopped_by: str = ""

    @property
    def kept(self) -> int:
        return self.steps - self.burn

    def records(self) -> list[Diagnostic]:
        """The chain's verdict as diagnostics: ``not_converged`` when the rule is not met."""
        if self.converged:
            return []
        stop = STOP_REASONS.get(self.stopped_by, "")
        message = (
            f"the posterior chain did NOT converge ({self.steps} steps"
            + (f", stopped: {stop}" if stop else "")
            + f"; about {self.steps_needed} more needed): "
            + "; ".join(self.messages)
        )
        return [
            Diagnostic(
                "not_converged",
                message,
                steps=self.steps,
                steps_needed=self.steps_needed,
                stopped_by=self.stopped_by,
                slowest=self.slowest,
                tau=float(np.max(self.tau)),
                rhat_max=float(np.max(self.rhat)),
                ess_bulk_min=float(np.min(self.ess_bulk)),
            )
        ]

    @property
    def slowest(self) -> str:
        """The parameter with the longest autocorrelation time."""
        return self.names[int(np.argmax(self.tau))]

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
                n: {
                    "tau": float(t),
                    "tau_change": float(c),
                    "ess": float(e),
                    "ess_bulk": float(eb),
                    "rhat": float(r),
                }
                for n, t, c, e, eb, r in zip(
                    self.names,
                    self.tau,
                    self.tau_change,
                    self.ess,
                    self.ess_bulk,
                    self.rhat,
                    strict=True,
                )
            },
            "rule": RULE,
            "converged": self.converged,
            "stopped_by": self.stopped_by,
            "steps_needed": self.steps_needed,
            "messages": list(self.messages),
        }

    def report(self) -> str:
        lines = [
            f"    {self.walkers} walkers x {self.steps} steps, burn-in {self.burn}, "
            f"acceptance {np.mean(self.acceptance):.3f} "
            f"(walkers {np.min(self.acceptance):.2f}-{np.max(self.acceptance):.2f})",
            f"    {'parameter':22s}{'tau':>8s}{'change':>8s}{'ESS':>9s}{'bulk ESS':>10s}"
            f"{'R-hat':>8s}",
        ]
        for n, t, c, e, eb, r in zip(
            self.names, self.tau, self.tau_change, self.ess, self.ess_bulk, self.rhat, strict=True
        ):
            lines.append(f"    {n:22s}{t:8.1f}{100 * c:7.1f}%{e:9.0f}{eb:10.0f}{r:8.3f}")
        verdict = "converged" if self.converged else "NOT converged"
        lines.append(f"    {verdict} (rule: {RULE})")
        if self.stopped_by:
            lines.append(f"    stopped by: {STOP_REASONS[self.stopped_by]}")
        lines += [f"    - {m}" for m in self.messages]
        return "\n".join(lines)


STOP_REASONS = {
    "converged": "the convergence rule was met",
    "max_steps": "--max-steps reached before the rule was met",
    "max_minutes": "--max-minutes reached before the rule was met",
    "steps": "the fixed length asked for (--steps)",
}


def _tau(x: np.ndarray, c: float = 5.0) -> np.ndarray:
    """Integrated autocorrelation time of every column of ``x`` (steps, walkers, ndim).

    emcee's estimator (walker-averaged autocorrelation, automatic window ``c tau``),
    except that a walker that never moved (zero variance: no autocorrelation defined)
    is left out of the average instead of turning it into NaN; with no moving walker
    at all, tau is the chain length.
    """
    from emcee.autocorr import auto_window
    from scipy.fft import irfft, next_fast_len, rfft

    steps, _, ndim = x.shape
    out = np.full(ndim, float(steps))
    if steps < 4:
        return out
    # Any length >= 2 steps - 1 gives the linear (not circular) autocorrelation; the
    # real transform at a fast length (not the next power of two, as emcee pads) costs a
    # third: on a 40,000-step chain of 16 walkers x 7 parameters the three estimates of
    # each check took 14% of a default run's sampling time
    n = next_fast_len(2 * steps - 1, real=True)
    centred = x - x.mean(axis=0, keepdims=True)
    f = rfft(centred, n=n, axis=0)
    acf = irfft(f * np.conjugate(f), n=n, axis=0)[:steps]  # (steps, walkers, ndim)
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


def kept_tau(chain: np.ndarray) -> tuple[int, np.ndarray, np.ndarray]:
    """Burn-in (``2 max tau``, tau first estimated on the chain's second half, at most half
    the chain), tau of every parameter on the kept part, and the change of each tau over
    the kept chain's last 10% relative to the longest tau."""
    steps = chain.shape[0]
    tau0 = _tau(chain[steps // 2 :])
    burn = min(math.ceil(BURN_FACTOR * float(np.max(tau0))), steps // 2)
    tau = _tau(chain[burn:])
    before = _tau(chain[burn : burn + max(4, int(TAU_EARLIER * (steps - burn)))])
    return burn, tau, np.abs(tau - before) / float(np.max(tau))


def bulk_ess(x: np.ndarray) -> np.ndarray:
    """Rank-normalised bulk ESS (ArviZ) of every parameter of ``x`` (steps, walkers, ndim),
    each walker a chain (as ``arviz.from_emcee`` does)."""
    az = import_arviz()
    out = np.empty(x.shape[-1])
    for j in range(x.shape[-1]):
        with np.errstate(divide="ignore", invalid="ignore"), warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)  # a walker that never moved
            out[j] = float(az.ess(np.ascontiguousarray(x[:, :, j].T), method="bulk"))
    return np.nan_to_num(out, nan=0.0)


def diagnose(
    chain: np.ndarray,
    acceptance: np.ndarray,
    names: tuple[str, ...],
    groups: int = 4,
    stopped_by: str = "",
) -> Diagnostics:
    """Diagnostics of ``chain`` (steps, walkers, ndim); module docstring."""
    steps, walkers, _ = chain.shape
    if steps < 8:
        raise ValueError(f"{steps} steps: too short to diagnose")
    burn, tau, tau_change = kept_tau(chain)
    kept = chain[burn:]
    ess = kept.shape[0] * walkers / tau
    ess_bulk = bulk_ess(kept)
    rhat = split_rhat(kept, groups)
    messages = []
    worst = int(np.argmax(tau))
    needed_len = TAU_FACTOR * float(tau[worst])
    steps_needed = max(0, math.ceil(needed_len + BURN_FACTOR * tau[worst] - steps))
    short = kept.shape[0] < needed_len
    if short:
        messages.append(
            f"the kept chain ({kept.shape[0]} steps) is shorter than {TAU_FACTOR} "
            f"autocorrelation times of {names[worst]} (tau = {tau[worst]:.0f}): run about "
            f"{steps_needed} more steps (idtool sample FIT --resume)"
        )
    moving = not tau_change[worst] < TAU_CHANGE_MAX
    if moving:
        messages.append(
            f"the longest autocorrelation time ({names[worst]}) is still changing: by "
            f"{100 * tau_change[worst]:.1f}% over the last {100 * (1 - TAU_EARLIER):.0f}% of "
            f"the chain (at most {100 * TAU_CHANGE_MAX:.0f}%)"
        )
        steps_needed = max(steps_needed, math.ceil(steps * (1 - TAU_EARLIER)))
    bad = [n for n, r in zip(names, rhat, strict=True) if not r <= RHAT_MAX]
    if bad:
        messages.append(
            f"split R-hat across walker groups above {RHAT_MAX} for {', '.join(bad)}: "
            "the walker groups disagree; run longer"
        )
        steps_needed = max(steps_needed, steps)  # doubling the chain is the usual remedy
    few = [n for n, e in zip(names, ess_bulk, strict=True) if not e >= ESS_MIN]
    if few:
        messages.append(f"bulk ESS below {ESS_MIN:.0f} for {', '.join(few)}")
        lowest = max(float(np.min(ess_bulk)), 1.0)
        steps_needed = max(steps_needed, math.ceil(kept.shape[0] * (ESS_MIN / lowest - 1.0)))
    acc = float(np.mean(acceptance))
    if not 0.15 <= acc <= 0.7:
        messages.append(
            f"mean acceptance fraction {acc:.2f} is outside 0.15-0.7: the posterior may be "
            "multimodal or badly scaled"
        )
    converged = not (short or moving or bad or few)
    return Diagnostics(
        names=tuple(names),
        steps=steps,
        burn=burn,
        walkers=walkers,
        acceptance=np.asarray(acceptance, float),
        tau=tau,
        tau_change=tau_change,
        ess=ess,
        ess_bulk=ess_bulk,
        rhat=rhat,
        converged=converged,
        steps_needed=0 if converged else max(steps_needed, 1),
        messages=tuple(messages),
        stopped_by=stopped_by,
    )
