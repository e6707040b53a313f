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
from idtool._fit._discrepancy import Conditioning
from idtool._fit._free_levels import FreeLevels
from idtool._fit._level_design import discrepancy_conditioning
from idtool._fit._result import Estimate, FitResult
from idtool._model._benchmodel import BenchModel, bench_model
from idtool._model._settings import ParameterSetting

__all__ = ["STATE_FILE", "StoredFit", "law_state_file", "load_stored_fit", "save_fit_state"]

STATE_FILE = "fit_state.npz"


def law_state_file(law: str) -> str:
    """The state file of another coupling law's fit, kept for averaged predictions."""
    return f"fit_state_{law}.npz"


def save_fit_state(folder: Path, result: FitResult, name: str = STATE_FILE) -> None:
    """Write ``fit_state.npz`` (internal vector, covariance, phi, parameter names), or
    another law's state as ``name``."""
    arrays: dict[str, np.ndarray] = {
        "z": result.z,
        "cov_z": result.cov_z,
        "phi": np.array(result.phi),
        "sigma_n": np.array(result.sigma_n),
        "names": np.array(result.model.names),
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
            "levels_cov_y": free.cov_y,
            "levels_sigma_n": np.array(free.sigma_n),
        }
    np.savez(folder / name, **arrays)  # type: ignore[arg-type]  # numpy stubs: allow_pickle


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
    # the levels model's sds: name -> (sd values, posterior probabilities); empty when off
    sd_grids: dict[str, tuple[np.ndarray, np.ndarray]] = dataclasses.field(default_factory=dict)
    # the free levels and the sds (estimate, ci95 lo, hi), or None when off
    levels: tuple[FreeLevels, dict[str, tuple[float, float, float]]] | None = None
    # other coupling laws' fits kept for averaged predictions: law -> (BIC weight, fit)
    alternates: dict[str, tuple[float, StoredFit]] = dataclasses.field(default_factory=dict)

    @property
    def conditioning(self) -> Conditioning | None:
        """What predictions condition the discrepancy on, or None when the levels model
        is off (:mod:`idtool._fit._discrepancy`)."""
        if self.levels is None:
            return None
        return discrepancy_conditioning(self.model, self.levels[0])

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
                bool(e.get("fixed", False)),
                str(e.get("fixed_by", "fixed by the user" if e.get("fixed") else "")),
                str(e.get("one_sided", "")),
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
        ds_info = doc["dataset"]
        noise = doc["noise"]
        mains_hz = float(noise["mains_hz"])
        # The periods asked for rebuild the very blocks (prepare_fit_data chooses the
        # same count again); a fit.json older than that field had block_s = periods / mains.
        periods = int(noise.get("periods_requested", round(float(noise["block_s"]) * mains_hz)))
        periods_used = int(noise.get("periods_per_block", periods))
        source = str(noise.get("mains_source", "argument"))
    except (ValueError, KeyError, OSError) as err:
        raise IdtoolError(f"{folder}: unreadable fit ({err}); run 'idtool fit' again") from None
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
    settings = tuple(ParameterSetting.from_dict(s) for s in doc.get("parameter_settings", []))

    def stored(
        coupling: str, actuator: str, offset: str, level: str, path: Path, alternates
    ) -> StoredFit:
        noise = doc["noise"].get("name", "ar1")
        model = bench_model(data, doc["law"], coupling, noise, actuator, offset, settings, level)
        state = np.load(path)
        if tuple(state["names"]) != model.names:
            raise IdtoolError(f"{path}: parameters do not match the model; fit again")
        return StoredFit(
            folder=folder,
            doc=doc,
            dataset=dataset,
            model=model,
            z=np.asarray(state["z"]),
            cov_z=np.asarray(state["cov_z"]),
            phi=float(state["phi"]),
            sigma_n=float(state["sigma_n"]),
            sd_grids={
                key.split(":", 1)[1]: (state[key][0], state[key][1])
                for key in state.files
                if key.startswith("sd_grid:")
            },
            levels=_stored_levels(state),
            alternates=alternates,
        )

    alternates = {}
    for w in doc.get("coupling_laws", []):  # law/coupling/actuator/offset[/level] in "key"
        if "state_file" in w:
            _, coupling, actuator, offset, *rest = w["key"].split("/")
            level = rest[0] if rest else "steady"  # keys before the level models: 4 parts
            alt = stored(coupling, actuator, offset, level, folder / w["state_file"], {})
            alternates[w["law"]] = (float(w["bic_weight"]), alt)
    return stored(
        doc["coupling"],
        doc.get("actuator", {}).get("name", "slope"),  # fits before the lag model: slope
        doc.get("offset", {}).get("name", "constant"),  # before the drift model: constant
        doc.get("level", {}).get("name", "steady"),  # before the level models: steady
        state_path,
        alternates,
    )


def _stored_levels(state) -> tuple[FreeLevels, dict[str, tuple[float, float, float]]] | None:
    """The levels model's state from ``fit_state.npz`` (None for a noise-only fit)."""
    if "levels_y" not in state.files:
        return None
    free = FreeLevels(
        off_n=state["levels_off_n"],
        on_n=state["levels_on_n"],
        measured=state["levels_measured"].astype(bool),
        y=state["levels_y"],
        cov_y=state["levels_cov_y"],
        sigma_n=float(state["levels_sigma_n"]),
    )
    sds = {
        key.split(":", 1)[1]: (float(state[key][0]), float(state[key][1]), float(state[key][2]))
        for key in state.files
        if key.startswith("sd_estimate:")
    }
    return free, sds
