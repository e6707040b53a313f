"""JAX's on-disk compilation cache for the command line: its settings and switching it
on (with it, the fit's traced programs are kept beside it: :mod:`idtool._fit._compiled`).
Imports nothing heavy: it runs before every command."""

from __future__ import annotations

import os
import sys

__all__ = ["CACHE_MAX_BYTES", "compilation_cache_settings", "enable_compilation_cache"]

CACHE_MAX_BYTES = 2 * 1024**3  # the compilation cache's disk use (the demo's: ~100 MB)


def compilation_cache_settings(path: str) -> dict[str, object]:
    """JAX's configuration for the on-disk compilation cache in folder ``path``."""
    return {
        "jax_compilation_cache_dir": path,
        # Every program, however small: two dozen of 20-30 ms each were recompiled on
        # every run below the default threshold (0.6 s of a warm fit).
        "jax_persistent_cache_min_compile_time_secs": 0.0,
        # XLA's own autotuning caches put the cache folder's path into the compile
        # options, so the key of the same program changed with IDTOOL_CACHE_DIR.
        "jax_persistent_cache_enable_xla_caches": "none",
        # A size limit (least recently used entries go) is what makes JAX lock the
        # cache's reads and writes (filelock): without it a second process can read an
        # entry still being written and crash deserialising it.
        "jax_compilation_cache_max_size": CACHE_MAX_BYTES,
    }


def enable_compilation_cache() -> None:
    """Keep compiled XLA programs on disk so a repeated command skips compilation.

    Compilation is most of the time to a first result of a short command. The cache
    lives in ``$IDTOOL_CACHE_DIR`` (default ``~/.cache/idtool/jax``); set it to an empty
    string to disable it. Set through JAX's environment variables, so a command that
    never computes (``validate``, ``--help``) does not import JAX; the configuration
    directly where JAX is loaded already (``main`` called from Python).
    """
    path = os.environ.get("IDTOOL_CACHE_DIR", os.path.expanduser("~/.cache/idtool/jax"))
    if not path:
        return
    settings = compilation_cache_settings(path)
    jax = sys.modules.get("jax")
    for name, value in settings.items():
        if jax is not None:
            jax.config.update(name, value)
        else:
            os.environ[name.upper()] = str(value)
