"""Reading a fit back from ``fits/NAME/``: the dataset it used, its model and its state.

``fit.json`` is for people and other tools; ``fit_state.npz`` keeps the exact internal
parameter vector, its covariance and the AR(1) coefficient, so sampling and prediction
start from the very point the fit found.
"""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np

from idtool._data._blocks import prepare_fit_data
from idtool._data._dataset import Dataset, load_dataset
from idtool._errors import IdtoolError
from idtool._fit._fit import Estimate, FitResult
from idtool._model._benchmodel import BenchModel, bench_model

__all__ = ["STATE_FILE", "StoredFit", "load_stored_fit", "save_fit_state"]

STATE_FILE = "fit_state.npz"


def save_fit_state(folder: Path, result: FitResult) -> None:
    """Write ``fit_state.npz`` (internal vector, covariance, phi, parameter names)."""
    np.savez(
        folder / STATE_FILE,
        z=result.z,
        cov_z=result.cov_z,
        phi=np.array(result.phi),
        sigma_n=np.array(result.sigma_n),
        names=np.array(result.model.names),
    )


@dataclasses.dataclass(frozen=True)
class StoredFit:
    """A fit read back: its document, dataset, model, and internal state."""

    folder: Path
    doc: dict
    dataset: Dataset
    model: BenchModel
    z: np.ndarray
    cov_z: np.ndarray
    phi: float
    sigma_n: float

    def estimates(self) -> dict[str, Estimate]:
        """Every shared parameter's estimate as ``fit.json`` records it."""
        entries = self.doc.get("parameters", {}) | self.doc.get("bench", {})
        return {
            name: Estimate(
                name,
                e["unit"],
                float(e["estimate"]),
                float(e["std_error"]),
                (float(e["ci95"][0]), float(e["ci95"][1])),
                bool(e.get("at_bound", False)),
            )
            for name, e in entries.items()
        }

    @property
    def optima(self) -> list[dict]:
        """The multi-start's optima from ``fit.json``: ``rss`` and the physical block of
        the internal vector ``z`` (entries that do not read back are skipped)."""
        specs = self.model.shared_params[: self.model.n_physical]
        out = []
        for o in self.doc.get("multistart", []):
            try:
                z = np.array([s.internal(o[s.name]) for s in specs])
                out.append({"rss": float(o["rss"]), "z": z})
            except (KeyError, TypeError, ValueError):
                continue
        return out


def load_stored_fit(folder: str | Path) -> StoredFit:
    """Read ``fits/NAME``; the dataset must still be where the fit found it, unchanged."""
    folder = Path(folder)
    doc_path, state_path = folder / "fit.json", folder / STATE_FILE
    for path in (doc_path, state_path):
        if not path.is_file():
            raise IdtoolError(f"{path}: not found; is {folder} the output of 'idtool fit'?")
    try:
        doc = json.loads(doc_path.read_text())
        state = np.load(state_path)
        ds_info = doc["dataset"]
        mains_hz = float(doc["noise"]["mains_hz"])
        periods = round(float(doc["noise"]["block_s"]) * mains_hz)
    except (ValueError, KeyError, OSError) as err:
        raise IdtoolError(f"{folder}: unreadable fit ({err}); run 'idtool fit' again") from None
    # A dataset saved with the fit (it lived in memory only) is recorded relative to it.
    dataset = load_dataset(folder / ds_info["path"])
    if dataset.sha256 != ds_info["sha256"]:
        raise IdtoolError(
            f"{ds_info['path']}: the dataset changed since the fit (sha256 "
            f"{dataset.sha256[:12]}... instead of {ds_info['sha256'][:12]}...); fit it again"
        )
    data = prepare_fit_data(dataset, mains_hz=mains_hz, periods_per_block=periods)
    model = bench_model(data, doc["law"], doc["coupling"], doc["noise"].get("name", "ar1"))
    if tuple(state["names"]) != model.names:
        raise IdtoolError(f"{state_path}: parameters do not match the model; fit again")
    return StoredFit(
        folder=folder,
        doc=doc,
        dataset=dataset,
        model=model,
        z=np.asarray(state["z"]),
        cov_z=np.asarray(state["cov_z"]),
        phi=float(state["phi"]),
        sigma_n=float(state["sigma_n"]),
    )
