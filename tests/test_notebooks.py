"""The notebooks run headless, start to finish, and are valid jupytext notebooks."""

import runpy
import sys
from pathlib import Path

import jupytext
import pytest

NOTEBOOKS = sorted((Path(__file__).parents[1] / "notebooks").glob("[0-9][0-9]_*.py"))


def test_there_are_notebooks():
    assert len(NOTEBOOKS) >= 2


@pytest.mark.parametrize("path", NOTEBOOKS, ids=lambda p: p.stem)
def test_notebook_is_a_paired_jupytext_notebook(path):
    nb = jupytext.read(path)
    kinds = {cell.cell_type for cell in nb.cells}
    assert kinds == {"markdown", "code"}
    assert nb.cells[0].cell_type == "markdown" and nb.cells[0].source.startswith("# ")


@pytest.mark.parametrize("path", NOTEBOOKS, ids=lambda p: p.stem)
def test_notebook_runs_headless(path, tmp_path, monkeypatch):
    """Each notebook runs start to finish as a script, in a fresh namespace and an empty
    folder. In this process rather than a kernel of its own: a notebook that fits the
    example finds its programs compiled by the tests beside it (tests/conftest.py puts
    it in their worker; 03: 33 -> 13 CPU s), where a new process compiled them all again.
    What a kernel added is not checked here: the notebooks show nothing interactively
    (the Agg backend), and imports, x64 and the figures are theirs either way."""
    import matplotlib.pyplot as plt

    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr(sys, "argv", [str(path)])
    try:
        runpy.run_path(str(path), run_name="__main__")
    finally:
        plt.close("all")
