"""The fit's programs kept on disk (idtool._fit._compiled): a fresh process loads them
without tracing; a changed source or a corrupt file makes them traced again, never an
error."""

from __future__ import annotations

from pathlib import Path

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from idtool._data._blocks import DataLabels
from idtool._fit import _compiled
from idtool._fit._compiled import SUBFOLDER, Program

pytest.importorskip("flatbuffers", reason="jax.export's serialisation needs flatbuffers")


class Line(eqx.Module):
    """An equinox module with an array and a static field, in and out (its tree
    structure holds equinox's MISSING marker, which the kept output tree must keep)."""

    slope: jax.Array
    label: str = eqx.field(static=True)


TRACES: list[str] = []


def line_at(line: Line, x, scale):
    TRACES.append(line.label)  # runs once per trace, not per call
    return Line(line.slope * x * scale, line.label + "'")


@pytest.fixture
def folder(tmp_path):
    """JAX's compilation cache folder set to ``tmp_path`` (restored after)."""
    before = jax.config.jax_compilation_cache_dir
    jax.config.update("jax_compilation_cache_dir", str(tmp_path))
    TRACES.clear()
    yield tmp_path / SUBFOLDER
    jax.config.update("jax_compilation_cache_dir", before)


def _args():
    return Line(jnp.array([1.0, 2.0]), "a"), np.array([3.0, 4.0]), 0.5


def test_a_fresh_program_loads_the_kept_one_without_tracing(folder):
    out = Program(line_at)(*_args())
    assert TRACES == ["a"]
    assert len(list(folder.glob("line_at-*.bin"))) == 1
    again = Program(line_at)(*_args())  # as a fresh process: nothing in memory
    assert TRACES == ["a"]
    assert again.label == out.label == "a'"
    np.testing.assert_array_equal(again.slope, [1.5, 4.0])
    np.testing.assert_array_equal(again.slope, out.slope)
    # other shapes or a static field of another value: another program
    Program(line_at)(Line(jnp.array([1.0, 2.0, 3.0]), "a"), np.ones(3), 0.5)
    Program(line_at)(Line(jnp.array([1.0, 2.0]), "b"), np.ones(2), 0.5)
    assert TRACES == ["a", "a", "b"]
    assert len(list(folder.glob("line_at-*.bin"))) == 3


class Labelled(eqx.Module):
    """An array and a dataset's labels (static: names no program computes with)."""

    x: jax.Array
    labels: DataLabels = eqx.field(static=True)


def _labels(name: str) -> DataLabels:
    return DataLabels(name, "0" * 64, (f"{name}_1", f"{name}_2"), 2, "rig", 0.0, ())


def scaled(data: Labelled, k):
    TRACES.append(data.labels.name)
    return data.x * k


def passed_on(data: Labelled):
    TRACES.append(data.labels.name)
    return Labelled(data.x * 2.0, data.labels)


def test_another_dataset_of_the_same_shape_loads_the_kept_program(folder):
    """A dataset's name and trace ids (DataLabels) are not in the key: a second
    dataset of the same shape, in a fresh process, neither traces nor keeps another."""
    first = Program(scaled)(Labelled(jnp.array([1.0, 2.0]), _labels("first")), 3.0)
    out = Program(scaled)(Labelled(jnp.array([5.0, 6.0]), _labels("second")), 3.0)
    assert TRACES == ["first"]
    assert len(list(folder.glob("scaled-*.bin"))) == 1
    np.testing.assert_array_equal(first, [3.0, 6.0])
    np.testing.assert_array_equal(out, [15.0, 18.0])
    a, b = (jax.tree.structure(Labelled(jnp.zeros(2), _labels(name))) for name in ("a", "b"))
    assert str(a) != str(b) and _compiled.structure_text(a) == _compiled.structure_text(b)
    # the rest of the static data is still keyed
    Program(scaled)(Labelled(jnp.array([1.0, 2.0, 3.0]), _labels("third")), 3.0)
    assert TRACES == ["first", "third"]


