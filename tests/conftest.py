"""Shared test set-up: 64-bit JAX (importing idtool turns it on), a headless backend,
and one on-disk compilation cache for the whole run."""

import os
from pathlib import Path

os.environ.setdefault("MPLBACKEND", "Agg")

import jax

import idtool  # noqa: F401  (enables jax_enable_x64)
from idtool._cli._main import compilation_cache_settings

assert jax.config.jax_enable_x64, "idtool must switch JAX to 64-bit floats"

# The CLI's compilation cache, in the repository's .pytest_cache unless IDTOOL_CACHE_DIR
# says otherwise (empty: off), for both xdist workers and every subprocess (notebooks,
# the console script: through JAX's environment variables). Many test files fit the
# same example dataset with the same models; each process compiled the same programs
# again, and compilation is most of a first fit's time. The cache is locked between
# processes (tests/test_validate_cli.py), and its keys hold the program and the jaxlib
# version, so an entry left by an older checkout is never used for another program.
_CACHE = os.environ.setdefault(
    "IDTOOL_CACHE_DIR", str(Path(__file__).parents[1] / ".pytest_cache" / "jax")
)
if _CACHE:
    for _name, _value in compilation_cache_settings(_CACHE).items():
        jax.config.update(_name, _value)
        os.environ[_name.upper()] = str(_value)
