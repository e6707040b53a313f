"""Shared test set-up: 64-bit JAX (importing idtool turns it on), a headless backend,
when compiled programs are dropped, and the order in which two xdist workers take the
files."""

import gc
import os
from pathlib import Path

from openblas_helpers import set_openblas_threads

os.environ.setdefault("MPLBACKEND", "Agg")
# One OpenBLAS thread per process, as the command line sets (idtool/_cli/_main.py): two
# xdist workers on two cores with OpenBLAS's own threads each spun waiting on the other's
# small solves (tests/test_plan.py: 41 -> 30 CPU s; an in-process fit_levels 5.7 -> 2.9 s,
# the same estimates). Read by OpenBLAS when NumPy and SciPy load it: set here, before
# they load in this process, and inherited by the xdist workers and notebook kernels
# (tests/test_threads.py checks it). A plugin may have loaded NumPy's already (a run
# without xdist): that one is set through its C interface.
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
# No on-disk compilation cache in tests (the CLI turns it on when ``main`` runs): it did
# not save time here (42.6 against 42.0 CPU minutes), and tests should not depend on
# what an earlier run left on disk. (Worker crashes inside XLA's compiler were blamed on
# it once; their cause was the memory-mapping limit, see the fixture below.) The cache's
# own locking is tested in tests/test_validate_cli.py with an explicit folder.
os.environ["IDTOOL_CACHE_DIR"] = ""

import jax
import pytest

import idtool  # (importing it enables jax_enable_x64)

set_openblas_threads(int(os.environ["OPENBLAS_NUM_THREADS"]))

assert jax.config.jax_enable_x64, "idtool must switch JAX to 64-bit floats"


def _memory_mappings() -> int | None:
    """This process's memory mappings (Linux), else None."""
    try:
        with open("/proc/self/maps", "rb") as f:
            return sum(1 for _ in f)
    except OSError:
        return None


def _mapping_limit() -> int:
    try:
        with open("/proc/sys/vm/max_map_count") as f:
            return int(f.read())
    except (OSError, ValueError):
        return 65530  # the kernel's default


# Drop the compiled programs once a worker holds 40% of the kernel's mapping limit
# (26 212 of the default 65 530): the largest module added 12 647 mappings to a clean
# worker, so the next module cannot reach the limit. Below it, programs are kept from
# one module to the next, which reuse them (the same designs and models).
CLEAR_AT_MAPPINGS = int(0.4 * _mapping_limit())


@pytest.fixture(autouse=True, scope="module")
def _release_compiled_programs():
    """Drop JAX's compiled programs after a test module when the worker holds many.

    An xdist worker runs many modules in one process, and every compiled XLA program
    keeps its code mapped: a worker that never dropped them reached 49 945 memory
    mappings of the kernel's 65 530 (``vm.max_map_count``), where ``mmap`` fails and
    XLA's compiler crashes the worker (segfault or abort inside
    ``backend_compile_and_load``, three fresh-clone runs lost a worker that way). They
    are dropped at :data:`CLEAR_AT_MAPPINGS`, and after every module where the count
    cannot be read (no ``/proc``).
    """
    yield
    count = _memory_mappings()
    if count is None or count >= CLEAR_AT_MAPPINGS:
        jax.clear_caches()
        gc.collect()


# --- the bank: fitted benches that several test files read -----------------------------
#
# Session-scoped (so once per xdist worker; the files that read them are one unit of
# :data:`GROUPS`, so one worker fits each). Read-only: a test that writes into one copies
# it first.


@pytest.fixture(scope="session")
def small_fit_folder(tmp_path_factory) -> Path:
    """``fits/small`` as ``idtool fit`` writes it, from the cached fit of seed 1 of the
    small design (``sample_helpers.small_fit``: 270 and 670 N x 50 and 70%, ON 1 s and
    2 s, 8 traces; the noise-only model). Read by tests/test_predict.py and
    tests/test_arviz.py."""
    from sample_helpers import small_fit

    from idtool._fit._artefact import fit_artefact, state_arrays
    from idtool._fit._folder import FIT_STATE
    from idtool._fit._store import write_artefact
    from idtool._report._fit_text import fit_json

    dataset, run = small_fit(1)
    root = tmp_path_factory.mktemp("bank-small")
    data_dir = idtool.write_dataset(dataset, root / "data")
    out = root / "fits" / "small"
    out.mkdir(parents=True)
    doc = fit_json(run, str(data_dir.resolve()), ["fit", str(data_dir), "--out", str(out)])
    states = {FIT_STATE.name: state_arrays(run.chosen)}
    write_artefact(out, fit_artefact(doc, "", dataset, run.data, states))
    return out


@pytest.fixture(scope="session")
def example_default_run():
    """The shipped example's fit with every default (seed 0), as ``idtool.fit`` runs it
    (``fit_dataset``; 24 traces, the levels model): read by tests/test_fit.py,
    tests/test_sample_until_converged.py and tests/test_variability.py, each of which
    fitted it itself before (three cold fits of 20-30 CPU s on two workers). A frozen
    ``FitRun``: a test that needs a :class:`idtool.Fit` wraps it in its own
    (``Fit.from_run``), so one file's posterior or folder never reaches another."""
    from idtool._fit._run import fit_dataset

    return fit_dataset(idtool.load_dataset(idtool.example_dataset_path()), seed=0)


