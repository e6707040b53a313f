"""The OpenBLAS libraries loaded in this process (NumPy's, SciPy's), read and set
through their C interface (no threadpoolctl in the environment)."""

import ctypes
from pathlib import Path

__all__ = ["openblas_threads", "set_openblas_threads"]

_GET = (
    "scipy_openblas_get_num_threads64_",
    "scipy_openblas_get_num_threads",
    "openblas_get_num_threads64_",
    "openblas_get_num_threads",
)


def _loaded() -> list[str]:
    """Paths of the OpenBLAS libraries mapped into this process (Linux; else none)."""
    try:
        lines = Path("/proc/self/maps").read_text().splitlines()
    except OSError:
        return []
    paths = {line.split()[-1] for line in lines}
    return sorted(p for p in paths if "openblas" in Path(p).name.lower())


def _function(lib: ctypes.CDLL, names: tuple[str, ...]):
    for name in names:
        f = getattr(lib, name, None)
        if f is not None:
            return f
    return None


def openblas_threads() -> dict[str, int]:
    """Each loaded OpenBLAS (file name) and its thread count."""
    found = {}
    for path in _loaded():
        get = _function(ctypes.CDLL(path), _GET)
        if get is not None:
            found[Path(path).name] = int(get())
    return found


def set_openblas_threads(n: int) -> None:
    """Every loaded OpenBLAS to ``n`` threads (one loaded later reads
    ``OPENBLAS_NUM_THREADS`` itself)."""
    for path in _loaded():
        set_ = _function(ctypes.CDLL(path), tuple(g.replace("_get_", "_set_") for g in _GET))
        if set_ is not None:
            set_(ctypes.c_int(n))
