"""The public workflow's result: a :class:`Fit` to report, sample, predict and save.

``idtool.fit(dataset) -> Fit`` (:mod:`idtool._entry`) runs what ``idtool fit`` runs;
the :class:`Fit` it returns carries the estimates and their intervals, the text
report, and (after :meth:`Fit.sample`) the posterior. Predictions come from the
posterior when there is one, else from Gaussian draws on the fit's covariance, and say
which (one path: :func:`idtool._posterior._draws.fit_draws`). ``Fit.save`` writes the fit
folder the command line writes, and ``idtool.load_fit`` reads it back into the same
object: both hold a :class:`~idtool._fit._artefact.FitArtefact`, made by one
constructor, so a fit read back behaves as the fresh one. Everything a notebook needs is
here, with no private module in sight.
"""

from __future__ import annotations

import dataclasses
import json
import os
import shutil
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from idtool._atomic import atomic_output_dir
from idtool._data._dataset import Dataset, load_dataset
from idtool._data._select import select_traces
from idtool._data._write import write_dataset
from idtool._diagnostic import Diagnostic
from idtool._errors import IdtoolError
from idtool._fit._artefact import FitArtefact, fit_artefact, state_arrays
from idtool._fit._cov import Covariance
from idtool._fit._folder import FIT_STATE, RESIDUALS_PNG, TRACES_PNG, law_state_file
from idtool._fit._result import Estimate, FitResult
from idtool._fit._run import FitRun
from idtool._fit._store import write_artefact
from idtool._model._benchmodel import BenchModel
from idtool._plan._plan import Plan, plan_pulls
from idtool._posterior._draws import fit_draws, stored_posterior
from idtool._posterior._posterior import Posterior
from idtool._posterior._record import PosteriorRecord
from idtool._posterior._runner import MAX_MINUTES, MAX_STEPS
from idtool._posterior._sample import sample_posterior
from idtool._posterior._store import PosteriorDraws
from idtool._predict._predict import Draws
from idtool._predict._tables import Amplitudes, Predictions, amplitude_table, predict_table
from idtool._predict._validation import Validation, validate
from idtool._provenance import provenance
from idtool._report._fit_text import fit_json, fit_report, plot_fit
from idtool._report._sample_text import write_posterior_outputs

__all__ = ["Fit"]


