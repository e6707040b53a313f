"""The fit artefact: one typed record of a fit, the same whether it was just made or read
back from its folder.

A fit is its ``fit.json`` document, its text report and the internal state of each
coupling law it kept (``fit_state*.npz``: the optimum ``z`` on the internal scale, its
covariance, the noise parameters, the levels model's state). :func:`fit_artefact` is the
one constructor: a fresh fit passes the documents it is about to write (the document
passed through JSON, so it holds exactly what the file will), a loaded fit the ones it
read (:func:`idtool._fit._store.load_artefact`), so the two behave identically by
construction. The record carries the model spec as a typed :class:`ModelSpec`, the
estimates, covariance, noise, levels, alternates (the other coupling laws predictions
average over, each a :class:`LawFit` with its BIC weight), the diagnostics and what the
report shows (:class:`~idtool._fit._summary.FitSummary`).

The folder's files are named in :mod:`idtool._fit._folder`; ``fit.json`` is described by
``datasets_schema/fit.schema.json`` and carries its ``schema_version``: a fit.json
without one (written before the field) reads as version 1, whose fields are a subset.
"""

from __future__ import annotations

import dataclasses
import functools
import json
from collections.abc import Mapping
from typing import Any

import numpy as np

from idtool._data._blocks import FitData
from idtool._data._dataset import Dataset
from idtool._diagnostic import Diagnostic, from_records
from idtool._errors import IdtoolError
from idtool._fit._cov import Covariance, covariance_from_state, covariance_state
from idtool._fit._discrepancy import Conditioning
from idtool._fit._folder import FIT_STATE
from idtool._fit._free_levels import FreeLevels
from idtool._fit._level_cov import LevelCovariance
from idtool._fit._level_design import discrepancy_conditioning, level_design
from idtool._fit._result import Estimate, FitResult
from idtool._fit._summary import FitSummary, estimate_of_doc, fit_summary
from idtool._fit._variability import SD_PARAMS, ThetaGivenSds
from idtool._model._benchmodel import BenchModel
from idtool._model._names import DEFAULT_DIRECTION
from idtool._model._settings import ParameterSetting
from idtool._model._spec import ModelSpec

__all__ = [
    "FitArtefact",
    "LawFit",
    "ModelSpec",
    "fit_artefact",
    "state_arrays",
]

SdGrids = dict[str, tuple[np.ndarray, np.ndarray]]
Levels = tuple[FreeLevels, dict[str, tuple[float, float, float]]]


@dataclasses.dataclass(frozen=True)
class LawFit:
    """One coupling law's fit, what predictions and the sampler need of it: its model,
    optimum ``z`` (internal scale, all parameters), covariance ``cov_z`` (in blocks, or
    dense from a folder written before them: :mod:`idtool._fit._cov`), noise
    parameters ``noise_state`` (the noise model's correlation state) and ``sigma_n``
    [N], and the levels model's sd grids (name ->
    (sd values, posterior probabilities)) and state (free levels, sds), or none;
    ``levels_jacobian`` (n, k): the Jacobian of the levels model's log levels in the
    physical parameters at the estimate (:attr:`Variability.jacobian
    <idtool._fit._variability.Variability.jacobian>`; none in a folder written before it)."""

    spec: ModelSpec
    model: BenchModel = dataclasses.field(repr=False)
    z: np.ndarray
    cov_z: Covariance = dataclasses.field(repr=False)
    noise_state: np.ndarray
    sigma_n: float
    sd_grids: SdGrids = dataclasses.field(default_factory=dict, repr=False)
    levels: Levels | None = dataclasses.field(default=None, repr=False)
    levels_jacobian: np.ndarray | None = dataclasses.field(default=None, repr=False)

    @functools.cached_property
    def theta_given_sds(self) -> ThetaGivenSds | None:
        """The physical parameters' covariance as a function of the sds
        (:class:`~idtool._fit._variability.ThetaGivenSds`: what predictions draw them
        from, given each draw's sds), or None: the levels model off, or a fit folder
        written before the Jacobian (version 2) or before the free levels' blocks."""
        if self.levels is None or self.levels_jacobian is None:
            return None
        free, sds = self.levels
        if free.cov_parts is None:
            return None
        design = level_design(self.model, free.measured)
        parts = dataclasses.replace(free.cov_parts, disc=design.disc_root)
        # the REML variances, as the fit had them: an sd the data cannot inform (not
        # estimated, not in ``sds``) at zero
        tau2 = np.array([sds[p.name][0] ** 2 if p.name in sds else 0.0 for p in SD_PARAMS])
        return ThetaGivenSds(parts, np.asarray(self.levels_jacobian, float), tau2)

    @property
    def phi(self) -> float:
        """The AR(1) coefficient: the state's ``phi`` (0 for a model without one), as
        ``fit.json``'s ``noise.phi`` has always recorded it."""
        return self.model.noise.state_by_name(self.noise_state).get("phi", 0.0)

    @property
    def conditioning(self) -> Conditioning | None:
        """What predictions condition the discrepancy on, or None when the levels model
        is off (:mod:`idtool._fit._discrepancy`)."""
        return None if self.levels is None else discrepancy_conditioning(self.model, self.levels[0])


