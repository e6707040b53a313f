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

__all__ = [
    "CHAIN_H5",
    "FIT_FOLDER",
    "FIT_JSON",
    "FIT_SCHEMA_VERSION",
    "FIT_STATE",
    "POSTERIOR_NC",
    "PPC_PNG",
    "REPORT_HTML",
    "REPORT_MD",
    "REPORT_SAMPLE_TXT",
    "REPORT_TXT",
    "RESIDUALS_PNG",
    "SAMPLE_JSON",
    "TRACES_PNG",
    "VALIDATION_JSON",
    "FolderFile",
    "law_state_file",
]

# fit.json's layout. "1": every fit.json before the field (read as version 1: the same
# fields, the optional ones absent); "2": with ``schema_version``, and fit_state.npz with
# the multi-start's optima on the internal scale.
FIT_SCHEMA_VERSION = "2"


@dataclasses.dataclass(frozen=True)
class FolderFile:
    """One file of a fit folder.

    Attributes:
        name: its file name (``{law}`` stands for a coupling law's name).
        command: the ``idtool`` command that writes it.
        what: what it holds (for the documentation).
        schema_version: a JSON document's layout version (``None``: not versioned).
        schema: its JSON Schema in ``datasets_schema/`` (``None``: none published).
    """

    name: str
    command: str
    what: str
    schema_version: str | None = None
    schema: str | None = None

    def for_law(self, law: str) -> str:
        """The name of the file of the coupling law ``law``."""
        return self.name.format(law=law)


FIT_JSON = FolderFile("fit.json", "fit", "the fit as data", FIT_SCHEMA_VERSION, "fit.schema.json")
REPORT_TXT = FolderFile("report.txt", "fit", "the printed fit report")
FIT_STATE = FolderFile(
    "fit_state.npz", "fit", "the fit's internal state, for `sample` and `predict`"
)
LAW_STATE = FolderFile(
    "fit_state_{law}.npz",
    "fit",
    "another coupling law's internal state, for averaged predictions",
)
TRACES_PNG = FolderFile("traces.png", "fit", "every trace with the fit")
RESIDUALS_PNG = FolderFile("residuals.png", "fit", "the residuals before and after AR(1) whitening")
VALIDATION_JSON = FolderFile(
    "validation.json", "validate-fit", "held-out traces: force fit %, RMSE, FR against its band"
)
CHAIN_H5 = FolderFile("chain.h5", "sample", "the emcee chain, every step")
POSTERIOR_NC = FolderFile("posterior.nc", "sample", "ArviZ `InferenceData`")
SAMPLE_JSON = FolderFile(
    "sample.json", "sample", "convergence diagnostics, priors, posterior predictive check"
)
REPORT_SAMPLE_TXT = FolderFile("report_sample.txt", "sample", "the printed posterior report")
PPC_PNG = FolderFile("ppc.png", "sample", "the posterior predictive check")
REPORT_HTML = FolderFile("report.html", "report", "the report (self-contained)")
REPORT_MD = FolderFile("report.md", "report", "the report as Markdown")

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
)


def law_state_file(law: str) -> str:
    """The state file of another coupling law's fit, kept for averaged predictions."""
    return LAW_STATE.for_law(law)
