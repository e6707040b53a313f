"""The fit folder, declared once: every file a command writes into it, with the command
that writes it, what it holds and, for a JSON document, its schema version and the JSON
Schema that describes it (``datasets_schema/``).

Code names a file by its entry here (``FIT_JSON.name``), never by a literal, so adding an
output file is one entry in :data:`FIT_FOLDER` (and its row in ``docs/outputs.md``, which
``tests/test_artefact.py`` checks against this table). The fit's own files are written
and read by :mod:`idtool._fit._artefact` (``fit.json``, ``report.txt``,
``fit_state*.npz``); the others by the stages that make them (the posterior's by
:mod:`idtool._posterior`, the report's by :mod:`idtool._report`).
"""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path
from typing import Any

from idtool._errors import IdtoolError

__all__ = [
    "CHAIN_H5",
    "FIT_FOLDER",
    "FIT_JSON",
    "FIT_SCHEMA_VERSION",
    "FIT_STATE",
    "PLAN_CSV",
    "POSTERIOR_NC",
    "PPC_PNG",
    "REPORT_HTML",
    "REPORT_MD",
    "REPORT_SAMPLE_TXT",
    "REPORT_TXT",
    "RESIDUALS_PNG",
    "SAMPLE_JSON",
    "SAMPLE_SCHEMA_VERSION",
    "TRACES_PNG",
    "VALIDATION_JSON",
    "VALIDATION_SCHEMA_VERSION",
    "FolderFile",
    "law_state_file",
]

# fit.json's layout. "1": every fit.json before the field (read as version 1: the same
# fields, the optional ones absent); "2": with ``schema_version``, and fit_state.npz with
# the multi-start's optima on the internal scale; "3": fit_state.npz with the levels
# model's Jacobian ``levels_jacobian`` (predictions draw the physical parameters given
# each draw's sds; a version-2 folder draws them at the REML sds, as before, and says so).
FIT_SCHEMA_VERSION = "3"
# sample.json's and validation.json's layouts: "1" (a file without the field, written
# before it, has the same fields and reads as version 1).
SAMPLE_SCHEMA_VERSION = "1"
VALIDATION_SCHEMA_VERSION = "1"


@dataclasses.dataclass(frozen=True)
class FolderFile:
    """One file of a fit folder.

    Attributes:
        name: its file name (``{law}`` stands for a coupling law's name).
        command: the ``idtool`` command that writes it.
        what: what it holds (for the documentation).
        writer: the function that writes it (``module:function``; the stages above this
            one write their own files, so they are named, not imported).
        reader: the function that reads it back (``module:function``), or "" when
            nothing does (figures, text reports, the report's own pages).
        schema_version: a JSON document's layout version (``None``: not versioned).
        schema: its JSON Schema in ``datasets_schema/`` (``None``: none published).
    """

    name: str
    command: str
    what: str
    writer: str
    reader: str = ""
    schema_version: str | None = None
    schema: str | None = None

    def for_law(self, law: str) -> str:
        """The name of the file of the coupling law ``law``."""
        return self.name.format(law=law)

    def read_json(self, folder: Path) -> dict[str, Any]:
        """This JSON document of ``folder``, its ``schema_version`` checked: none (a
        file written before the field) reads as version 1; a newer version than this
        idtool's is refused with an :class:`~idtool._errors.IdtoolError` naming the
        file and what to do, as is a missing or unreadable file."""
        path = Path(folder) / self.name
        if not path.is_file():
            raise IdtoolError(
                f"{path}: not found; is {folder} a fit folder, and has 'idtool "
                f"{self.command}' run on it?"
            )
        try:
            doc = json.loads(path.read_text())
        except (ValueError, OSError) as err:
            raise IdtoolError(
                f"{path}: unreadable ({err}); run 'idtool {self.command}' again"
            ) from None
        if not isinstance(doc, dict):
            raise IdtoolError(f"{path}: not a JSON object; run 'idtool {self.command}' again")
        version = str(doc.get("schema_version", "1"))
        newest = self.schema_version or "1"
        if not version.isdigit() or int(version) > int(newest):
            raise IdtoolError(
                f"{path}: schema version {version}, this idtool reads versions 1 to "
                f"{newest}; update idtool (or run 'idtool {self.command}' again with this one)"
            )
        return doc


