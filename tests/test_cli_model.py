"""``idtool curve`` and ``idtool seed-study`` through the command line."""

import json
import os
import subprocess
import sys

import numpy as np
import pandas as pd
import pytest

from idtool._cli._main import main
from idtool._model._limits import coulomb_friction_ratio


def test_curve_json_has_the_documented_keys(capsys):
    assert main(["curve", "--law", "coulomb", "--vr", "0.1,0.5,0.9", "--json"]) == 0
    rows = json.loads(capsys.readouterr().out)
    assert [set(r) for r in rows] == [{"vr", "friction_ratio", "power_ratio"}] * 3
    got = [r["friction_ratio"] for r in rows]
    np.testing.assert_allclose(got, coulomb_friction_ratio(np.array([0.1, 0.5, 0.9])), atol=1e-9)


def test_curve_table_for_each_law(capsys):
    for law in ("coulomb", "dahl", "lugre"):
        assert main(["curve", "--law", law, "--vr", "0.05:0.95:3", "--lambda", "5"]) == 0
        out = capsys.readouterr().out
        assert "friction_ratio" in out and "power_ratio" in out
        assert len(out.strip().splitlines()) == 2 + 3


def test_curve_dahl_spot_value(capsys):
    main(["curve", "--law", "dahl", "--vr", "0.5", "--lambda", "5", "--json"])
    assert json.loads(capsys.readouterr().out)[0]["friction_ratio"] == pytest.approx(
        0.379, abs=2e-3
    )


@pytest.mark.parametrize(
    "args",
    [["--vr", "abc"], ["--vr", "-0.5"], ["--vr", "0.5", "--lambda", "0"], ["--vr", ""]],
)
def test_curve_bad_input_exits_2_with_a_message(args, capsys):
    assert main(["curve", *args]) == 2
    err = capsys.readouterr().err
    assert err.startswith("idtool curve: ") and "Traceback" not in err


def test_console_script_bad_input_has_no_traceback():
    proc = subprocess.run(
        [sys.executable, "-m", "idtool._cli._main", "curve", "--vr", "x"],
        capture_output=True,
        text=True,
        check=False,
    )
    assert proc.returncode == 2
    assert "Traceback" not in proc.stderr and "--vr" in proc.stderr


@pytest.fixture(scope="module")
def seed_study_dir(tmp_path_factory):
    out = tmp_path_factory.mktemp("runs") / "seed"
    assert main(["seed-study", "--out", str(out)]) == 0
    return out


def test_seed_study_writes_figures_and_tidy_csv(seed_study_dir):
    names = sorted(p.name for p in seed_study_dir.iterdir())
    assert [n for n in names if n.endswith(".png")] == [
        "fig10_mass_kg.png",
        "fig11_stiffness_n_m.png",
        "fig8_force_amplitude_n.png",
        "fig9_friction_coefficient.png",
    ]
    for n in names:
        if n.endswith(".png"):
            assert (seed_study_dir / n).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    table = pd.read_csv(seed_study_dir / "seed_study.csv")
    assert list(table.columns) == [
        "figure",
        "parameter",
        "value",
        "velocity_ratio",
        "friction_ratio",
        "power_ratio",
    ]
    assert set(table.figure) == {"fig8", "fig9", "fig10", "fig11"}
    assert np.all(np.isfinite(table[["velocity_ratio", "friction_ratio", "power_ratio"]]))
    prov = json.loads((seed_study_dir / "provenance.json").read_text())
    assert prov["versions"]["jax"] and "seed-study" in prov["command"]


def test_seed_study_shows_the_paper_trends(seed_study_dir):
    table = pd.read_csv(seed_study_dir / "seed_study.csv")

    def at_vr(fig, column, vr=0.5):
        rows = table[table.figure == fig]
        return [
            np.interp(vr, g.velocity_ratio, g[column]) for _, g in rows.groupby("value", sort=True)
        ]

    assert np.all(np.diff(at_vr("fig8", "friction_ratio")) < 0)  # FR falls with Fe
    assert np.all(np.diff(at_vr("fig8", "power_ratio", 0.2)) > 0)  # PDR rises with Fe
    assert np.all(np.diff(at_vr("fig9", "friction_ratio")) > 0)  # FR rises with mu
    assert np.all(np.diff(at_vr("fig10", "friction_ratio")) > 0)  # FR rises with m
    assert np.all(np.diff(at_vr("fig11", "friction_ratio")) < 0)  # FR falls towards resonance
    assert np.allclose(table[table.velocity_ratio > 1.0].friction_ratio, 1.0, atol=1e-9)


