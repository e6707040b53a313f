"""The HTML shell of ``report.html``: style (screen and print), tables, the header a
qualification file needs (what, when, which data, report id) and the sign-off block.

Pure string building; what goes into the sections is :mod:`idtool._report._html`'s.
"""

from __future__ import annotations

import base64
import datetime
import hashlib
import html
import json
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any

__all__ = ["G", "g", "img", "kv_table", "page", "report_id", "signoff", "table"]

# Screen: one readable column. Print ("print to PDF"): A4 pages with margins, the answer
# alone on the first page, no section or figure cut across a page break where it fits,
# banners and shading printed in colour (browsers drop backgrounds by default), and
# the page's own font size so 9 pt figure text stays 9 pt on paper.
_CSS = """
body{font-family:sans-serif;font-size:11pt;max-width:1100px;margin:auto;padding:1em;
color:#111}
h1{font-size:1.6em;margin-bottom:0.2em}h2{font-size:1.25em;border-bottom:1px solid #999;
margin-top:1.4em}
table{border-collapse:collapse;font-size:0.9em;margin:0.4em 0}
td,th{border:1px solid #bbb;padding:2px 6px;text-align:left;vertical-align:top}
th{background:#eee}td.num{text-align:right;font-variant-numeric:tabular-nums}
img{max-width:100%;display:block;margin:0.5em 0}
pre{white-space:pre-wrap;overflow-wrap:anywhere;background:#f6f6f6;padding:0.3em 0.5em}
.banner{border:2px solid #b00000;background:#fff0f0;padding:0.4em 1em;margin:0.6em 0;
font-weight:bold}
.meta td:first-child{font-weight:bold;white-space:nowrap}
.answer table{font-size:1em}.answer td{white-space:nowrap}.note{color:#444;font-size:0.9em}
.signoff td{height:2.4em;min-width:11em}
@page{size:A4;margin:14mm}
@media print{
body{max-width:none;padding:0;font-size:10pt}
*{-webkit-print-color-adjust:exact;print-color-adjust:exact}
section{break-inside:avoid-page}h2{break-after:avoid-page}
img,table{break-inside:avoid-page}
#answer{break-after:page}
img{max-height:24cm;width:auto}
}
"""


G = ".4g"  # the report's numbers: four significant digits


def g(x: float) -> str:
    """A number in four significant digits."""
    return f"{x:{G}}"


def img(path: Path, alt: str) -> str:
    """``path``'s PNG embedded (the report opens offline, as one file)."""
    data = base64.b64encode(path.read_bytes()).decode("ascii")
    return f'<img alt="{html.escape(alt)}" src="data:image/png;base64,{data}">'


def table(header: Iterable[str] | None, rows: Iterable[Iterable[Any]], cls: str = "") -> str:
    """An HTML table (no header row if ``header`` is None); every cell escaped."""
    head = "".join(f"<th>{html.escape(str(h))}</th>" for h in header or ())
    body = "".join(
        "<tr>" + "".join(f"<td>{html.escape(str(c))}</td>" for c in row) + "</tr>" for row in rows
    )
    attr = f' class="{cls}"' if cls else ""
    thead = f"<thead><tr>{head}</tr></thead>" if header is not None else ""
    return f"<table{attr}>{thead}<tbody>{body}</tbody></table>"


def _flat(doc: Mapping[str, Any], prefix: str = "") -> list[tuple[str, str]]:
    out: list[tuple[str, str]] = []
    for key, value in doc.items():
        name = f"{prefix}{key}"
        if isinstance(value, Mapping) and value:
            out += _flat(value, name + ": ")
        elif isinstance(value, float):
            out.append((name, g(value)))
        elif isinstance(value, list | tuple):
            out.append((name, ", ".join(g(v) if isinstance(v, float) else str(v) for v in value)))
        else:
            out.append((name, "-" if value is None else str(value)))
    return out


def kv_table(doc: Mapping[str, Any]) -> str:
    """A nested mapping as a two-column table (nested keys joined by ': '), not JSON."""
    return table(["item", "value"], _flat(doc), cls="meta")


def report_id(*parts: bytes) -> str:
    """An id of the report's content: the same fit, posterior and options give the same
    id, any change another (12 hex digits of a SHA-256, each part length-prefixed)."""
    digest = hashlib.sha256()
    for part in parts:
        digest.update(len(part).to_bytes(8, "big"))
        digest.update(part)
    return "IDT-" + digest.hexdigest()[:12].upper()


def options_bytes(**options: Any) -> bytes:
    """Report options, canonically, for :func:`report_id`."""
    return json.dumps(options, sort_keys=True).encode()


def now_utc() -> str:
    return datetime.datetime.now(datetime.UTC).strftime("%Y-%m-%d %H:%M UTC")


def signoff() -> str:
    """Blank lines for the people who prepare, check and approve the qualification."""
    rows = [[role, "", "", "", ""] for role in ("Prepared by", "Checked by", "Approved by")]
    return (
        "<p>By signing, the reviewer confirms the banners above were read and the dataset "
        "(sha256 in the header) is the one the test was run on.</p>"
        + table(["role", "name", "function", "date", "signature"], rows, cls="signoff")
    )


def page(title: str, header: str, banners: str, sections: Mapping[str, str]) -> str:
    """The whole document: title, header, banners, then the sections in order (each
    with an ``id`` from its name, e.g. ``answer``, for links and print rules)."""
    body = "".join(
        f'<section id="{_anchor(name)}"><h2>{html.escape(name)}</h2>{content}</section>'
        for name, content in sections.items()
    )
    return (
        "<!DOCTYPE html><html lang='en'><head><meta charset='utf-8'>"
        f"<title>{html.escape(title)}</title><style>{_CSS}</style></head><body>"
        f"<h1>{html.escape(title)}</h1>{header}{banners}{body}</body></html>"
    )


def _anchor(name: str) -> str:
    word = name.split(":")[0].split()[0].lower()
    return "".join(c for c in word if c.isalnum())
