"""``idtool validate``: summary of a good dataset, located problems and exit 2 for a bad one."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest
from bench_data_helpers import (
    CORRUPTIONS,
    TRACE_IDS,
    Corruption,
    expected_location,
    make_dataset,
    set_cell,
)

import idtool
from idtool._cli._main import main


def _console_script() -> str:
    script = Path(sys.executable).with_name("idtool")
    if not script.exists():
        pytest.skip("the idtool console script is not installed next to this Python")
    return str(script)


def test_validate_example(capsys):
    assert main(["validate", str(idtool.example_dataset_path())]) == 0
    out = capsys.readouterr().out
    assert "example-seat-belt-bench" in out and "24 trace(s)" in out
    assert "N670_A50_T2.5" in out and "4.170-6.670" in out
    assert "valid: no errors" in out


def test_validate_json_summary(capsys, tmp_path):
    root = make_dataset(tmp_path / "d")
    assert main(["validate", str(root), "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert [t["id"] for t in summary["traces"]] == list(TRACE_IDS)
    assert summary["traces"][0]["on_windows_s"] == [[0.2, 0.3]]
    assert summary["sha256"] == idtool.load_dataset(root).sha256


def test_quiet_prints_nothing_but_errors_and_keeps_json(capsys, tmp_path):
    root = make_dataset(tmp_path / "d")
    assert main(["validate", str(root), "--quiet"]) == 0
    assert capsys.readouterr() == ("", "")
    assert main(["validate", str(root), "-q", "--json"]) == 0  # asked for: printed
    assert json.loads(capsys.readouterr().out)["sha256"] == idtool.load_dataset(root).sha256
    (root / "dataset.json").write_text("{not json")
    assert main(["validate", str(root), "--quiet"]) == 2
    out, err = capsys.readouterr()
    assert out == "" and "dataset.json" in err


def test_every_command_documents_quiet_and_the_exit_statuses(capsys):
    from idtool._cli._main import build_parser

    parser = build_parser()
    commands = parser._subparsers._group_actions[0].choices  # type: ignore[union-attr]
    for name, command in commands.items():
        text = command.format_help()
        assert "--quiet" in text, name
        assert "3 'sample'" in " ".join(text.split()), name


def test_validate_prints_warnings(capsys, tmp_path):
    root = make_dataset(tmp_path / "d")
    set_cell(root / "traces/b.csv", 30, "time_s", "0.295")
    assert main(["validate", str(root)]) == 0
    out = capsys.readouterr().out
    assert "1 warning(s)" in out and "irregular sampling" in out and "row 31" in out


@pytest.mark.parametrize("case", CORRUPTIONS, ids=lambda c: c.name)
def test_validate_malformed_exits_2_with_located_problem(capsys, tmp_path, case: Corruption):
    root = make_dataset(tmp_path / "d")
    case.apply(root)
    assert main(["validate", str(root)]) == 2
    captured = capsys.readouterr()
    assert "Traceback" not in captured.err + captured.out
    lines = captured.err.splitlines()
    assert lines[0].startswith("idtool validate: ")
    located = [line for line in lines if all(p in line for p in expected_location(root, case))]
    assert located, captured.err


def test_validate_missing_folder(capsys, tmp_path):
    assert main(["validate", str(tmp_path / "nothing")]) == 2
    assert "does not exist" in capsys.readouterr().err


def test_console_script_reports_bad_data_without_traceback(tmp_path):
    """The real installed ``idtool`` command, in a fresh process."""
    script = _console_script()
    root = make_dataset(tmp_path / "d")
    set_cell(root / "traces/a.csv", 7, "force_n", "12;5")
    (root / "traces/b.parquet").write_bytes(b"not parquet at all")
    document = json.loads((root / "dataset.json").read_text())
    document["traces"][1]["file"] = "traces/b.parquet"
    (root / "dataset.json").write_text(json.dumps(document))
    done = subprocess.run([script, "validate", str(root)], capture_output=True, text=True)
    assert done.returncode == 2
    assert "Traceback" not in done.stderr + done.stdout
    assert f"{root / 'traces/a.csv'}, row 7, column 'force_n'" in done.stderr
    assert f"{root / 'traces/b.parquet'}" in done.stderr and "Parquet" in done.stderr

    good = subprocess.run(
        [script, "validate", str(make_dataset(tmp_path / "ok"))], capture_output=True, text=True
    )
    assert good.returncode == 0, good.stderr
    assert "valid: no errors" in good.stdout


def test_the_compilation_cache_is_locked_between_processes(tmp_path):
    """The CLI's on-disk compilation cache has a size limit, which is what makes JAX
    lock its reads and writes (filelock): unlocked, a process read an entry another was
    still writing and segfaulted deserialising it (two test workers, CI)."""
    import filelock  # the lock JAX needs for it  # noqa: F401
    from jax._src.lru_cache import LRUCache

    from idtool._cli._cache import CACHE_MAX_BYTES, compilation_cache_settings

    settings = compilation_cache_settings(str(tmp_path))
    assert settings["jax_compilation_cache_max_size"] == CACHE_MAX_BYTES > 0
    cache = LRUCache(str(tmp_path), max_size=CACHE_MAX_BYTES)
    assert cache.eviction_enabled
    cache.put("k", b"v")
    assert cache.get("k") == b"v" and (tmp_path / ".lockfile").exists()  # it locked


def test_help_validate_and_import_do_not_load_jax(tmp_path):
    """The parser of every command is built on each call, and the fit, sample,
    parameters and curve commands take their choices from the registries, whose modules
    import JAX (about a second): the choices are read only when that command's value is
    checked or its help printed, so ``idtool --help`` and ``idtool validate`` stay
    quick. The choices still reach the help and the error message."""
    code = (
        "import contextlib, io, sys\n"
        "from idtool._cli._main import main\n"
        "for argv in (['--help'], ['validate', '--help']):\n"
        "    with contextlib.redirect_stdout(io.StringIO()), contextlib.suppress(SystemExit):\n"
        "        main(argv)\n"
        "with contextlib.redirect_stdout(io.StringIO()):\n"
        f"    assert main(['validate', {str(idtool.example_dataset_path())!r}]) == 0\n"
        "print(sorted(m for m in ('jax', 'equinox') if m in sys.modules))\n"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == "[]"
    fit_help = subprocess.run(
        [sys.executable, "-m", "idtool._cli._main", "fit", "--help"], capture_output=True, text=True
    ).stdout
    assert "coupling law: constant, exponential, load-power, power-limited, sdof, auto" in " ".join(
        fit_help.split()
    )
    bad = subprocess.run(
        [sys.executable, "-m", "idtool._cli._main", "fit", "x", "--out", str(tmp_path / "o"),
         "--coupling", "bogus"],
        capture_output=True,
        text=True,
    )  # fmt: skip
    assert bad.returncode == 2 and "invalid choice: 'bogus' (choose from 'constant'" in bad.stderr