@pytest.fixture(scope="session")
def readme_run(tmp_path_factory) -> tuple[dict, Path]:
    """The README's Python API script, as printed (fit, report, save, sample until
    converged with seed 0, save_posterior, predict, amplitude_for), run once in a folder
    of its own: its namespace and that folder. Read by tests/test_api.py (the script
    runs with public names) and tests/test_sample_until_converged.py (its chain, the
    example's uninterrupted default one, is what a stopped and resumed ``idtool sample``
    must equal bit for bit): the example's default chain runs once for both (6,400
    steps; it ran once more before)."""
    text = (Path(__file__).parents[1] / "README.md").read_text()
    code = text.split("## Python API")[1].split("```python\n")[1].split("```")[0]
    folder = tmp_path_factory.mktemp("readme")
    scope: dict = {"__readme_code__": code}
    here = os.getcwd()
    os.chdir(folder)
    try:
        exec(compile(code, "README.md", "exec"), scope)
    finally:
        os.chdir(here)
    return scope, folder


# --- xdist: which worker takes what, and in which order ---------------------------------
#
# ``--dist loadfile`` (the Makefile's) gives each worker whole units, in the order they
# were collected: the module and session fixtures (a fit, a posterior) run once per
# worker. Compilation is most of a first fit (the example's default fit: 25 s cold, 4 s
# again in the same process), and a worker keeps its compiled programs from one module
# to the next (above), so the files that fit benches of the same shapes (the same
# designs, the same models) are one unit: one worker compiles their programs once, and
# the session's fitted benches (the bank, above) are fitted once. The run ends when
# the slower worker does, so the units go heaviest first (longest processing time
# first: the light ones fill in at the end). The files of SPLIT_BY_PARAMETER are split by
# their parameter, each value a unit of its own: their tests share no fixture, and one
# file alone would hold a worker for minutes.
GROUPS: dict[str, tuple[str, ...]] = {
    # the example's design (the paper's 24-trace matrix): its default fit (the bank's
    # example_default_run, read by test_fit, test_sample_until_converged and
    # test_variability) and posterior, and the departure benches of the coverage test on
    # the same matrix; and 270 and 670 N x 50 and 70%, one 2 s ON window, 3 s sliding
    # either side: 4 traces (test_fit, test_report, test_validate_fit). One unit, as
    # test_fit reads both (it also compiles the example's fit afresh: it checks which
    # programs a fit compiles, from cleared caches)
    "the paper's matrix and four traces": (
        "tests/test_api.py",
        "tests/test_coverage.py",
        "tests/test_sample_until_converged.py",
        "tests/test_variability.py",
        "tests/test_fit.py",
        "tests/test_report.py",
        "tests/test_validate_fit.py",
        # fits the example with every default and samples it (in this process: 33 ->
        # 13 CPU s after these files)
        "tests/test_notebooks.py[03_uncertainty_design_maps]",
    ),
    # sample_helpers.small_params: the bank's small fit, its posteriors
    "the small design": ("tests/test_arviz.py", "tests/test_predict.py", "tests/test_sample.py"),
}
SPLIT_BY_PARAMETER = ("tests/test_notebooks.py",)
# Seconds a file takes (a split file's part by its parameter), its tests' setup and call
# as --junitxml totals them, in a full run on two busy cores (2026-11-27, an AMD EPYC whose
# run took 35.6 min: about 2.8 times the machine of the figures before); the levels
# files' estimated after their programs were shared. Only the order depends on them: a
# stale figure costs balance, never a test; a file not listed is taken as light, and
# goes last.
FILE_SECONDS: dict[str, float] = {
    "tests/test_coupling_sdof.py": 302,
    "tests/test_coupling_laws.py": 238,
    "tests/test_coverage.py": 216,
    "tests/test_sample.py": 192,
    "tests/test_levels_sample.py": 190,
    "tests/test_api.py": 183,
    "tests/test_variability.py": 240,
    "tests/test_fit.py": 151,
    "tests/test_artefact.py": 140,
    "tests/test_compare.py": 139,
    "tests/test_plateau_drift.py": 133,
    "tests/test_transducer.py": 132,
    "tests/test_arviz.py": 120,
    "tests/test_fit_law.py": 240,
    "tests/test_levels_discrepancy.py": 20,
    "tests/test_levels_drift.py": 110,
    "tests/test_relaxing_on.py": 107,
    "tests/test_report.py": 104,
    "tests/test_lm.py": 84,
    "tests/test_levels_compare.py": 80,
    "tests/test_sample_until_converged.py": 77,
    "tests/test_notebooks.py[02_fit_new_material]": 76,
    "tests/test_direction_auto.py": 75,
    "tests/test_coverage_fading.py": 74,
    "tests/test_cli_model.py": 73,
    "tests/test_levels_choice.py": 90,
    "tests/test_levels_plan.py": 120,
    "tests/test_speed_design.py": 63,
    "tests/test_plan.py": 62,
    "tests/test_sd_conditional.py": 59,
    "tests/test_notebooks.py[03_uncertainty_design_maps]": 56,
    "tests/test_direction.py": 52,
    "tests/test_study.py": 51,
    "tests/test_notebooks.py[01_seed_model]": 50,
    "tests/test_arrowhead.py": 38,
    "tests/test_parameter_settings.py": 36,
    "tests/test_levels_table.py": 110,
    "tests/test_levels_coupling_check.py": 150,
    "tests/test_ridge_jump.py": 35,
    "tests/test_predict.py": 34,
    "tests/test_cov_blocks.py": 31,
    "tests/test_coupling_load_power.py": 26,
    "tests/test_validate_fit.py": 26,
    "tests/test_toy_parts.py": 24,
    "tests/test_table_fast.py": 24,
    "tests/test_contact.py": 19,
    "tests/test_off_corner.py": 19,
    "tests/test_toy_noise.py": 18,
    "tests/test_priors.py": 17,
    "tests/test_mains.py": 15,
    "tests/test_actuator.py": 13,
    "tests/test_ridge.py": 11,
    "tests/test_box.py": 11,
    "tests/test_reml_rows.py": 8,
    "tests/test_import.py": 8,
    "tests/test_xla_pool.py": 8,
    "tests/test_departures.py": 7,
    "tests/test_offset.py": 7,
    "tests/test_simulate.py": 7,
    "tests/test_validate_cli.py": 7,
    "tests/test_funnel.py": 6,
    "tests/test_dataset.py": 5,
    "tests/test_simulator_schema.py": 5,
    "tests/test_compiled.py": 4,
}
_GROUP_OF = {path: name for name, paths in GROUPS.items() for path in paths}