def test_seed_study_refuses_to_overwrite_without_force(seed_study_dir, capsys):
    before = (seed_study_dir / "seed_study.csv").read_bytes()
    assert main(["seed-study", "--out", str(seed_study_dir)]) == 2
    assert "--force" in capsys.readouterr().err
    assert (seed_study_dir / "seed_study.csv").read_bytes() == before


def test_only_a_console_process_freezes_its_imports_and_only_once():
    """``load_numerics`` exempts the imports from the garbage collector in the console
    script's process (a one-command process), never in a Python session calling
    ``main`` (frozen cyclic garbage would never be freed there), and once."""
    code = """
import gc
from idtool._cli import _args
_args.load_numerics()
session = gc.get_freeze_count()
_args.freeze_on_load = True
_args.load_numerics()
console = gc.get_freeze_count()
junk = [[i] for i in range(1000)]
_args.load_numerics()
print(session, console > 100_000, gc.get_freeze_count() == console)
"""
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.split() == ["0", "True", "True"]


@pytest.mark.parametrize("console", [False, True])
def test_a_console_process_collects_no_garbage_while_it_imports(console):
    """In the console script's process the collector is off during ``load_numerics``'s
    imports (and on again after); a Python session's collector runs as it would."""
    code = f"""
import gc
from idtool._cli import _args
runs = []
gc.callbacks.append(lambda phase, info: phase == "start" and runs.append(info["generation"]))
_args.freeze_on_load = {console}
_args.load_numerics()
print(len(runs) > 0, gc.isenabled())
"""
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.split() == [str(not console), "True"]


@pytest.mark.parametrize("given, expected", [(None, "1"), ("2", "2")])
def test_the_console_script_sets_one_openblas_thread_before_numpy_loads(given, expected):
    """OpenBLAS reads ``OPENBLAS_NUM_THREADS`` once, when NumPy loads it: the console
    script sets it first (one thread, ``idtool._cli._main.single_threaded_blas``),
    unless the environment gives it."""
    code = """
import os, sys
from idtool._cli import _main
seen = []
real = _main.single_threaded_blas
def spy():
    seen.append("numpy" in sys.modules)
    real()
_main.single_threaded_blas = spy
sys.argv = ["idtool", "curve", "--vr", "0.5", "--json"]
_main.console()
import numpy
print(seen, os.environ["OPENBLAS_NUM_THREADS"], file=sys.stderr)
"""
    env = {k: v for k, v in os.environ.items() if k != "OPENBLAS_NUM_THREADS"}
    if given is not None:
        env["OPENBLAS_NUM_THREADS"] = given
    proc = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True, env=env
    )
    assert proc.stderr.split() == ["[False]", expected]


def test_the_figures_modules_import_in_a_background_thread():
    """``idtool fit`` imports matplotlib while it fits (``import_in_background``): the
    thread imports every module a figure's drawing and saving needs."""
    code = """
import sys
from idtool._plotting import MODULES, import_in_background
assert not any(m in sys.modules for m in MODULES)
thread = import_in_background()
thread.join()
print(thread.daemon, all(m in sys.modules for m in MODULES))
"""
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.split() == ["True", "True"]


def test_scipy_special_is_off_the_fits_import_path_and_imported_in_the_background():
    """The fit's modules leave scipy.special (0.15-0.25 s of import, for one p-value) to
    ``idtool fit``'s background thread (``LATE_IMPORTS``), which imports it."""
    code = """
import sys
import idtool._entry
from idtool._cli._fit import LATE_IMPORTS
from idtool._plotting import import_in_background
print("scipy.special" in sys.modules)
import_in_background(LATE_IMPORTS).join()
print("scipy.special" in sys.modules)
"""
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.split() == ["False", "True"]