@dataclasses.dataclass(frozen=True)
class FitArtefact:
    """A fit, fresh or loaded (module docstring).

    Attributes:
        dataset: the fitted traces.
        data: their block means (:class:`~idtool._data._blocks.FitData`).
        chosen: the chosen model's :class:`LawFit`.
        estimates: every parameter's :class:`~idtool.Estimate`, physical ones first.
        optima: the multi-start's optima: ``rss`` [N^2] and the physical block of ``z``.
        warnings: the fit's doubts (:class:`~idtool._diagnostic.Diagnostic`).
        notes: what the data let the fit measure (facts, not doubts).
        coupling_laws: each fitted coupling law's key, criteria and weights, best first.
        alternates: the other models predictions average over: their label (a coupling
            law's name, or with ``direction="auto"`` :func:`idtool._fit._run.model_label`'s)
            -> (BIC weight, its :class:`LawFit`).
        summary: what it reports besides (traces, derived quantities, correlations,
            model comparison, levels model, provenance:
            :class:`~idtool._fit._summary.FitSummary`).
        report_text: the printed fit report.
        doc: the ``fit.json`` document, as written.
        states: the state files' arrays by file name (:func:`state_arrays`).
    """

    dataset: Dataset = dataclasses.field(repr=False)
    data: FitData = dataclasses.field(repr=False)
    chosen: LawFit
    estimates: dict[str, Estimate]
    optima: tuple[dict[str, Any], ...]
    warnings: tuple[str, ...]
    notes: tuple[str, ...]
    coupling_laws: dict[str, dict[str, Any]]
    alternates: dict[str, tuple[float, LawFit]]
    summary: FitSummary = dataclasses.field(repr=False)
    report_text: str = dataclasses.field(repr=False)
    doc: dict[str, Any] = dataclasses.field(repr=False)
    states: dict[str, dict[str, np.ndarray]] = dataclasses.field(repr=False, default_factory=dict)
    # ``direction="auto"``: each direction's record and each model predictions average
    # over by label (fit.json's ``directions`` and ``model_weights``); empty otherwise
    directions: dict[str, dict[str, Any]] = dataclasses.field(repr=False, default_factory=dict)
    model_weights: dict[str, dict[str, Any]] = dataclasses.field(repr=False, default_factory=dict)

    @property
    def schema_version(self) -> str:
        """The layout version of ``fit.json`` (:data:`~idtool._fit._folder.FIT_SCHEMA_VERSION`)."""
        return str(self.doc.get("schema_version", "1"))

    @property
    def spec(self) -> ModelSpec:
        return self.chosen.spec

    @property
    def model(self) -> BenchModel:
        return self.chosen.model

    @property
    def chosen_label(self) -> str:
        """The chosen model's name among those predictions average over: its coupling
        law, or its entry of ``model_weights`` (``direction="auto"``)."""
        for label, entry in self.model_weights.items():
            if "state_file" not in entry and entry.get("key") == self.spec.key:
                return label
        return self.model.coupling.name

    @property
    def chosen_weight(self) -> float:
        """The chosen model's BIC weight among those predictions average over (its
        coupling law's, or its ``model_weights`` entry's; 1 when the fit lists none)."""
        table = self.model_weights or self.coupling_laws
        entry = table.get(self.chosen_label)
        return 1.0 if entry is None else float(entry["bic_weight"])


