"""Shared test set-up: 64-bit JAX (importing idtool turns it on) and a headless backend."""

import os

os.environ.setdefault("MPLBACKEND", "Agg")
# No on-disk compilation cache in tests (the CLI turns it on when ``main`` runs): twice
# a fresh-clone run lost an xdist worker to a segfault inside JAX with the cache on
# (reading an entry, b204230; compiling-and-writing one, this session's CI), never with
# it off; and it did not save time here (42.6 against 42.0 CPU minutes). The cache's
# own locking is tested in tests/test_validate_cli.py with an explicit folder.
os.environ["IDTOOL_CACHE_DIR"] = ""

import jax

import idtool  # noqa: F401  (enables jax_enable_x64)

assert jax.config.jax_enable_x64, "idtool must switch JAX to 64-bit floats"