_STORE = "idtool._fit._store"
_SAMPLE = "idtool._report._sample_text:write_posterior_outputs"
FIT_JSON = FolderFile(
    "fit.json",
    "fit",
    "the fit as data",
    f"{_STORE}:write_artefact",
    f"{_STORE}:read_fit_doc",
    FIT_SCHEMA_VERSION,
    "fit.schema.json",
)
REPORT_TXT = FolderFile(
    "report.txt",
    "fit",
    "the printed fit report",
    f"{_STORE}:write_artefact",
    f"{_STORE}:load_artefact",
)
FIT_STATE = FolderFile(
    "fit_state.npz",
    "fit",
    "the fit's internal state, for `sample` and `predict`",
    f"{_STORE}:write_artefact",
    f"{_STORE}:read_states",
)
LAW_STATE = FolderFile(
    "fit_state_{law}.npz",
    "fit",
    "another coupling law's internal state, for averaged predictions",
    f"{_STORE}:write_artefact",
    f"{_STORE}:read_states",
)
TRACES_PNG = FolderFile(
    "traces.png", "fit", "every trace with the fit", "idtool._report._fit_text:plot_fit"
)
RESIDUALS_PNG = FolderFile(
    "residuals.png",
    "fit",
    "the residuals before and after AR(1) whitening",
    "idtool._report._fit_text:plot_fit",
)
VALIDATION_JSON = FolderFile(
    "validation.json",
    "validate-fit",
    "held-out traces: force fit %, RMSE, FR against its band",
    "idtool._cli._validate_fit:_run",
    "idtool._report._html_validation:validation_section",
    VALIDATION_SCHEMA_VERSION,
    "validation.schema.json",
)
CHAIN_H5 = FolderFile(
    "chain.h5",
    "sample",
    "the emcee chain, every step",
    "idtool._posterior._chainfile:append_segment",
    "idtool._posterior._chainfile:read_chain",
)
POSTERIOR_NC = FolderFile(
    "posterior.nc",
    "sample",
    "ArviZ `InferenceData`",
    "idtool._posterior._store:write_posterior",
    "idtool._posterior._store:load_posterior",
)
SAMPLE_JSON = FolderFile(
    "sample.json",
    "sample",
    "convergence diagnostics, priors, posterior predictive check",
    _SAMPLE,
    "",
    SAMPLE_SCHEMA_VERSION,
    "sample.schema.json",
)
REPORT_SAMPLE_TXT = FolderFile(
    "report_sample.txt", "sample", "the printed posterior report", _SAMPLE
)
PPC_PNG = FolderFile("ppc.png", "sample", "the posterior predictive check", _SAMPLE)
REPORT_HTML = FolderFile(
    "report.html", "report", "the report (self-contained)", "idtool._report._html:write_report"
)
REPORT_MD = FolderFile(
    "report.md", "report", "the report as Markdown", "idtool._report._html:write_report"
)
PLAN_CSV = FolderFile(
    "plan.csv",
    "report",
    "the report's next pulls when its goal is unmet: the conditions table",
    "idtool._report._html:write_report",
    "idtool._data._import_conditions:conditions_for",
)

FIT_FOLDER: tuple[FolderFile, ...] = (
    FIT_JSON,
    REPORT_TXT,
    FIT_STATE,
    LAW_STATE,
    TRACES_PNG,
    RESIDUALS_PNG,
    VALIDATION_JSON,
    CHAIN_H5,
    POSTERIOR_NC,
    SAMPLE_JSON,
    REPORT_SAMPLE_TXT,
    PPC_PNG,
    REPORT_HTML,
    REPORT_MD,
    PLAN_CSV,
)


def law_state_file(law: str) -> str:
    """The state file of another coupling law's fit, kept for averaged predictions."""
    return LAW_STATE.for_law(law)