def state_arrays(result: FitResult) -> dict[str, np.ndarray]:
    """A fit's internal state as ``fit_state*.npz`` holds it: the vector ``z`` and its covariance
    (in blocks, :func:`~idtool._fit._cov.covariance_state`), ``phi`` and the noise's
    correlation state ``noise_state``, ``sigma_n`` [N], the parameter names, the
    multi-start's optima (``optima_rss`` [N^2], ``optima_z``: their physical blocks,
    internal scale) and the levels model's sd grids and state (with, since version 3,
    ``levels_jacobian``: the physical parameters' covariance at any sds needs it)."""
    k = result.model.n_physical
    arrays: dict[str, np.ndarray] = {
        "z": np.asarray(result.z),
        **covariance_state(result.cov_z),  # its blocks (since issue 28: never (p, p))
        "phi": np.array(result.phi),
        "noise_state": np.asarray(result.noise_state, float),
        "sigma_n": np.array(result.sigma_n),
        "names": np.array(result.model.names),
        "optima_rss": np.array([float(o["rss"]) for o in result.optima], float),
        "optima_z": np.array([np.asarray(o["z"], float)[:k] for o in result.optima]).reshape(
            len(result.optima), k
        ),
    }
    # the levels model's sd grids (sd values, probabilities), one array per sd
    arrays |= {f"sd_grid:{k}": np.stack(v) for k, v in result.sd_grids.items()}
    if result.levels is not None:  # what the sampler's levels likelihood needs
        free, sds = result.levels
        arrays |= {f"sd_estimate:{k}": np.array(v) for k, v in sds.items()}
        arrays |= {
            "levels_off_n": free.off_n,
            "levels_on_n": free.on_n,
            "levels_measured": free.measured,
            "levels_y": free.y,
            "levels_sigma_n": np.array(free.sigma_n),
        }
        if free.cov_y is not None:  # dense: a folder written before the blocks, resaved
            arrays["levels_cov_y"] = free.cov_y
        if free.cov_parts is not None:  # y's covariance in blocks (never (n, n))
            arrays |= {
                "levels_cov_block": free.cov_parts.block,
                "levels_cov_low": free.cov_parts.low,
            }
    v = result.variability
    if v is not None and v.jacobian is not None:  # since version 3: theta given the sds
        arrays["levels_jacobian"] = np.asarray(v.jacobian, float)
    return arrays


def _cov_parts(state: Mapping[str, np.ndarray]) -> LevelCovariance | None:
    """The free levels' covariance in blocks, where the fit saved them (since issue 28;
    a folder without them samples on the dense ``levels_cov_y``)."""
    if "levels_cov_block" not in state:
        return None
    block = np.asarray(state["levels_cov_block"])
    measured = np.asarray(state["levels_measured"]).astype(float)
    disc = np.zeros((block.shape[0], 2, 0))
    return LevelCovariance(block, np.asarray(state["levels_cov_low"]), disc, measured)


def _noise_state(model: BenchModel, state: Mapping[str, np.ndarray]) -> np.ndarray:
    """The noise's correlation state as saved; a folder from before the state kept
    ``phi`` alone (then the only state a noise model had)."""
    if "noise_state" in state:
        return np.asarray(state["noise_state"], float)
    return model.noise.state_from_names({"phi": float(state["phi"])})


def _law_fit(spec: ModelSpec, data: FitData, state: Mapping[str, np.ndarray], where: str) -> LawFit:
    """The :class:`LawFit` of ``spec`` from its state arrays (``where``: for errors)."""
    model = spec.build(data)
    if tuple(str(n) for n in state["names"]) != model.names:
        raise IdtoolError(f"{where}: parameters do not match the model; fit again")
    levels: Levels | None = None
    if "levels_y" in state:
        free = FreeLevels(
            off_n=np.asarray(state["levels_off_n"]),
            on_n=np.asarray(state["levels_on_n"]),
            measured=np.asarray(state["levels_measured"]).astype(bool),
            y=np.asarray(state["levels_y"]),
            cov_y=np.asarray(state["levels_cov_y"]) if "levels_cov_y" in state else None,
            sigma_n=float(state["levels_sigma_n"]),
            cov_parts=_cov_parts(state),
        )
        sds = {
            key.split(":", 1)[1]: (float(v[0]), float(v[1]), float(v[2]))
            for key, v in state.items()
            if key.startswith("sd_estimate:")
        }
        levels = free, sds
    return LawFit(
        spec=spec,
        model=model,
        z=np.asarray(state["z"]),
        cov_z=covariance_from_state(state, model.n_shared),
        noise_state=_noise_state(model, state),
        sigma_n=float(state["sigma_n"]),
        sd_grids={
            key.split(":", 1)[1]: (np.asarray(v[0]), np.asarray(v[1]))
            for key, v in state.items()
            if key.startswith("sd_grid:")
        },
        levels=levels,
        levels_jacobian=np.asarray(state["levels_jacobian"])
        if "levels_jacobian" in state
        else None,
    )


def _estimates(doc: Mapping[str, Any], model: BenchModel) -> dict[str, Estimate]:
    """Every parameter's estimate as ``fit.json`` records it: the shared ones, then each
    trace's own (``offset_n[N270_A50_T1]``, from the trace's entry of ``traces``)."""
    entries = doc.get("parameters", {}) | doc.get("bench", {})
    out = {name: estimate_of_doc(name, e) for name, e in entries.items()}
    for trace in doc.get("traces", []):
        for key, _, _ in model.trace_groups:
            if key in trace:
                name = f"{key}[{trace['id']}]"
                out[name] = estimate_of_doc(name, trace[key])
    return out


