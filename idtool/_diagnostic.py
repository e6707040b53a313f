"""Diagnostics as data (issue 26): every doubt idtool raises about a fit or a chain is a
:class:`Diagnostic`, a message that also carries a ``code``, a ``severity`` and the
``values`` it is about.

A :class:`Diagnostic` *is* its message (a ``str``), so the lists of warnings and notes
that reports print stay lists of sentences; what reads them by meaning (the report's
banners, ``compare``, the tests) reads :attr:`Diagnostic.code` instead of the prose.
``fit.json`` and ``sample.json`` store them as records (``diagnostics``: code, severity,
message, values), and a stored fit reads them back as diagnostics
(:func:`from_records`).

The codes are declared once, in :data:`CODES` (code -> what it means); a code that is
not declared is refused, so a typo cannot make a banner disappear silently.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from typing import Any

__all__ = [
    "BANNER_CODES",
    "CODES",
    "DRIFT_CODES",
    "MISFIT_CODES",
    "SEVERITIES",
    "Diagnostic",
    "banner_label",
    "from_records",
    "has_code",
    "records",
    "reworded",
    "with_code",
]

SEVERITIES = ("warning", "note")

CODES = {
    # the fit
    "bound": "a physical parameter sits at the bound of its range",
    "uninformed": "a physical parameter's 95% interval spans more than a factor of 100",
    "correlation": "two physical parameters are correlated beyond 0.95",
    "singular": "a near-singular direction in parameter space",
    "single_load": "one normal load: the coupling's shape cannot be told apart",
    "lm_not_converged": "Levenberg-Marquardt stopped before its tolerance",
    "profile_interval": "the Gauss-Newton interval is far off; the profile likelihood's reported",
    "misfit_levels": "the model misses the traces' own levels beyond their noise",
    "misfit_operating_points": "the model misses the operating points (discrepancy sd)",
    "levels_not_estimated": "scatter and discrepancy could not be estimated",
    "drift_on": "the ON level drifts within its plateaus (a fading horn)",
    "drift_off": "the OFF level drifts within its plateaus (a creeping level)",
    "drift_creep": "the fitted offset drifts grow with the load (a creeping level)",
    "drift_modelled": "a level model follows the levels' drift (relaxing ON or creeping level)",
    "coupling_laws": "the coupling laws fit comparably or disagree",
    "directions": "the directions of vibration fit comparably",
    "detuning": "the sdof horn's detuning",
    "data": "what the data and their blocks say (mains, sample rate, traces)",
    "fit": "another of the fit's doubts",
    # the posterior
    "not_converged": "the posterior chain did not meet the convergence rule",
    "sampler_start": "the sampler's start moved from the fit's optimum",
    # predictions
    "extrapolation": "an answer beyond the tested loads or amplitudes",
}

# The model misses the data beyond their noise; a level drifts within its plateaus.
MISFIT_CODES = frozenset({"misfit_levels", "misfit_operating_points"})
DRIFT_CODES = frozenset({"drift_on", "drift_off", "drift_creep", "drift_modelled"})
# The codes a report raises as red banners before anything else.
BANNER_CODES = MISFIT_CODES | DRIFT_CODES


class Diagnostic(str):
    """A message (the ``str`` itself) with its ``code`` (one of :data:`CODES`), its
    ``severity`` (one of :data:`SEVERITIES`) and the ``values`` it reports."""

    code: str
    severity: str
    values: dict[str, Any]

    def __new__(
        cls, code: str, message: str, severity: str = "warning", **values: Any
    ) -> Diagnostic:
        if code not in CODES:
            raise ValueError(f"diagnostic code {code!r} is not declared in CODES")
        if severity not in SEVERITIES:
            raise ValueError(f"diagnostic severity {severity!r}: use one of {SEVERITIES}")
        out = super().__new__(cls, message)
        out.code, out.severity = code, severity
        out.values = {k: _plain(v) for k, v in values.items()}
        return out

    def __reduce__(self):
        return (_rebuild, (self.code, str(self), self.severity, self.values))

    def to_dict(self) -> dict[str, Any]:
        return {
            "code": self.code,
            "severity": self.severity,
            "message": str(self),
            "values": dict(self.values),
        }


def _rebuild(code: str, message: str, severity: str, values: dict) -> Diagnostic:
    return Diagnostic(code, message, severity, **values)


def _plain(value: Any) -> Any:
    """A JSON-ready value: NumPy scalars and tuples made plain."""
    if hasattr(value, "item") and getattr(value, "ndim", 1) == 0:
        return value.item()
    if isinstance(value, tuple | list):
        return [_plain(v) for v in value]
    return value


def as_diagnostic(item: str, code: str = "fit", severity: str = "warning") -> Diagnostic:
    """``item`` itself when it is a :class:`Diagnostic`, else a message under ``code``."""
    return item if isinstance(item, Diagnostic) else Diagnostic(code, item, severity)


def reworded(item: str, message: str, **values: Any) -> str:
    """``message`` in place of ``item``'s, keeping its code, severity and values (updated
    by ``values``) when it is a :class:`Diagnostic` (a plain sentence stays plain)."""
    if isinstance(item, Diagnostic):
        return Diagnostic(item.code, message, item.severity, **(item.values | values))
    return message


def banner_label(item: Diagnostic) -> str:
    """The report's banner heading of a diagnostic with one of :data:`BANNER_CODES`."""
    return "Model misfit" if item.code.startswith("misfit") else "Level drift"


def records(
    items: Iterable[str], code: str = "fit", severity: str = "warning"
) -> list[dict[str, Any]]:
    """JSON records of ``items`` (plain messages under ``code`` and ``severity``)."""
    return [as_diagnostic(i, code, severity).to_dict() for i in items]


def from_records(docs: Iterable[Mapping[str, Any]]) -> list[Diagnostic]:
    """The diagnostics of stored records (:func:`records`)."""
    return [
        Diagnostic(d["code"], d["message"], d.get("severity", "warning"), **d.get("values", {}))
        for d in docs
    ]


def has_code(item: str, *codes: str) -> bool:
    """Whether ``item`` is a diagnostic with one of ``codes``."""
    return isinstance(item, Diagnostic) and item.code in codes


def with_code(items: Iterable[str], *codes: str) -> list[Diagnostic]:
    """The diagnostics among ``items`` with one of ``codes``."""
    return [i for i in items if isinstance(i, Diagnostic) and i.code in codes]