def _split_unit(nodeid: str) -> str:
    """``nodeid``'s file, or its file and parameter for :data:`SPLIT_BY_PARAMETER`."""
    path = nodeid.split("::", 1)[0]
    if path in SPLIT_BY_PARAMETER and nodeid.endswith("]") and "[" in nodeid:
        return f"{path}[{nodeid[nodeid.index('[') + 1 : -1]}]"
    return path


def work_unit(nodeid: str) -> str:
    """The unit of ``nodeid`` a worker takes whole: the group of :data:`GROUPS` that
    lists its file (or its file and parameter), else :func:`_split_unit`."""
    unit = _split_unit(nodeid)
    return _GROUP_OF.get(unit, _GROUP_OF.get(nodeid.split("::", 1)[0], unit))


def _unit_seconds(nodeids: list[str]) -> dict[str, float]:
    """Estimated seconds of each unit: the sum of its parts' figures (a file's, or a
    split file's part's own, else its share of the file's)."""
    parts_of: dict[str, set[str]] = {}
    for nodeid in nodeids:
        parts_of.setdefault(nodeid.split("::", 1)[0], set()).add(_split_unit(nodeid))
    seconds: dict[str, float] = {}
    counted: set[str] = set()
    for nodeid in nodeids:
        part, path = _split_unit(nodeid), nodeid.split("::", 1)[0]
        if part in counted:
            continue
        counted.add(part)
        share = FILE_SECONDS.get(part, FILE_SECONDS.get(path, 1.0) / len(parts_of[path]))
        unit = work_unit(nodeid)
        seconds[unit] = seconds.get(unit, 0.0) + share
    return seconds


@pytest.hookimpl(trylast=True)
def pytest_collection_modifyitems(config, items):
    """Heaviest unit first (:data:`FILE_SECONDS`); a unit's tests together, in their
    order. Every process collects the same items, so all sort alike."""
    first: dict[str, int] = {}
    for i, item in enumerate(items):
        first.setdefault(work_unit(item.nodeid), i)
    seconds = _unit_seconds([item.nodeid for item in items])
    items.sort(key=lambda item: (-seconds[work_unit(item.nodeid)], first[work_unit(item.nodeid)]))


def pytest_configure(config):
    if config.pluginmanager.hasplugin("xdist"):
        config.pluginmanager.register(_UnitsHeaviestFirst(), "idtool-units-heaviest-first")


class _UnitsHeaviestFirst:
    @pytest.hookimpl(tryfirst=True)
    def pytest_xdist_make_scheduler(self, config, log):
        """``--dist loadfile`` with the units of :func:`work_unit`, taken in the order
        collected (sorted above) rather than by their number of tests."""
        if config.getvalue("dist") != "loadfile":
            return None
        from xdist.scheduler import LoadScopeScheduling

        class UnitsHeaviestFirst(LoadScopeScheduling):
            def _split_scope(self, nodeid: str) -> str:
                return work_unit(nodeid)

        config.option.loadscopereorder = False
        return UnitsHeaviestFirst(config, log)
