"""MkDocs hooks: pages made from the repository's own files at build time, and a check.

* ``notebooks/NN_*.py`` (paired jupytext ``py:percent`` notebooks) become
  ``notebooks/NN_*.md``: markdown cells as they are, code cells as Python blocks. They
  are shown without outputs (``tests/test_notebooks.py`` runs them); converting instead
  of executing keeps the build offline and a few seconds long.
* ``datasets_schema/README.md`` becomes ``dataset-format.md`` with the JSON Schema files
  beside it, so its links work and the schemas can be downloaded from the site. The
  format stays written once, where the package installs it.
* ``CONTRIBUTING.md`` and ``CHANGELOG.md`` become the pages ``contributing.md`` and
  ``changelog.md``, their links into ``docs/`` (and to the format's README) made
  relative to the site.
* Every page's code blocks are checked for imports of private modules (``idtool._*``):
  examples use the public API only. A hit is a warning, so ``mkdocs build --strict``
  fails.
"""

from __future__ import annotations

import logging
import re
from pathlib import Path

from mkdocs.structure.files import File, Files

log = logging.getLogger("mkdocs.hooks.pages")

ROOT = Path(__file__).resolve().parents[2]
NOTEBOOKS = "notebooks"
SCHEMA_README = ROOT / "datasets_schema" / "README.md"
# Files at the repository root that GitHub shows there and the site shows as pages; their
# links into docs/ are rewritten to the site's.
PROJECT_PAGES = {"CONTRIBUTING.md": "contributing.md", "CHANGELOG.md": "changelog.md"}
PRIVATE_IMPORT = re.compile(r"^\s*(from|import)\s+idtool\._", re.MULTILINE)
FENCE = re.compile(r"^```[^\n]*\n(.*?)^```", re.MULTILINE | re.DOTALL)


def notebook_markdown(path: Path) -> str:
    """A jupytext notebook as a Markdown page (its title first, then where it lives)."""
    import jupytext

    nb = jupytext.read(path)
    parts: list[str] = []
    for i, cell in enumerate(nb.cells):
        source = cell.source.strip("\n")
        if cell.cell_type == "markdown":
            parts.append(source)
        elif source:
            parts.append(f"```python\n{source}\n```")
        if i == 0:
            rel = path.relative_to(ROOT).as_posix()
            parts.append(
                f'!!! note "Run it yourself"\n'
                f"    This page is `{rel}`, a paired jupytext notebook, shown without its\n"
                f"    outputs. Run it as a script (`.venv/bin/python {rel}`) or open it in\n"
                f"    Jupyter ([Notebooks](../notebooks.md))."
            )
    return "\n\n".join(parts) + "\n"


def on_files(files: Files, config) -> Files:
    for path in sorted((ROOT / NOTEBOOKS).glob("[0-9][0-9]_*.py")):
        files.append(
            File.generated(config, f"{NOTEBOOKS}/{path.stem}.md", content=notebook_markdown(path))
        )
    files.append(File.generated(config, "dataset-format.md", content=SCHEMA_README.read_text()))
    for name, page in PROJECT_PAGES.items():
        text = (ROOT / name).read_text().replace("](docs/", "](")
        text = text.replace("](datasets_schema/README.md", "](dataset-format.md")
        files.append(File.generated(config, page, content=text))
    for schema in sorted(SCHEMA_README.parent.glob("*.schema.json")):
        files.append(File.generated(config, schema.name, abs_src_path=str(schema)))
    return files


def on_page_markdown(markdown: str, page, config, files) -> str:
    for block in FENCE.findall(markdown):
        for hit in PRIVATE_IMPORT.finditer(block):
            line = block[hit.start() :].splitlines()[0].strip()
            log.warning(f"{page.file.src_uri}: an example imports a private module: {line}")
    return markdown
