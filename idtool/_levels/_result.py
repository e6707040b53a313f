"""What a fit of a steady-state friction table found: :class:`LevelsFit`, its text
report, predictions with bands, ``fit.json`` and the figure of FR against speed."""

from __future__ import annotations

import dataclasses
import json
import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from idtool._atomic import atomic_file, atomic_output_dir, write_text_atomic
from idtool._errors import IdtoolError
from idtool._fit._result import Estimate
from idtool._fit._run import ChoiceWeight
from idtool._lawfit._profile import Side
from idtool._lawfit._result import estimate_from_sides
from idtool._levels._choice import pool
from idtool._levels._estimate import SD_FLOOR, SD_NAMES, Optimum, _cov, _data
from idtool._levels._free import CouplingCheck
from idtool._levels._model import LevelsModel
from idtool._levels._plan import LevelsPlan, plan_rows
from idtool._levels._sample import LevelsPosterior, sample_table
from idtool._posterior._record import PosteriorRecord
from idtool._posterior._runner import MAX_MINUTES, MAX_STEPS
from idtool._posterior._store import write_posterior
from idtool._version import __version__

__all__ = ["SCHEMA_VERSION", "LevelsFit", "LevelsPrediction"]

SCHEMA_VERSION = "1"
FIT_JSON, REPORT_TXT, FIGURE = "fit.json", "report.txt", "fr_vs_speed.png"
CHAIN_H5, POSTERIOR_NC, SAMPLE_JSON, REPORT_SAMPLE_TXT = (
    "chain.h5", "posterior.nc", "sample.json", "report_sample.txt",
)  # fmt: skip
# what 'idtool sample' writes into a table fit's folder (the figure redrawn)
POSTERIOR_FILES = (CHAIN_H5, POSTERIOR_NC, SAMPLE_JSON, REPORT_SAMPLE_TXT)
# A prediction moved by more than this (relative FR) along a direction of the
# parameters the table does not inform is not bounded by the data.
UNPINNED_FR = 0.01


@dataclasses.dataclass(frozen=True)
class LevelsPrediction:
    """Friction ratios predicted at operating points, with 95% bands.

    Attributes:
        load_n, amplitude_m, speed_m_s, frequency_hz: the points (arrays of one shape).
        fr: the model's FR at the estimate [-].
        mean_band: ``(lo, hi)`` of FR at a new condition: the parameters' uncertainty
            (and FR at the interval ends of those the table leaves open) and the model
            discrepancy [-].
        next_band: ``(lo, hi)`` of the next measurement: plus the pull-to-pull scatter.
        pinned: False where the table does not bound the prediction (it moves along a
            direction of the parameters the data do not inform); its bands are NaN.
    """

    load_n: np.ndarray
    amplitude_m: np.ndarray
    speed_m_s: np.ndarray
    frequency_hz: np.ndarray
    fr: np.ndarray
    mean_band: tuple[np.ndarray, np.ndarray]
    next_band: tuple[np.ndarray, np.ndarray]
    pinned: np.ndarray

    def to_rows(self) -> list[dict[str, Any]]:
        """One dict per point (SI units), for JSON and tables."""
        out = []
        for i in range(self.fr.size):
            out.append(
                {
                    "normal_load_n": float(self.load_n.flat[i]),
                    "amplitude_m": float(self.amplitude_m.flat[i]),
                    "sliding_speed_m_s": float(self.speed_m_s.flat[i]),
                    "vibration_frequency_hz": float(self.frequency_hz.flat[i]),
                    "fr": float(self.fr.flat[i]),
                    "fr_mean_ci95": [float(b.flat[i]) for b in self.mean_band],
                    "fr_next_ci95": [float(b.flat[i]) for b in self.next_band],
                    "pinned": bool(self.pinned.flat[i]),
                }
            )
        return out


