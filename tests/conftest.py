"""Shared test set-up: 64-bit JAX (importing idtool turns it on) and a headless backend."""

import os

os.environ.setdefault("MPLBACKEND", "Agg")

import jax

import idtool  # noqa: F401  (enables jax_enable_x64)

assert jax.config.jax_enable_x64, "idtool must switch JAX to 64-bit floats"