class Fit:
    """One identified dataset: the chosen model, its estimates, every candidate, and
    the posterior once sampled. Made by :func:`fit` or :func:`load_fit`, which give the
    same object: everything but :attr:`run` and :attr:`result` (the candidates, in
    memory only) comes from its :class:`~idtool._fit._artefact.FitArtefact`, built the
    same way from the documents a fresh fit writes and a loaded one reads.

    Attributes:
        dataset: the :class:`~idtool.Dataset` fitted.
        artefact: the fit as a typed record (:class:`idtool.FitArtefact`).
        model: the chosen :class:`~idtool.BenchModel` (law, coupling, noise model).
        estimates: every parameter's :class:`~idtool.Estimate` (value, standard error,
            95% interval, unit), physical ones first.
        posterior: the :class:`~idtool.Posterior` after :meth:`sample`, else ``None``.
    """

    def __init__(
        self,
        artefact: FitArtefact,
        run: FitRun | None = None,
        folder: Path | None = None,
    ):
        self.artefact = artefact
        self.dataset = artefact.dataset
        self.run = run
        self.folder = folder
        self.posterior: Posterior | None = None

    @classmethod
    def from_run(
        cls,
        dataset: Dataset,
        run: FitRun,
        seconds: float = 0.0,
        command: Sequence[str] | None = None,
    ) -> Fit:
        """The fit of a fresh run: its artefact made from the documents it writes
        (``fit.json`` with ``seconds`` [s], the time the fit took; the report; the state
        of each kept law), so it behaves as the same fit read back does."""
        path = None if dataset.path is None else str(Path(dataset.path).resolve())
        doc = fit_json(run, path, None if command is None else list(command))
        doc["seconds"] = round(seconds, 2)
        return cls(fit_artefact(doc, fit_report(run), dataset, run.data, _states(run)), run)

    # ------------------------------------------------------------------ what it found
    @property
    def model(self) -> BenchModel:
        return self.artefact.model

    @property
    def z(self) -> np.ndarray:
        """The optimum on the internal scale (all parameters, nuisances included)."""
        return self.artefact.chosen.z

    @property
    def cov_z(self) -> Covariance:
        """The covariance of ``z``, kept in the blocks of the fit's normal equations
        (memory linear in the traces): ``.leading(k)`` is the first ``k`` parameters'
        (k, k), ``.diagonal()`` the variances, ``.dense()`` the whole (p, p) matrix; dense
        from a fit folder written before the blocks, with the same methods."""
        return self.artefact.chosen.cov_z

    @property
    def phi(self) -> float:
        return self.artefact.chosen.phi

    @property
    def noise_state(self) -> np.ndarray:
        """The noise model's correlation state (``NOISE_MODELS``; AR(1): ``[phi]``)."""
        return self.artefact.chosen.noise_state

    @property
    def sigma_n(self) -> float:
        return self.artefact.chosen.sigma_n

    @property
    def seconds(self) -> float:
        """The time the fit took [s]."""
        return float(self.artefact.doc.get("seconds", 0.0))

    @property
    def levels(self):
        """The levels model's (free levels, sds), or None (``variability=False``)."""
        return self.artefact.chosen.levels

    @property
    def conditioning(self):
        """What predictions condition the discrepancy on (the traces' own friction
        ratios), or None (``variability=False``)."""
        return self.artefact.chosen.conditioning

    @property
    def estimates(self) -> dict[str, Estimate]:
        return self.artefact.estimates

    @property
    def optima(self) -> list[dict]:
        """The multi-start's distinct optima (``rss``, internal physical ``z``)."""
        return list(self.artefact.optima)

    @property
    def warnings(self) -> list[str]:
        return list(self.artefact.warnings)

    @property
    def notes(self) -> list[str]:
        """What the data let the fit measure (one trace per operating point, ON windows
        too short to settle): facts for the report, not doubts (:attr:`warnings`)."""
        return list(self.artefact.notes)

    @property
    def coupling_laws(self) -> dict[str, dict[str, float | str]]:
        """Each fitted coupling law (best first): its best candidate model's ``key``,
        ``bic``, ``aic`` and Akaike/Schwarz weights (``bic_weight``, ``aic_weight``),
        and the ``state_file`` of each other law predictions average over: several with
        ``coupling="auto"``, else the one law at weight 1."""
        return dict(self.artefact.coupling_laws)

    @property
    def directions(self) -> dict[str, dict[str, float | str]]:
        """Each direction of vibration fitted with ``direction="auto"`` (best first): its
        best candidate's ``key``, ``bic``, ``aic`` and Akaike/Schwarz weights, as
        :attr:`coupling_laws` gives the coupling laws'; empty when one direction was
        fitted."""
        return dict(self.artefact.directions)

    @property
    def result(self) -> FitResult:
        """The chosen model's full fit result (in memory only, not after load_fit)."""
        if self.run is None:
            raise IdtoolError("a fit read back from disk keeps its estimates, not its result")
        return self.run.chosen

    def __repr__(self) -> str:
        phys = ", ".join(f"{n}={self.estimates[n].estimate:.4g}" for n in self.model.physical_names)
        phys += "".join(f", {n}={v:.4g} (fixed)" for n, v in self.model.fixed.items())
        return (
            f"Fit({self.dataset.name!r}, {self.model.law.name}/{self.model.coupling.name}/"
            f"{self.model.noise.name}: {phys})"
        )

    def report(self) -> str:
        """The fit report a person reads (estimates, intervals, correlations, model
        comparison, friction ratio per operating point, warnings)."""
        return self.artefact.report_text

    # ------------------------------------------------------------------ posterior
    def sample(
        self,
        walkers: int | None = None,
        steps: int | None = None,
        seed: int = 0,
        *,
        noise: str | None = None,
        priors: str | os.PathLike | dict | None = None,
        progress: bool = False,
        chain_path: str | os.PathLike | None = None,
        resume: bool = False,
        checkpoint_s: float = 20.0,
        max_steps: int = MAX_STEPS,
        max_minutes: float = MAX_MINUTES,
    ) -> Posterior:
        """Sample the posterior of the shared and noise parameters with emcee (the
        per-trace nuisances integrated out); kept on the fit, so :meth:`predict` uses it
        from then on. Without ``steps`` it samples until the chain has converged (the
        rule in ``Posterior.diagnostics``), bounded by ``max_steps`` and ``max_minutes``;
        ``steps`` runs a fixed length instead. ``walkers``: the ensemble's size (default
        16 on the levels model's posterior, 32 on the traces' own:
        :func:`idtool._posterior._sample.default_walkers`). ``chain_path`` checkpoints
        the chain (``chain.h5``) every ``checkpoint_s`` seconds; ``resume`` continues
        it. The same seed gives the same chain."""
        sampled = sample_posterior(
            self,
            walkers=walkers,
            steps=steps,
            seed=seed,
            noise=noise,
            priors=priors,
            chain_path=chain_path,
            resume=resume,
            progress=progress,
            checkpoint_s=checkpoint_s,
            max_steps=max_steps,
            max_minutes=max_minutes,
        )
        # its predictions average over the coupling laws the fit kept, as the fit's do
        self.posterior = dataclasses.replace(sampled, fit=self.artefact)
        return self.posterior

    def save_posterior(
        self, folder: str | os.PathLike | None = None, command: Sequence[str] | None = None
    ) -> str:
        """Write the posterior's files (``posterior.nc``, ``sample.json``,
        ``report_sample.txt``, ``ppc.png``) into ``folder`` (default: where the fit was
        saved); returns the posterior's text report."""
        if self.posterior is None:
            raise IdtoolError("no posterior yet: call Fit.sample() first")
        where = folder if folder is not None else self.folder
        if where is None:
            raise IdtoolError("the fit is not saved: give a folder (or call Fit.save first)")
        return write_posterior_outputs(self, self.estimates, self.posterior, Path(where), command)

    def draws(self, max_draws: int = 2000, seed: int = 0) -> Draws:
        """Draws of the physical parameters: the posterior's if sampled (in memory or
        ``posterior.nc`` beside a loaded fit), else Gaussian on the fit's covariance."""
        posterior: PosteriorRecord | PosteriorDraws | None = self.posterior
        if posterior is None and self.folder is not None:
            posterior = stored_posterior(self.folder)
        return fit_draws(self.artefact, posterior, max_draws, seed)

    # ------------------------------------------------------------------ predictions
    def predict(
        self,
        load_n: float | Sequence[float],
        amplitude: float | Sequence[float],
        speed_m_s: float | Sequence[float] | None = None,
        *,
        max_draws: int = 2000,
        seed: int = 0,
    ) -> Predictions:
        """Friction ratio FR (median and 95% band) and reduction ``100 (1 - FR)`` [%]
        over the grid loads [N] x commanded amplitude fractions x speeds [m/s] (default
        the fit's speed); warns where the grid leaves the fitted range. Under the
        relaxing ON level FR is the cold horn's, at the window's start, and a note gives
        the rises to its steady state (:mod:`idtool._model._level_model`)."""
        draws = self.draws(max_draws, seed)
        table = predict_table(draws, self.model.data, load_n, amplitude, speed_m_s)
        note = self._steady_state_note()
        if note is None:
            return table
        return dataclasses.replace(table, warnings=(*table.warnings, note))

    def _steady_state_note(self) -> Diagnostic | None:
        """Under the relaxing ON level: what the steady state adds to the cold-horn FR
        (eq. R2 of :mod:`idtool._model._level_model`), from the traces' rises."""
        if not any(g == "on_rise" for g, _, _ in self.model.level.trace_params):
            return None
        values = self.model.values(np.asarray(self.z, float))
        rises = np.atleast_1d(np.asarray(values["on_rise"], float))
        tau = float(values["on_relax_time_s"])
        return Diagnostic(
            "drift_modelled",
            "the friction ratios are the cold horn's, at the ON window's start (the relaxing "
            f"ON level): towards steady state, with time constant {tau:.2g} s, the traces' "
            f"ON levels rose by {100 * np.median(rises):.0f}% of themselves (median; "
            f"{100 * rises.min():+.0f}% to {100 * rises.max():+.0f}%), FR_ss = min(FR (1 + "
            "rise), 1); each measured trace's is in fit.json (friction_ratio_steady)",
            severity="note",
            median_rise=float(np.median(rises)),
            time_constant_s=float(tau),
        )

    def plan(
        self,
        goal: str = "band",
        n_pulls: int = 10,
        *,
        at: Sequence[tuple[float, float]] | None = None,
        half_width: float = 0.01,
        next_pull: bool = False,
        rel: float = 0.05,
        weight: float = 0.95,
        loads_n: tuple[float, float] | None = None,
        amplitudes: tuple[float, float] | None = None,
        speeds_m_s: Sequence[float] | None = None,
        on_time_s: float | None = None,
        grid: tuple[int, int] = (10, 10),
        max_draws: int = 2000,
        seed: int = 0,
    ) -> Plan:
        """The next ``n_pulls`` pulls for a goal (:mod:`idtool._plan`): ``band`` (the FR
        band's half-width [FR] at the operating points ``at``, (load [N], amplitude)
        pairs, down to ``half_width``), ``laws`` (tell the coupling laws apart) or
        ``parameters`` (every physical parameter to relative sd ``rel``), from the
        linearised levels model; candidates on a ``grid`` of loads [N] x amplitudes
        within ``loads_n`` and ``amplitudes`` (low, high; default the tested range).
        Checked over the fit's draws (the posterior's if sampled). Same seed, same plan."""
        return plan_pulls(
            self.artefact,
            self.draws(max_draws, seed),
            goal,
            n_pulls,
            at=at,
            half_width=half_width,
            next_pull=next_pull,
            rel=rel,
            weight=weight,
            loads_n=loads_n,
            amplitudes=amplitudes,
            speeds_m_s=speeds_m_s,
            on_time_s=on_time_s,
            grid=grid,
            seed=seed,
        )

    def amplitude_for(
        self,
        reduction_percent: float,
        load_n: float | Sequence[float],
        speed_m_s: float | Sequence[float] | None = None,
        *,
        max_draws: int = 2000,
        seed: int = 0,
    ) -> Amplitudes:
        """The commanded amplitude fraction that lowers friction by
        ``reduction_percent`` at each load [N] and speed [m/s], with its 95% band, or
        why it is out of reach."""
        draws = self.draws(max_draws, seed)
        return amplitude_table(draws, self.model.data, reduction_percent, load_n, speed_m_s)

    def validate(
        self,
        dataset: Dataset | str | os.PathLike | None = None,
        traces: str | Sequence[str] | None = None,
        *,
        max_draws: int = 2000,
        seed: int = 0,
    ) -> Validation:
        """How well the fit predicts traces it did not see (:mod:`idtool._predict.
        _validation`): per trace, the force fit % and RMSE [N] with only its nuisances
        fitted, and its own friction ratio against the 95% band of a new pull; their
        coverage.

        Args:
            dataset: the traces to predict (default: the fit's own dataset).
            traces: shell patterns selecting them (default: the traces of the fit's own
                dataset that the fit did not use; all of another dataset's).
        """
        own = self.dataset
        if dataset is None:
            if own.path is None:
                raise IdtoolError("the fit's dataset lives in memory: give a dataset")
            dataset = load_dataset(own.path)
        elif not isinstance(dataset, Dataset):
            dataset = load_dataset(Path(dataset))
        fitted = {t.id for t in own.traces} if dataset.sha256 == own.sha256 else set()
        if traces is not None:
            held = select_traces(dataset, traces)
        elif fitted == {t.id for t in dataset.traces}:
            raise IdtoolError(
                f"the fit used every trace of {dataset.name}: nothing is held out; give "
                "another session's dataset, or fit some traces with --traces"
            )
        else:
            held = select_traces(dataset, [f"!{i}" for i in sorted(fitted)] or ["*"])
        reused = sorted(fitted & {t.id for t in held.traces})
        draws = self.draws(max_draws, seed)
        out = validate(self.model, self.z, self.noise_state, draws, held)
        if reused:
            note = f"not held out: {', '.join(reused)} were fitted"
            out = dataclasses.replace(out, warnings=(*out.warnings, note))
        return out

    # ------------------------------------------------------------------ files
    def to_json(self, command: Sequence[str] | None = None) -> dict:
        """The ``fit.json`` document (``datasets_schema/fit.schema.json``); ``command``
        replaces the recorded one."""
        doc = json.loads(json.dumps(self.artefact.doc))
        if command is not None:
            doc["command"] = provenance(list(command))["command"]
        return doc

    def save(
        self,
        path: str | os.PathLike,
        *,
        force: bool = False,
        plots: bool = True,
        command: Sequence[str] | None = None,
    ) -> Path:
        """Write the fit folder (``fit.json``, ``report.txt``, ``fit_state.npz`` and,
        with ``plots``, ``traces.png`` and ``residuals.png``) all or nothing; an
        existing folder is replaced only with ``force``. A dataset that lives in memory
        only (simulated) is written into the folder's ``dataset/`` so the fit can be
        read back. ``command`` is recorded as provenance (default: the one recorded when
        the fit was made). A fit read back is written again the same way, its plots
        copied from its folder."""
        out = Path(path)
        doc = self.to_json(command)
        recorded = doc["dataset"]["path"]
        with atomic_output_dir(out, force=force) as tmp:
            if self.dataset.path is None:
                write_dataset(self.dataset, tmp / "dataset")
                doc["dataset"]["path"] = "dataset"  # relative to the fit folder
            elif self.folder is not None and not Path(recorded).is_absolute():
                # read back with the dataset saved in its folder: the very files along
                shutil.copytree(self.folder / recorded, tmp / recorded)
            write_artefact(tmp, dataclasses.replace(self.artefact, doc=doc))
            if plots and self.run is not None:
                plot_fit(self.run, tmp)
            elif plots and self.folder is not None:
                for plot in (TRACES_PNG, RESIDUALS_PNG):
                    if (self.folder / plot.name).is_file():
                        shutil.copyfile(self.folder / plot.name, tmp / plot.name)
        self.artefact = dataclasses.replace(self.artefact, doc=json.loads(json.dumps(doc)))
        self.folder = out
        return out


def _states(run: FitRun) -> dict[str, dict[str, np.ndarray]]:
    """The state arrays of a run's chosen fit and of each law it kept, by file name."""
    out = {FIT_STATE.name: state_arrays(run.chosen)}
    return out | {law_state_file(law): state_arrays(f) for law, f in run.alternates.items()}
