"""Shared test set-up: 64-bit JAX (importing idtool turns it on) and a headless backend."""

import os

os.environ.setdefault("MPLBACKEND", "Agg")
# No on-disk compilation cache in tests (the CLI turns it on when ``main`` runs): it did
# not save time here (42.6 against 42.0 CPU minutes), and tests should not depend on
# what an earlier run left on disk. (Worker crashes inside XLA's CPU compile were blamed
# on it once; one recurred with it off, under load: its stack's
# ``_compile_and_write_cache`` is JAX's compile path whenever
# ``jax_enable_compilation_cache`` is on, its default, folder or not.) The cache's own
# locking is tested in tests/test_validate_cli.py with an explicit folder.
os.environ["IDTOOL_CACHE_DIR"] = ""

import jax

import idtool  # noqa: F401  (enables jax_enable_x64)

assert jax.config.jax_enable_x64, "idtool must switch JAX to 64-bit floats"
