"""Griffe extension for the API reference: idtool's docstrings cite with Sphinx roles
(``:func:`load_fit```, ``:class:`~idtool.Dataset```), which Markdown would print as
they are. A role naming a public name of ``idtool`` (or a member of one) becomes a
cross-reference to its entry in the reference; any other target (a private module or
helper, another package) becomes inline code. The docstrings themselves stay as they
are: the source is read, not changed.
"""

from __future__ import annotations

import ast
import re
from pathlib import Path
from typing import Any

import griffe

ROLE = re.compile(r":(?:py:)?(?:func|class|meth|data|attr|exc|obj|mod|const):`(~?)([^`]+)`")
INIT = Path(__file__).resolve().parents[2] / "idtool" / "__init__.py"


def public_names() -> frozenset[str]:
    """``idtool.__all__``, read from the source (nothing is imported): ``__version__``
    and the keys of the lazy table ``_LAZY``, the one list of public names."""
    for node in ast.parse(INIT.read_text()).body:
        if isinstance(node, ast.Assign) and any(
            isinstance(t, ast.Name) and t.id == "_LAZY" for t in node.targets
        ):
            return frozenset({"__version__", *ast.literal_eval(node.value)})
    raise RuntimeError(f"no _LAZY in {INIT}")


PUBLIC = public_names()


def replace_role(match: re.Match[str]) -> str:
    tilde, target = match.groups()
    path = target.removeprefix("idtool.")
    parts = path.split(".")
    shown = parts[-1] if tilde else target
    linkable = parts[0] in PUBLIC and len(parts) <= 2 and not any(p.startswith("_") for p in parts)
    if linkable:
        return f"[`{shown}`][idtool.{path}]"
    return f"`{shown}`"


class SphinxRoles(griffe.Extension):
    """Rewrite Sphinx roles in every docstring griffe reads."""

    def on_instance(self, *, obj: griffe.Object, **kwargs: Any) -> None:
        if obj.docstring is not None and ":" in obj.docstring.value:
            obj.docstring.value = ROLE.sub(replace_role, obj.docstring.value)
