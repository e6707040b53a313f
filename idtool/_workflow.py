"""The public workflow's result: a :class:`Fit` to report, sample, predict and save.

``idtool.fit(dataset) -> Fit`` (:mod:`idtool._entry`) runs what ``idtool fit`` runs;
the :class:`Fit` it returns carries the estimates and their intervals, the text
report, and (after :meth:`Fit.sample`) the posterior. Predictions come from the
posterior when there is one, else from Gaussian draws on the fit's covariance, and say
which. ``Fit.save`` writes the fit folder the command line writes, and
``idtool.load_fit`` reads it back. Everything a notebook needs is here, with no private
module in sight.
"""

from __future__ import annotations

import dataclasses
import json
import os
import time
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np

from idtool._atomic import atomic_output_dir
from idtool._data._dataset import Dataset, load_dataset
from idtool._data._select import select_traces
from idtool._data._write import write_dataset
from idtool._diagnostic import Diagnostic, from_records
from idtool._errors import IdtoolError
from idtool._fit._result import Estimate, FitResult
from idtool._fit._run import FitRun
from idtool._fit._store import StoredFit, law_state_file, save_fit_state
from idtool._model._benchmodel import BenchModel
from idtool._posterior._draws import draws_from_posterior, draws_from_stored
from idtool._posterior._posterior import Posterior
from idtool._posterior._runner import MAX_MINUTES, MAX_STEPS
from idtool._posterior._sample import sample_posterior
from idtool._posterior._store import POSTERIOR_FILE, load_posterior
from idtool._predict._mixture import average_over_laws, chosen_law_weight
from idtool._predict._predict import Draws, draws_from_covariance
from idtool._predict._tables import Amplitudes, Predictions, amplitude_table, predict_table
from idtool._predict._validation import Validation, validate
from idtool._report._fit_text import fit_json, fit_report, plot_fit
from idtool._report._sample_text import write_posterior_outputs

__all__ = ["Fit"]


