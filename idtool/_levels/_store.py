"""A table fit's folder read back: :func:`load_levels_fit` (``fit.json``, the table it
names, and ``posterior.nc`` when sampled), and :func:`is_levels_fit`, which the commands
that read a fit folder ask first."""

from __future__ import annotations

import dataclasses
import json
import math
from pathlib import Path

import numpy as np

from idtool._data._levels import load_levels
from idtool._errors import IdtoolError
from idtool._fit._run import ChoiceWeight
from idtool._lawfit._profile import Side
from idtool._lawfit._result import estimate_from_sides
from idtool._levels._api import fit_levels
from idtool._levels._discrepancy import summary
from idtool._levels._estimate import SD_NAMES, Optimum, _cov, _data
from idtool._levels._free import CouplingCheck
from idtool._levels._model import levels_model
from idtool._levels._result import FIT_JSON, POSTERIOR_NC, LevelsFit
from idtool._levels._sample import TABLE, LevelsPosterior
from idtool._posterior._store import load_posterior

__all__ = ["is_levels_fit", "load_levels_fit", "not_for_tables"]


def is_levels_fit(folder: str | Path) -> bool:
    """True when ``folder`` holds the ``fit.json`` of a friction table's fit."""
    try:
        doc = json.loads((Path(folder) / FIT_JSON).read_text())
    except (OSError, ValueError):
        return False
    return isinstance(doc, dict) and doc.get("kind") == "levels"


def not_for_tables(folder: str | Path, what: str) -> IdtoolError:
    """The error of a command or option that does not apply to a table fit (yet)."""
    return IdtoolError(
        f"{folder} is the fit of a friction table (kind: levels): {what} works on fits of "
        "bench traces only, not (yet) on a table's; on a table fit use idtool sample, "
        "idtool report, or LevelsFit.predict in Python (docs/how-to/levels-table.md)"
    )


def load_levels_fit(folder: str | Path) -> LevelsFit:
    """Read a table fit's folder (``idtool fit`` on a dataset of kind ``levels``): the
    table must still be where the fit found it, unchanged (its sha256 is checked); a
    sampled folder's ``posterior.nc`` comes with it (the fit's ``posterior``).

    Raises:
        IdtoolError: no table fit there, an unreadable ``fit.json``, a table moved,
            changed or never saved (a fit of a table held in memory).
    """
    folder = Path(folder)
    path = folder / FIT_JSON
    if not path.is_file():
        raise IdtoolError(f"{folder}: not a fit folder (no fit.json); run 'idtool fit' first")
    if not is_levels_fit(folder):
        raise IdtoolError(f"{path}: not the fit of a friction table (kind: levels)")
    doc = json.loads(path.read_text())
    try:
        ds, m = doc["dataset"], doc["model"]
        if ds["path"] is None:
            raise IdtoolError(
                f"{path}: the table was fitted from memory, not a dataset folder; "
                "import it (idtool import-levels) and fit that"
            )
        table = load_levels(ds["path"])
        if table.sha256 != ds["sha256"]:
            raise IdtoolError(
                f"{ds['path']}: the table changed since the fit (sha256 {table.sha256[:12]}... "
                f"instead of {ds['sha256'][:12]}...); fit it again"
            )
        state = doc.get("state")
        if state is None:  # written before the state: the same fit again (seeded)
            fit = fit_levels(
                table, law=m["law"], coupling=m["coupling"], direction=m["direction"],
                seed=int(doc["seed"]),
            )  # fmt: skip
        else:
            fit = _rebuild(doc, table)
            ranking = tuple(_choice(w) for w in doc.get("models_compared", ()))
            alternates = tuple(_rebuild(a, table) for a in doc.get("alternates", ()))
            check = doc.get("coupling_check")
            fit = dataclasses.replace(
                fit, ranking=ranking, alternates=alternates,
                coupling_check=None if check is None else CouplingCheck.from_dict(check),
            )  # fmt: skip
    except (KeyError, TypeError, ValueError, IndexError) as err:
        raise IdtoolError(f"{path}: unreadable fit ({err!r}); run 'idtool fit' again") from None
    if (folder / POSTERIOR_NC).is_file():
        draws = load_posterior(folder / POSTERIOR_NC)
        if draws.meta.get("noise") != TABLE:
            raise IdtoolError(f"{folder / POSTERIOR_NC}: not a table fit's posterior; sample again")
        post = LevelsPosterior(
            draws.values, draws.meta["diagnostics"], draws.meta.get("timing", {}),
            int(draws.meta.get("seed", 0)),
        )  # fmt: skip
        object.__setattr__(fit, "posterior", post)
    return fit


def _choice(entry: dict) -> ChoiceWeight:
    return ChoiceWeight(
        str(entry["model"]), str(entry["key"]), float(entry["bic"]), float(entry["aic"]),
        float(entry["bic_weight"]), float(entry["aic_weight"]),
    )  # fmt: skip


def _rebuild(doc: dict, table) -> LevelsFit:
    m, state = doc["model"], doc["state"]
    model = levels_model(table, m["law"], m["coupling"], m["direction"])
    theta = np.asarray(doc["theta_internal"], float)
    cov_theta = np.asarray(doc["cov_internal"], float).reshape(theta.size, theta.size)
    sds = {n: float(doc["sds"][n]) for n in SD_NAMES}
    y, meas, k = _data(model)
    c = _cov(meas, k, np.array([sds[n] for n in SD_NAMES]))
    null = np.asarray(state["null"], float).reshape(theta.size, -1)
    active = tuple(bool(a) for a in state["active"])
    opt = Optimum(
        theta=theta,
        cov_theta=cov_theta,
        sds=sds,
        active=(active[0], active[1], active[2]),
        y=y,
        cov=c,
        chi2=float(doc["chi2"]),
        null=null,
        loglik=float(doc["log_likelihood"]),
        restricted=bool(state["restricted"]),
        discrepancy=None if "discrepancy" not in doc["sds"] else summary(doc["sds"]["discrepancy"]),
    )
    se_z = np.sqrt(np.maximum(np.diag(cov_theta), 0.0))
    estimates, sides, ends = {}, {}, {}
    for j, p in enumerate(model.params):
        lo, hi = (Side.from_json(e) for e in state["sides"][p.name])
        sides[p.name] = (lo, hi)
        ends[p.name] = np.asarray(state["ends"][p.name], float).reshape(2, theta.size)
        se = float(se_z[j]) if lo.method == hi.method == "wald" else math.inf
        estimates[p.name] = estimate_from_sides(p, float(theta[j]), se, lo, hi)
    return LevelsFit(
        model, opt, estimates, sides, ends, tuple(doc["warnings"]), tuple(doc["notes"]),
        float(doc["seconds"]), int(doc["seed"]),
    )  # fmt: skip