def _optima(doc: Mapping[str, Any], model: BenchModel, state: Mapping[str, np.ndarray]):
    """The multi-start's optima (``rss``, physical block of ``z``): from the state file,
    or (version 1) from ``fit.json``'s physical values (entries that do not read back
    are skipped)."""
    if "optima_rss" in state:
        rss, zs = np.asarray(state["optima_rss"]), np.asarray(state["optima_z"])
        return tuple({"rss": float(r), "z": np.array(z)} for r, z in zip(rss, zs, strict=True))
    specs = model.shared_params[: model.n_physical]
    out = []
    for o in doc.get("multistart", []):
        try:
            z = np.array([s.internal(o[s.name]) for s in specs])
            out.append({"rss": float(o["rss"]), "z": z})
        except (KeyError, TypeError, ValueError):
            continue
    return tuple(out)


def _sentences(doc: Mapping[str, Any], key: str) -> tuple[str, ...]:
    """``warnings`` or ``notes``: from ``diagnostic_records`` (codes and values kept),
    else the plain sentences of a fit written before them (and before notes: none)."""
    if "diagnostic_records" in doc:
        severity = "warning" if key == "warnings" else "note"
        found: list[Diagnostic] = from_records(doc["diagnostic_records"])
        return tuple(d for d in found if d.severity == severity)
    return tuple(doc.get(key, []))


def _spec(doc: Mapping[str, Any], coupling: str, key: str | None = None) -> ModelSpec:
    """The model spec of ``fit.json``'s chosen model, or of another coupling law's from
    its ``key`` (law/coupling/actuator/offset[/level][@direction]). A key that names no
    direction is in the chosen model's, or along the sliding where the directions were
    compared (``model_weights``: there a key names every other direction)."""
    settings = tuple(ParameterSetting.from_dict(s) for s in doc.get("parameter_settings", []))
    noise = str(doc["noise"].get("name", "ar1"))
    direction = str(doc.get("direction", {}).get("name", "along"))  # before: along
    if key is not None and "model_weights" in doc:
        direction = DEFAULT_DIRECTION
    if key is not None:
        return ModelSpec.from_key(key, noise, settings, direction)
    return ModelSpec(
        doc["law"],
        coupling,
        noise,
        doc.get("actuator", {}).get("name", "slope"),  # fits before the lag model: slope
        doc.get("offset", {}).get("name", "constant"),  # before the drift model: constant
        doc.get("level", {}).get("name", "steady"),  # before the level models: steady
        settings,
        direction,
    )


def fit_artefact(
    doc: Mapping[str, Any],
    report_text: str,
    dataset: Dataset,
    data: FitData,
    states: Mapping[str, Mapping[str, np.ndarray]],
) -> FitArtefact:
    """The artefact of a ``fit.json`` document, the report's text and the state arrays
    by file name (``fit_state.npz`` and each kept law's); ``data``: the dataset's block
    means as the fit made them. The one constructor, for fresh and loaded fits alike."""
    written: dict[str, Any] = json.loads(json.dumps(doc))  # exactly what fit.json holds
    doc = written
    law_entries = doc.get("coupling_laws", [])
    chosen_spec = _spec(doc, doc["coupling"])
    chosen = _law_fit(chosen_spec, data, states[FIT_STATE.name], FIT_STATE.name)
    model_entries = doc.get("model_weights", [])
    alternates = {}
    # the models predictions average over: by direction and coupling law where the
    # directions were compared, else by coupling law
    labelled = [(w, w["model"]) for w in model_entries] or [(w, w["law"]) for w in law_entries]
    for w, label in labelled:
        if "state_file" in w:
            spec = _spec(doc, w["key"].split("/")[1], w["key"])
            alt = _law_fit(spec, data, states[w["state_file"]], w["state_file"])
            alternates[label] = (float(w["bic_weight"]), alt)
    return FitArtefact(
        dataset=dataset,
        data=data,
        chosen=chosen,
        estimates=_estimates(doc, chosen.model),
        optima=_optima(doc, chosen.model, states[FIT_STATE.name]),
        warnings=_sentences(doc, "warnings"),
        notes=_sentences(doc, "notes"),
        coupling_laws={w["law"]: w for w in law_entries},
        directions={w["direction"]: w for w in doc.get("directions", [])},
        model_weights={w["model"]: w for w in model_entries},
        alternates=alternates,
        summary=fit_summary(doc),
        report_text=report_text.rstrip("\n"),
        doc=written,
        states={name: dict(arrays) for name, arrays in states.items()},
    )