@dataclasses.dataclass(frozen=True)
class LevelsFit:
    """Kt, mu and the coupling fitted to a steady-state friction table
    (:func:`idtool.fit_levels`).

    Attributes:
        model: the table and the physical model (law, coupling, direction).
        optimum: estimate, covariance, sds, uninformed directions.
        estimates: each physical parameter's :class:`~idtool.Estimate` by name.
        sides: each parameter's interval ends and how they were found.
        ends: each parameter's theta refitted at its interval's ends (2, k), internal.
        warnings: what the reader must know (unpinned parameters, misfit).
        notes: facts of the design (no repeats: scatter and discrepancy summed).
        seconds: wall time of the fit [s].
        seed: of the multi-start.
        posterior: the posterior once sampled (:meth:`sample`) or read back with the
            fit (:func:`idtool.load_levels_fit`); its draws then give the predictions.
        ranking: after a model choice (``coupling="auto"``, ``direction="auto"``) every
            model's BIC and weight, this one first (empty otherwise).
        alternates: the other models of BIC weight >= 0.001, in the ranking's order:
            the predictions average them with this one by weight.
        coupling_check: the coupling law's shape against free slip amplitudes
            (:mod:`idtool._levels._free`), where the table has more load-amplitude
            points than the law has parameters; None otherwise.
    """

    model: LevelsModel
    optimum: Optimum
    estimates: dict[str, Estimate]
    sides: dict[str, tuple[Side, Side]]
    ends: dict[str, np.ndarray]
    warnings: tuple[str, ...]
    notes: tuple[str, ...]
    seconds: float
    seed: int = 0
    posterior: LevelsPosterior | None = dataclasses.field(default=None, compare=False)
    # coupling="auto" / direction="auto": every model's BIC and weight, this one first,
    # and the others kept for the predictions (BIC weight >= MIN_LAW_WEIGHT), in order
    ranking: tuple[ChoiceWeight, ...] = ()
    alternates: tuple[LevelsFit, ...] = dataclasses.field(default=(), compare=False)
    coupling_check: CouplingCheck | None = None

    @property
    def table(self):
        return self.model.table

    @property
    def fitted_fr(self) -> np.ndarray:
        """The model's FR at every row of the table [-]."""
        n = self.table.n_rows
        return np.exp(np.asarray(self.model.log_levels(self.optimum.theta))[n:])

    def predict(
        self,
        load_n,
        speed_m_s,
        *,
        amplitude_m=None,
        amplitude_fraction=None,
        frequency_hz=None,
    ) -> LevelsPrediction:
        """FR at loads [N], speeds [m/s] and amplitudes (in metres, or as fractions of
        the table's reference amplitude), broadcast together; ``frequency_hz`` [Hz]
        defaults to the table's (the first row's). Bands from the parameters'
        covariance (delta method on log FR) and the discrepancy sd; the next
        measurement's adds the scatter sd; both reach FR at the interval ends of each
        parameter the table does not bound on both sides (the others refitted there).
        A point is not pinned (NaN bands) where FR moves by more than 1% per unit of
        the internal scale along a direction the table does not inform. After a model
        choice (``coupling="auto"``, ``direction="auto"``) the models kept are averaged
        by their BIC weights (:func:`idtool._levels._choice.pool`)."""
        own = self._predict_own(
            load_n, speed_m_s, amplitude_m=amplitude_m,
            amplitude_fraction=amplitude_fraction, frequency_hz=frequency_hz,
        )  # fmt: skip
        if not self.alternates:
            return own
        # the alternates are the ranking's next entries (best first, those kept)
        parts = [own] + [
            a._predict_own(
                load_n, speed_m_s, amplitude_m=amplitude_m,
                amplitude_fraction=amplitude_fraction, frequency_hz=frequency_hz,
            )
            for a in self.alternates
        ]  # fmt: skip
        weights = [w.bic_weight for w in self.ranking[: len(parts)]]
        fr, mean_band, next_band = pool(
            weights, [p.fr for p in parts], [p.mean_band for p in parts],
            [p.next_band for p in parts],
        )  # fmt: skip
        pinned = np.all([p.pinned for p in parts], axis=0)
        return dataclasses.replace(
            own, fr=fr, mean_band=mean_band, next_band=next_band, pinned=pinned
        )

    def _predict_own(
        self, load_n, speed_m_s, *, amplitude_m=None, amplitude_fraction=None, frequency_hz=None
    ) -> LevelsPrediction:
        """:meth:`predict` of this model alone."""
        t = self.table
        if (amplitude_m is None) == (amplitude_fraction is None):
            raise ValueError("give amplitude_m or amplitude_fraction")
        if amplitude_m is None:
            amplitude_m = np.asarray(amplitude_fraction, float) * t.reference_amplitude_m
        f = t.vibration_frequency_hz[0] if frequency_hz is None else frequency_hz
        n, a, v, f = np.broadcast_arrays(
            *(np.asarray(x, float) for x in (load_n, amplitude_m, speed_m_s, f))
        )
        alpha = a / t.reference_amplitude_m
        if self.posterior is not None:
            return self._predict_posterior(n, a, v, f)
        import jax

        theta = self.optimum.theta
        fr = np.asarray(self.model.fr_at(theta, n, alpha, v, f))
        jac = np.asarray(jax.jacfwd(self.model.fr_at)(theta, n, alpha, v, f)).reshape(fr.size, -1)
        jl = jac / np.maximum(fr.reshape(-1, 1), 1e-300)  # d log FR / d theta
        var = np.einsum("ik,kl,il->i", jl, self.optimum.cov_theta, jl).reshape(fr.shape)
        sds = self.optimum.sds
        mean_sd = np.sqrt(var + sds["discrepancy_fr"] ** 2)
        next_sd = np.sqrt(mean_sd**2 + sds["scatter_fr"] ** 2)
        null = self.optimum.null
        moved = np.max(np.abs(jl @ null), axis=1) if null.shape[1] else np.zeros(fr.size)
        pinned = (moved <= UNPINNED_FR).reshape(fr.shape)
        # the bands reach FR at the interval ends of each parameter the table does not
        # bound on both sides (the others refitted there): the covariance alone misses
        # a direction the data leave open that is flat at the estimate (a load scale
        # far above every load of the table)
        low, high = fr.copy(), fr.copy()
        for name, e in self._law_estimates().items():
            if e.one_sided or e.weakly_identified:
                for theta_end in self.ends[name]:
                    at_end = np.asarray(self.model.fr_at(theta_end, n, alpha, v, f))
                    low, high = np.minimum(low, at_end), np.maximum(high, at_end)

        def band(sd):
            lo = np.minimum(fr * np.exp(-1.96 * sd), low)
            hi = np.maximum(fr * np.exp(1.96 * sd), high)
            return np.where(pinned, lo, np.nan), np.where(pinned, hi, np.nan)

        return LevelsPrediction(n, a, v, f, fr, band(mean_sd), band(next_sd), pinned)

    def _law_estimates(self) -> dict[str, Estimate]:
        """The estimates as the law states them: a parameter the coupling check widened
        (its law-free ends, where the table rejects the law) with the law's own sides,
        which its predictions read (the law's discrepancy carries the misfit)."""
        check = self.coupling_check
        if check is None or not check.widened:
            return self.estimates
        out = dict(self.estimates)
        for name, (lo, hi) in check.law_sides.items():
            j = self.model.names.index(name)
            out[name] = estimate_from_sides(
                self.model.params[j], float(self.optimum.theta[j]), math.inf, lo, hi
            )
        return out

    def _predict_posterior(self, n, a, v, f, seed: int = 0) -> LevelsPrediction:
        """FR from the posterior's draws: the median of the model's FR, the mean band
        with each draw's discrepancy, the next measurement's with its scatter too
        (2.5 and 97.5 percentiles; normal draws seeded by ``seed``)."""
        import jax

        assert self.posterior is not None
        theta, sds = self.posterior.thetas(self.model)
        alpha = a / self.table.reference_amplitude_m
        fr_d = np.asarray(
            jax.vmap(lambda th: self.model.fr_at(th, n.ravel(), alpha.ravel(), v.ravel(),
                                                 f.ravel()))(theta)
        )  # fmt: skip
        rng = np.random.default_rng(seed)
        mean = fr_d * np.exp(sds["discrepancy_fr"][:, None] * rng.standard_normal(fr_d.shape))
        nxt = mean * np.exp(sds["scatter_fr"][:, None] * rng.standard_normal(fr_d.shape))

        def band(x):
            lo, hi = np.percentile(x, [2.5, 97.5], axis=0)
            return lo.reshape(n.shape), hi.reshape(n.shape)

        fr = np.median(fr_d, axis=0).reshape(n.shape)
        return LevelsPrediction(n, a, v, f, fr, band(mean), band(nxt), np.ones(n.shape, bool))

    # --------------------------------------------------------------------- plan
    def plan(
        self,
        goal: str = "band",
        n_rows: int = 6,
        *,
        at: Sequence[tuple[float, float, float]] | None = None,
        half_width: float = 0.01,
        rel: float = 0.05,
        loads_n: tuple[float, float] | None = None,
        amplitudes_m: tuple[float, float] | None = None,
        speeds_m_s: tuple[float, float] | None = None,
        grid: int = 5,
    ) -> LevelsPlan:
        """The next ``n_rows`` measurements of the table for a goal
        (:mod:`idtool._levels._plan`): ``band`` (the largest FR band half-width [FR]
        over the conditions ``at``, each (load [N], amplitude [m], speed [m/s]), down to
        ``half_width``) or ``parameters`` (every physical parameter to relative sd
        ``rel``); candidates on a geometric grid of ``grid`` loads x amplitudes x
        speeds within the ranges given (default the table's). From the linearised
        model at the fit's estimate (the best model's after a model choice)."""
        _, meas, kmat = _data(self.model)
        sds = self.optimum.sds
        floor = [max(sds["scatter_mu"], SD_FLOOR), max(sds["scatter_fr"], SD_FLOOR), 0.0]
        plan = plan_rows(
            self.model, np.asarray(self.optimum.theta, float), _cov(meas, kmat, np.array(floor)),
            sds, goal, n_rows, at=at, half_width=half_width, rel=rel, loads_n=loads_n,
            amplitudes_m=amplitudes_m, speeds_m_s=speeds_m_s, grid=grid,
        )  # fmt: skip
        loose = [n for n, e in self._law_estimates().items() if e.one_sided or e.weakly_identified]
        if loose:
            # predict widens its bands to these parameters' interval ends; the linear
            # model cannot (a seed of tests/test_levels_plan.py's table: 0.056 for 0.076)
            note = (
                f"{', '.join(loose)} not bounded on both sides: predictions widen their "
                "bands to the interval ends, the linearised values here do not (they "
                "can understate the band)"
            )
            plan = dataclasses.replace(plan, notes=(*plan.notes, note))
        if self.alternates:
            best = self.ranking[0]
            note = (
                f"planned on the best model ({best.name}, BIC weight {best.bic_weight:.2f}) "
                f"alone: the fit's predictions average {1 + len(self.alternates)} models "
                "by weight, so its band now can differ from the plan's"
            )
            plan = dataclasses.replace(plan, notes=(*plan.notes, note))
        return plan

    # ---------------------------------------------------------------- posterior
    def sample(
        self,
        walkers: int | None = None,
        steps: int | None = None,
        seed: int | None = None,
        priors=None,
        chain_path: str | Path | None = None,
        resume: bool = False,
        progress: bool = False,
        checkpoint_s: float = 20.0,
        max_steps: int = MAX_STEPS,
        max_minutes: float = MAX_MINUTES,
    ) -> LevelsPosterior:
        """Sample the posterior of the table's likelihood (the one the fit maximises)
        with emcee, by default until converged (:mod:`idtool._levels._sample`; the
        arguments as :meth:`idtool.Fit.sample`'s). The fit keeps it as
        :attr:`posterior`: its predictions (and the speed figure) then come from the
        draws. Returns it."""
        record = sample_table(
            self.model, self.optimum, self.sides, walkers=walkers, steps=steps, seed=seed,
            priors=priors, chain_path=chain_path, resume=resume, progress=progress,
            checkpoint_s=checkpoint_s, max_steps=max_steps, max_minutes=max_minutes,
        )  # fmt: skip
        post = LevelsPosterior.of(record)
        object.__setattr__(self, "posterior", post)  # the fit's own, as Fit.sample's
        return post

    def sample_report(self) -> str:
        """The posterior's text report: the estimates against the posterior intervals,
        and the chain's diagnostics."""
        post = self.posterior
        if post is None:
            raise IdtoolError("no posterior: sample first (idtool sample FITDIR)")
        lines = [
            f"idtool {__version__}: posterior of the table fit {self.table.name} "
            f"({post.describe()}, {post.n_draws} draws kept)",
            "",
            "[[Posterior]] median and 95% interval (fit: estimate and its interval)",
        ]
        summary = post.summary()
        for name, s in summary.items():
            lo, hi = s["ci95"]
            e = self.estimates.get(name)
            fit_text = f"   fit {e.estimate:.4g} {e.statement}" if e is not None else ""
            lines.append(f"  {name:15s} {s['median']:<11.4g} [{lo:.4g}, {hi:.4g}]{fit_text}")
        check = self.coupling_check
        if check is not None and check.widened:
            lines += [
                "",
                "[[Warning]] the table rejects the "
                f"{check.coupling} law's shape (p = {check.p_value:.2g} against free slip "
                f"amplitudes): the posterior of {', '.join(check.widened)} is the law's, "
                "conditional on that shape; the fit's interval, widened to the law-free "
                "one, is what the table says",
            ]
        record = post.record
        if record is not None:
            lines += ["", "[[Convergence]]", record.diagnostics.report()]
        else:
            d = post.diagnostics
            lines += ["", "[[Convergence]]", f"    {post.describe()}; {d.get('rule', '')}"]
        return "\n".join(lines)

    def save_posterior(self, out: str | Path, command: list[str] | None = None) -> str:
        """Write the posterior into the fit's folder ``out``: ``posterior.nc`` (ArviZ
        InferenceData), ``sample.json`` (summary, diagnostics, timing),
        ``report_sample.txt`` and, when the table spans speeds, ``fr_vs_speed.png``
        redrawn with the posterior's bands; each file atomically. Returns the report."""
        post = self.posterior
        if post is None or post.record is None:
            raise IdtoolError("no posterior sampled in this session: sample first")
        out = Path(out)
        record: PosteriorRecord = post.record
        extra = {"kind": "levels", "fit_seed": self.seed, "command": command}
        write_posterior(record, out / POSTERIOR_NC, extra=extra)
        report = self.sample_report()
        doc = {
            "kind": "levels",
            "idtool_version": __version__,
            "summary": post.summary(),
            "diagnostics": post.diagnostics,
            "timing": post.timing,
            "seed": post.seed,
            "priors": {n: p.to_dict() for n, p in record.priors.items()},
            "command": command,
        }
        write_text_atomic(out / SAMPLE_JSON, json.dumps(doc, indent=1) + "\n")
        write_text_atomic(out / REPORT_SAMPLE_TXT, report + "\n")
        if self.spans_speeds:
            with atomic_file(out / FIGURE) as tmp:
                self.plot_speed(tmp)
        return report

    # ------------------------------------------------------------------ outputs
    def report(self) -> str:
        """The text report: data, model, estimates with their statements, sds,
        warnings, and the table against the fit."""
        t, m, o = self.table, self.model, self.optimum
        lines = [
            f"idtool {__version__}: fit of a steady-state friction table (kind: levels)",
            f"dataset   {t.name} ({t.material}); {t.n_rows} rows, "
            f"{t.operating_points[1].size} conditions; friction as {t.friction}",
        ]
        if t.source:
            lines.append(f"source    {t.source}")
        lines += [
            f"model     law {m.law}, coupling {m.coupling}, direction {m.direction}; "
            f"amplitude fraction = amplitude / {t.reference_amplitude_m * 1e6:g} um",
        ]
        if m.spec.drift:
            hours = float(np.ptp(t.time_s)) / 3600.0
            lines.append(
                f"drift     the horn's output drifts linearly over the rows' times "
                f"({hours:.3g} h, horn_drift); every estimate and prediction is at the "
                "campaign's middle"
            )
        if self.ranking:
            lines += [
                "",
                "[[Models compared]] BIC, its excess over the best, weight exp(-delta/2) "
                "(the predictions average those above 0.001)",
            ]
            for w in self.ranking:
                lines.append(
                    f"  {w.name:24s} BIC {w.bic:10.2f}  delta {w.bic - self.ranking[0].bic:8.2f}"
                    f"  weight {w.bic_weight:.3f}"
                )
        lines += [
            "",
            "[[Estimates]] (95% intervals: Wald, checked against the profile likelihood)",
        ]
        for name, e in self.estimates.items():
            lines.append(f"  {name:15s} {e.estimate:<12.5g} {e.unit:4s} {e.statement}")
        check = self.coupling_check
        if check is not None:
            lines += [
                "",
                f"[[Coupling law's shape]] against a free slip amplitude at each of "
                f"{check.points} load-amplitude points ({check.resolved} at two or more speeds)",
                f"  -2 log likelihood ratio {check.statistic:.2f}, F on {check.dof} and "
                f"{check.residual_dof} degrees of freedom, p = {check.p_value:.3g}: "
                + ("rejected at 5%, intervals widened" if check.rejected else "not rejected"),
            ]
            for name, (lo, hi) in check.free.items():
                e = estimate_from_sides(m.params[m.names.index(name)], 0.0, math.inf, lo, hi)
                lines.append(f"  {name:15s} law-free {e.statement}")
        lines += [
            "",
            f"[[Scatter and discrepancy]] (relative sds, {'REML' if o.restricted else 'ML'})",
        ]
        for name in SD_NAMES:
            tag = f"{100 * o.sds[name]:.2f}%" if o.sds[name] > 0 else "not estimated"
            d = o.discrepancy
            if name == "discrepancy_fr" and d is not None:
                tag += (
                    f"  (REML {100 * d.reml:.2f}%, 95% {100 * d.ci95[0]:.2f}-"
                    f"{100 * d.ci95[1]:.2f}%: its likelihood integrated, the bands' and "
                    "intervals' sd)"
                )
            lines.append(f"  {name:15s} {tag}")
        lines += ["", "[[Rows]] measured and fitted friction ratio"]
        fit_fr = self.fitted_fr
        for i in range(t.n_rows):
            lines.append(
                f"  N {t.normal_load_n[i]:8.4g} N  a {t.amplitude_m[i] * 1e6:7.3g} um  "
                f"v {t.sliding_speed_m_s[i] * 1e3:7.4g} mm/s  "
                f"f {t.vibration_frequency_hz[i] / 1e3:6.4g} kHz"
                f"  FR {t.friction_ratio[i]:.3f}  fit {fit_fr[i]:.3f}"
            )
        if self.notes:
            lines += ["", "[[Notes]]", *(f"  - {x}" for x in self.notes)]
        if self.warnings:
            lines += ["", "[[Warnings]]", *(f"  - {x}" for x in self.warnings)]
        return "\n".join(lines)

    fit_report = report

    def to_json(self, command: list[str] | None = None) -> dict[str, Any]:
        """``fit.json``'s document; ``command``: the command line that made it."""
        t, m, o = self.table, self.model, self.optimum
        estimates = {}
        for name, e in self.estimates.items():
            lo, hi = self.sides[name]
            estimates[name] = {
                "value": e.estimate,
                "unit": e.unit,
                "std_error": None if not math.isfinite(e.std_error) else e.std_error,
                "ci95": list(e.ci95),
                "one_sided": e.one_sided,
                "statement": e.statement,
                "interval_method": [lo.method, hi.method],
            }
        fit_fr = self.fitted_fr
        return {
            "schema_version": SCHEMA_VERSION,
            "kind": "levels",
            "idtool_version": __version__,
            "dataset": {
                "name": t.name,
                "material": t.material,
                "source": t.source,
                "path": None if t.path is None else str(Path(t.path).resolve()),
                "sha256": t.sha256,
                "friction": t.friction,
                "n_rows": t.n_rows,
                "reference_amplitude_m": t.reference_amplitude_m,
            },
            "model": {"law": m.law, "coupling": m.coupling, "direction": m.direction},
            "estimates": estimates,
            "sds": {
                **o.sds,
                "method": "REML" if o.restricted else "ML",
                **({} if o.discrepancy is None else {"discrepancy": o.discrepancy.to_json()}),
            },
            "chi2": o.chi2,
            "log_likelihood": o.loglik,
            "theta_internal": [float(x) for x in o.theta],
            "cov_internal": o.cov_theta.tolist(),
            "rows": [
                {"fr": float(t.friction_ratio[i]), "fr_fit": float(fit_fr[i])}
                for i in range(t.n_rows)
            ],
            "warnings": list(self.warnings),
            "notes": list(self.notes),
            "seconds": self.seconds,
            "seed": self.seed,
            "command": command,
            # coupling="auto" / direction="auto": every model's criteria, best first, and
            # the models kept for the predictions (each a document of this form)
            "models_compared": [w.to_dict("model") for w in self.ranking],
            "alternates": [a.to_json(command) for a in self.alternates],
            "coupling_check": None
            if self.coupling_check is None
            else self.coupling_check.to_dict(),
            # what idtool.load_levels_fit rebuilds the fit from (internal scale)
            "state": {
                "sides": {
                    name: [side.to_json() for side in self.sides[name]] for name in self.estimates
                },
                "ends": {name: self.ends[name].tolist() for name in self.estimates},
                "null": o.null.tolist(),
                "active": list(o.active),
                "restricted": o.restricted,
            },
        }

    @property
    def spans_speeds(self) -> bool:
        return np.unique(self.table.sliding_speed_m_s).size > 1

    def save(
        self, out: str | Path, *, force: bool = False, command: list[str] | None = None
    ) -> Path:
        """Write ``fit.json``, ``report.txt`` and, when the table spans speeds,
        ``fr_vs_speed.png`` into the folder ``out``, all or nothing; ``command`` (the
        command line's arguments) is recorded in ``fit.json``."""
        out = Path(out)
        with atomic_output_dir(out, force=force) as tmp:
            (tmp / FIT_JSON).write_text(json.dumps(self.to_json(command), indent=1) + "\n")
            (tmp / REPORT_TXT).write_text(self.report() + "\n")
            if self.spans_speeds:
                self.plot_speed(tmp / FIGURE)
        return out

    def plot_speed(self, path: str | Path) -> Path:
        """FR against sliding speed for each load and amplitude of the table: the
        model's curve, its 95% band at a new condition, the next measurement's, and the
        rows (with their standard errors)."""
        import matplotlib

        matplotlib.use("Agg", force=False)
        import matplotlib.pyplot as plt

        t = self.table
        v = t.sliding_speed_m_s
        speeds = np.geomspace(0.5 * v.min(), 1.5 * v.max(), 60)
        amplitudes = np.unique(t.amplitude_m)[:4]  # one panel each (the first four)
        loads = np.unique(t.normal_load_n)
        fig, axes = plt.subplots(
            1, amplitudes.size, figsize=(3.2 + 3.0 * amplitudes.size, 4.2), dpi=120,
            sharey=True, squeeze=False,
        )  # fmt: skip
        colours = plt.rcParams["axes.prop_cycle"].by_key()["color"]
        se = np.nan_to_num(t.friction_ratio * np.hypot(t.on_se / t.on, t.off_se / t.off))
        for ax, a in zip(axes[0], amplitudes, strict=True):
            for k, n in enumerate(loads):
                rows = (t.normal_load_n == n) & (t.amplitude_m == a)
                if not rows.any():
                    continue
                c = colours[k % len(colours)]
                p = self.predict(n, speeds, amplitude_m=a)
                ax.plot(speeds * 1e3, p.fr, color=c, label=f"{n:g} N")
                ax.fill_between(speeds * 1e3, *p.mean_band, color=c, alpha=0.25, lw=0)
                ax.fill_between(speeds * 1e3, *p.next_band, color=c, alpha=0.10, lw=0)
                ax.errorbar(
                    v[rows] * 1e3, t.friction_ratio[rows], yerr=1.96 * se[rows], fmt="o",
                    color=c, ms=4,
                )  # fmt: skip
            ax.set_xscale("log")
            ax.set_xlabel("sliding speed [mm/s]")
            ax.set_title(f"amplitude {a * 1e6:.3g} um", fontsize=10)
            ax.grid(True, which="both", alpha=0.3)
            ax.legend(fontsize=8, title="normal load", title_fontsize=8)
        axes[0][0].set_ylabel("friction ratio ON / OFF [-]")
        axes[0][0].set_ylim(0.0, 1.1)
        bands = "posterior 95% bands" if self.posterior is not None else "95% bands"
        if self.alternates:
            bands += f"\naveraged over {1 + len(self.alternates)} models by BIC weight"
        fig.suptitle(
            f"{t.name}: {self.model.law}, {self.model.coupling}, {self.model.direction}; {bands}",
            fontsize=9,
        )
        fig.text(
            0.01, 0.01, "dark band: FR at a new condition; light: next measurement", fontsize=7
        )
        fig.tight_layout()
        fig.savefig(path, format="png")
        plt.close(fig)
        return Path(path)
