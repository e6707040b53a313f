"""Shared test set-up: 64-bit JAX (importing idtool turns it on) and a headless backend."""

import gc
import os

os.environ.setdefault("MPLBACKEND", "Agg")
# No on-disk compilation cache in tests (the CLI turns it on when ``main`` runs): it did
# not save time here (42.6 against 42.0 CPU minutes), and tests should not depend on
# what an earlier run left on disk. (Worker crashes inside XLA's compiler were blamed on
# it once; their cause was the memory-mapping limit, see the fixture below.) The cache's
# own locking is tested in tests/test_validate_cli.py with an explicit folder.
os.environ["IDTOOL_CACHE_DIR"] = ""

import jax
import pytest

import idtool  # noqa: F401  (enables jax_enable_x64)

assert jax.config.jax_enable_x64, "idtool must switch JAX to 64-bit floats"


@pytest.fixture(autouse=True, scope="module")
def _release_compiled_programs():
    """Drop JAX's compiled programs after each test module.

    An xdist worker runs many modules in one process, and every compiled XLA program
    keeps its code mapped: a worker reached 49 945 memory mappings of the kernel's
    65 530 (``vm.max_map_count``), where ``mmap`` fails and XLA's compiler crashes the
    worker (segfault or abort inside ``backend_compile_and_load``, three fresh-clone runs
    lost a worker that way). Modules share few programs (their data shapes differ), so
    recompiling those costs little.
    """
    yield
    jax.clear_caches()
    gc.collect()