class Fit:
    """One identified dataset: the chosen model, its estimates, every candidate, and
    the posterior once sampled. Made by :func:`fit` or :func:`load_fit`.

    Attributes:
        dataset: the :class:`~idtool.Dataset` fitted.
        model: the chosen :class:`~idtool.BenchModel` (law, coupling, noise model).
        estimates: every parameter's :class:`~idtool.Estimate` (value, standard error,
            95% interval, unit), physical ones first.
        posterior: the :class:`~idtool.Posterior` after :meth:`sample`, else ``None``.
    """

    def __init__(
        self,
        dataset: Dataset,
        state: FitResult | StoredFit,
        run: FitRun | None = None,
        folder: Path | None = None,
    ):
        self.dataset = dataset
        self._state = state
        self.run = run
        self.folder = folder
        self.posterior: Posterior | None = None
        self.seconds = 0.0  # time the fit took [s]

    # ------------------------------------------------------------------ what it found
    @property
    def model(self) -> BenchModel:
        return self._state.model

    @property
    def z(self) -> np.ndarray:
        """The optimum on the internal scale (all parameters, nuisances included)."""
        return self._state.z

    @property
    def cov_z(self) -> np.ndarray:
        return self._state.cov_z

    @property
    def phi(self) -> float:
        return self._state.phi

    @property
    def sigma_n(self) -> float:
        return self._state.sigma_n

    @property
    def levels(self):
        """The levels model's (free levels, sds), or None (``variability=False``)."""
        return self._state.levels

    @property
    def conditioning(self):
        """What predictions condition the discrepancy on (the traces' own friction
        ratios), or None (``variability=False``)."""
        return self._state.conditioning

    @property
    def estimates(self) -> dict[str, Estimate]:
        if isinstance(self._state, FitResult):
            return self._state.estimates
        return self._state.estimates()

    @property
    def optima(self) -> list[dict]:
        """The multi-start's distinct optima (``rss``, internal physical ``z``)."""
        return self._state.optima

    @property
    def warnings(self) -> list[str]:
        return self._sentences("warnings")

    @property
    def notes(self) -> list[str]:
        """What the data let the fit measure (one trace per operating point, ON windows
        too short to settle): facts for the report, not doubts (:attr:`warnings`)."""
        return self._sentences("notes")

    @property
    def coupling_laws(self) -> dict[str, dict[str, float | str]]:
        """Each fitted coupling law (best first): its best candidate model's ``key``,
        ``bic``, ``aic`` and Akaike/Schwarz weights (``bic_weight``, ``aic_weight``):
        several with ``coupling="auto"``, else the one law at weight 1. In memory or
        from ``fit.json``."""
        if self.run is not None:
            return {n: w.to_dict() for n, w in self.run.coupling_weights.items()}
        doc = self._state.doc if isinstance(self._state, StoredFit) else {}
        return {w["law"]: w for w in doc.get("coupling_laws", [])}

    def _sentences(self, key: str) -> list[str]:
        """The fit's ``warnings`` or ``notes``: in memory, or from ``fit.json``: its
        ``diagnostic_records`` (codes and values kept), else the plain sentences of a fit
        written before them (and before notes existed: none)."""
        if isinstance(self._state, FitResult):
            return list(getattr(self._state, key))
        doc = self._state.doc
        if "diagnostic_records" in doc:
            severity = "warning" if key == "warnings" else "note"
            return [d for d in from_records(doc["diagnostic_records"]) if d.severity == severity]
        return list(doc.get(key, []))

    @property
    def result(self) -> FitResult:
        """The chosen model's full fit result (in memory only, not after load_fit)."""
        if not isinstance(self._state, FitResult):
            raise IdtoolError("a fit read back from disk keeps its estimates, not its result")
        return self._state

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
        if self.run is not None:
            return fit_report(self.run)
        assert self.folder is not None
        return (self.folder / "report.txt").read_text().rstrip("\n")

    # ------------------------------------------------------------------ posterior
    def sample(
        self,
        walkers: int = 32,
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
        ``steps`` runs a fixed length instead. ``chain_path`` checkpoints the chain
        (``chain.h5``) every ``checkpoint_s`` seconds; ``resume`` continues it. The same
        seed gives the same chain."""
        self.posterior = sample_posterior(
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
        grids, cond = self._state.sd_grids, self._state.conditioning
        if self.posterior is not None:
            draws = draws_from_posterior(self.posterior, self.model, max_draws, grids, seed, cond)
        elif self.folder is not None and (self.folder / POSTERIOR_FILE).is_file():
            stored = load_posterior(self.folder / POSTERIOR_FILE)
            draws = draws_from_stored(stored, self.model, max_draws, grids, seed, cond)
        else:
            draws = draws_from_covariance(
                self.model, self.z, self.cov_z, max_draws, seed, grids, cond
            )
        # averaged over the coupling laws the fit kept (fit coupling="auto")
        others: Mapping[str, tuple[float, FitResult | StoredFit]]
        if self.run is not None:
            laws = self.run.coupling_weights
            others = {law: (laws[law].bic_weight, f) for law, f in self.run.alternates.items()}
            weight = laws[self.model.coupling.name].bic_weight
        else:
            assert isinstance(self._state, StoredFit)
            others = self._state.alternates
            weight = chosen_law_weight(self._state.doc, self.model.coupling.name)
        return average_over_laws(draws, weight, others, seed)

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
        values = self.model.values(np.asarray(self._state.z, float))
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
        out = validate(self.model, self.z, self.phi, draws, held)
        if reused:
            note = f"not held out: {', '.join(reused)} were fitted"
            out = dataclasses.replace(out, warnings=(*out.warnings, note))
        return out

    # ------------------------------------------------------------------ files
    def to_json(self, command: Sequence[str] | None = None) -> dict:
        """The ``fit.json`` document (schema in the README)."""
        if self.run is None:
            assert isinstance(self._state, StoredFit)
            return self._state.doc
        path = None if self.dataset.path is None else str(Path(self.dataset.path).resolve())
        return fit_json(self.run, path, None if command is None else list(command))

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
        read back. ``command`` is recorded as provenance (default: the process's)."""
        if self.run is None:
            raise IdtoolError("this fit was read from disk; it is saved already")
        started = time.perf_counter()
        out = Path(path)
        with atomic_output_dir(out, force=force) as tmp:
            doc = self.to_json(command)
            if self.dataset.path is None:
                write_dataset(self.dataset, tmp / "dataset")
                doc["dataset"]["path"] = "dataset"  # relative to the fit folder
            doc["seconds"] = round(self.seconds + time.perf_counter() - started, 2)
            (tmp / "fit.json").write_text(json.dumps(doc, indent=1) + "\n")
            (tmp / "report.txt").write_text(self.report() + "\n")
            save_fit_state(tmp, self.result)
            for law, alternate in self.run.alternates.items():  # for averaged predictions
                save_fit_state(tmp, alternate, law_state_file(law))
            if plots:
                plot_fit(self.run, tmp)
        self.folder = out
        return out