def test_a_program_whose_output_holds_labels_is_not_kept(folder):
    """Its output tree would give the first dataset's labels to the next one."""
    out = Program(passed_on)(Labelled(jnp.array([1.0, 2.0]), _labels("first")))
    assert out.labels.name == "first"
    np.testing.assert_array_equal(out.x, [2.0, 4.0])
    assert not list(folder.glob("passed_on-*.bin"))


def test_a_changed_source_traces_again(folder, monkeypatch):
    Program(line_at)(*_args())
    monkeypatch.setattr(_compiled, "_environment", lambda: "another source hash")
    out = Program(line_at)(*_args())
    assert TRACES == ["a", "a"]
    np.testing.assert_array_equal(out.slope, [1.5, 4.0])
    assert len(list(folder.glob("line_at-*.bin"))) == 2


@pytest.mark.parametrize("content", [b"", b"not a pickle", b"\x80\x04N."])
def test_a_corrupt_file_is_traced_again_and_replaced(folder, content):
    Program(line_at)(*_args())
    (path,) = folder.glob("line_at-*.bin")
    path.write_bytes(content)
    out = Program(line_at)(*_args())
    assert TRACES == ["a", "a"]
    np.testing.assert_array_equal(out.slope, [1.5, 4.0])
    assert path.read_bytes() != content
    Program(line_at)(*_args())  # the replacement loads
    assert TRACES == ["a", "a"]


def test_the_source_hash_changes_with_any_python_file_and_only_with_those(tmp_path):
    (tmp_path / "sub").mkdir()
    (tmp_path / "a.py").write_text("x = 1\n")
    (tmp_path / "sub" / "b.py").write_text("y = 2\n")
    before = _compiled.tree_hash(tmp_path)
    (tmp_path / "notes.md").write_text("not code")
    assert _compiled.tree_hash(tmp_path) == before
    (tmp_path / "sub" / "b.py").write_text("y = 3\n")
    assert _compiled.tree_hash(tmp_path) != before
    (tmp_path / "sub" / "b.py").write_text("y = 2\n")
    (tmp_path / "sub" / "b.py").rename(tmp_path / "sub" / "c.py")  # a module renamed
    assert _compiled.tree_hash(tmp_path) != before
    assert _compiled.source_hash() == _compiled.tree_hash(Path(_compiled.__file__).parents[1])


def test_without_the_compilation_cache_it_is_jax_jit_and_keeps_nothing(tmp_path):
    assert _compiled.program_folder() is None  # the tests run without JAX's disk cache
    program = Program(line_at)
    TRACES.clear()
    out = program(*_args())
    program(*_args())
    assert TRACES == ["a"]
    assert program._cache_size() == 1
    np.testing.assert_array_equal(out.slope, [1.5, 4.0])
    assert not any(tmp_path.iterdir())


def test_the_command_line_keeps_the_programs_beside_its_compilation_cache(tmp_path):
    """The console script switches JAX's cache on before JAX is imported (environment
    variables): the programs' folder follows it."""
    import os
    import subprocess
    import sys

    code = (
        "from idtool._cli._cache import enable_compilation_cache\n"
        "enable_compilation_cache()\n"
        "from idtool._fit._compiled import program_folder\n"
        "print(program_folder())\n"
    )
    env = os.environ | {"IDTOOL_CACHE_DIR": str(tmp_path / "jax")}
    out = subprocess.run(
        [sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True
    )
    assert out.stdout.strip() == str(tmp_path / "jax" / SUBFOLDER)


def test_a_program_without_compiler_options_compiles_quickly():
    """XLA's options default to QUICK_COMPILE (fusion emitters off, LLVM at -O1), in the
    jitted fallback and in the key alike; options given are kept as given."""
    quick = Program(line_at)
    assert quick._options == {"compiler_options": _compiled.QUICK_COMPILE}
    assert quick.jitted._jit_info.compiler_options_kvs == tuple(_compiled.QUICK_COMPILE.items())
    given = {"xla_backend_optimization_level": 0}
    assert Program(line_at, compiler_options=given)._options == {"compiler_options": given}
