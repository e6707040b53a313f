"""The fit folder on disk: :func:`write_artefact` writes a fit's own files (``fit.json``,
``report.txt``, ``fit_state*.npz``, named in :mod:`idtool._fit._folder`) and
:func:`load_artefact` reads them back into the :class:`~idtool._fit._artefact.FitArtefact`
a fresh fit has, through the same constructor (:func:`~idtool._fit._artefact.fit_artefact`).

``fit.json``'s ``schema_version`` is checked on reading: none (a fit.json written before
the field) reads as version 1; a version newer than this idtool's is refused, naming the
file and what to do.
"""

from __future__ import annotations

import dataclasses
import json
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from idtool._data._blocks import prepare_fit_data
from idtool._data._dataset import load_dataset
from idtool._errors import IdtoolError
from idtool._fit._artefact import FitArtefact, fit_artefact
from idtool._fit._folder import FIT_JSON, FIT_STATE, REPORT_TXT

__all__ = ["load_artefact", "read_fit_doc", "read_states", "write_artefact"]


def read_fit_doc(folder: Path) -> dict[str, Any]:
    """``fit.json`` of ``folder``, its schema version checked (none: version 1)."""
    if not (folder / FIT_JSON.name).is_file():
        raise IdtoolError(
            f"{folder / FIT_JSON.name}: not found; is {folder} the output of 'idtool fit'?"
        )
    return FIT_JSON.read_json(folder)


def write_artefact(folder: Path, artefact: FitArtefact) -> None:
    """Write ``fit.json``, ``report.txt`` and the state files into ``folder``."""
    (folder / FIT_JSON.name).write_text(json.dumps(artefact.doc, indent=1) + "\n")
    (folder / REPORT_TXT.name).write_text(artefact.report_text + "\n")
    for name, arrays in artefact.states.items():
        np.savez(folder / name, **arrays)  # type: ignore[arg-type]  # numpy stubs: allow_pickle


def read_states(folder: Path, doc: Mapping[str, Any]) -> dict[str, dict[str, np.ndarray]]:
    """The state arrays of ``folder``'s fit: ``fit_state.npz`` and each kept law's."""
    kept = [*doc.get("coupling_laws", []), *doc.get("model_weights", [])]
    files = dict.fromkeys(w["state_file"] for w in kept if "state_file" in w)
    names = [FIT_STATE.name, *files]
    states = {}
    for name in names:
        path = folder / name
        if not path.is_file():
            raise IdtoolError(f"{path}: not found; is {folder} the output of 'idtool fit'?")
        with np.load(path) as npz:
            states[name] = {key: np.asarray(npz[key]) for key in npz.files}
    return states


def load_artefact(folder: str | Path) -> FitArtefact:
    """Read the fit folder ``folder``; the dataset must still be where the fit found it,
    unchanged (its sha256 is checked)."""
    folder = Path(folder)
    doc = read_fit_doc(folder)
    doc_path = folder / FIT_JSON.name
    if isinstance(doc, dict) and doc.get("kind") == "levels":
        raise IdtoolError(
            f"{folder} is the fit of a friction table (kind: levels), not of bench traces: "
            "read it with idtool.load_levels_fit (idtool predict, sample, report, compare "
            "and plan read it too); validate-fit and the trace fit's API do not apply to it"
        )
    try:
        ds_info = doc["dataset"]
        noise = doc["noise"]
        mains_hz = float(noise["mains_hz"])
        # The periods asked for rebuild the very blocks (prepare_fit_data chooses the
        # same count again); a fit.json older than that field had block_s = periods / mains.
        periods = int(noise.get("periods_requested", round(float(noise["block_s"]) * mains_hz)))
        periods_used = int(noise.get("periods_per_block", periods))
        source = str(noise.get("mains_source", "argument"))
    except (ValueError, KeyError, TypeError) as err:
        raise IdtoolError(f"{doc_path}: unreadable fit ({err}); run 'idtool fit' again") from None
    states = read_states(folder, doc)
    # A dataset saved with the fit (it lived in memory only) is recorded relative to it.
    dataset = load_dataset(folder / ds_info["path"])
    if dataset.sha256 != ds_info["sha256"]:
        raise IdtoolError(
            f"{ds_info['path']}: the dataset changed since the fit (sha256 "
            f"{dataset.sha256[:12]}... instead of {ds_info['sha256'][:12]}...); fit it again"
        )
    fitted = ds_info.get("traces")  # a fit of some of the dataset's traces (--traces)
    if fitted is not None and len(fitted) != len(dataset.traces):
        by_id = {t.id: t for t in dataset.traces}
        dataset = dataclasses.replace(dataset, traces=tuple(by_id[i] for i in fitted))
    data = prepare_fit_data(
        dataset, mains_hz=mains_hz, periods_per_block=periods, mains_source=source
    )
    if data.periods_per_block != periods_used:  # an old fit whose blocks were not whole periods
        raise IdtoolError(
            f"{doc_path}: the fit averaged over blocks of {periods_used} mains periods, this "
            f"idtool makes blocks of {data.periods_per_block} whole periods; run 'idtool fit' again"
        )
    report_path = folder / REPORT_TXT.name
    report = report_path.read_text() if report_path.is_file() else ""
    return fit_artefact(doc, report, dataset, data, states)
