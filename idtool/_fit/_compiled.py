"""The fit's traced programs kept on disk, so that a fresh process skips tracing them.

A warm ``idtool fit`` of the example in a fresh process spent ~2 s (summed over its
threads) tracing its Levenberg-Marquardt and REML programs in Python before JAX's
persistent compilation cache could be asked for their executables: that cache is keyed
by the lowered module, so every process traced again. Here each program is exported
(``jax.export``: its StableHLO, serialised) under a key computed without tracing: a hash
of idtool's source files, the JAX and jaxlib versions, the backend, 64-bit mode and
XLA_FLAGS, the program's name and JIT options, and the arguments' tree structure
(static fields included, but for labels: :func:`structure_text`) and abstract values
(shape, dtype, weak type). A fresh process
deserialises it (milliseconds), lowers the call to it and finds the executable in JAX's
persistent cache as before.

The executable itself (``jax.experimental.serialize_executable``) would also skip the
lowering, but with jaxlib 0.10.2 on CPU an executable that had been loaded from JAX's
cache and serialised again failed in the next process ("Function
bitcast_concatenate_fusion.5 not found"), and loading one while another thread ran a
program crashed the process: not a cache to trust.

The programs live in ``idtool-programs/`` inside JAX's compilation cache folder, and
only while that cache is on (the command line switches it on,
:mod:`idtool._cli._cache`; a Python session may, with
``jax.config.update("jax_compilation_cache_dir", ...)``); otherwise :class:`Program`
is the plain ``jax.jit``. A file that cannot be read, deserialised or compiled
(truncated, corrupt, of other shapes) is traced again and replaced, never an error.
Files are written whole and renamed into place, so concurrent processes see a whole
file or none. Serialising needs the ``flatbuffers`` package; without it nothing is kept
and every process traces, as before.

Loading a file runs pickle (for the output's tree structure): the folder is trusted as
JAX's own cache is.
"""

from __future__ import annotations

import functools
import hashlib
import io
import logging
import os
import pickle
import sys
import tempfile
import threading
from collections.abc import Callable
from pathlib import Path
from typing import Any

import jax
import jaxlib
from equinox._module import _flatten as eqx_flatten

__all__ = [
    "QUICK_COMPILE",
    "SUBFOLDER",
    "Program",
    "program",
    "program_folder",
    "source_hash",
    "structure_text",
    "tree_hash",
]

_log = logging.getLogger(__name__)

SUBFOLDER = "idtool-programs"  # inside JAX's compilation cache folder

# XLA's options for a program whose decorator gives none. XLA:CPU's default (fusion
# emitters, LLVM at -O2) compiled the levels model's REML programs in 1.5-4.2 s each
# (fit_sds, evaluate; 2 cores, load 8), these in 0.2-0.4 s; the fit's numbers moved by
# one rounding (REML's log-likelihood, 1.6e-16 relative). The Levenberg-Marquardt
# program chose the same (idtool._fit._program).
QUICK_COMPILE = {"xla_cpu_use_fusion_emitters": False, "xla_backend_optimization_level": 1}
_FORMAT = 1  # of the files; bumped when what they hold changes


def tree_hash(root: Path) -> str:
    """SHA-256 of the Python source files under ``root`` (relative path and bytes,
    sorted)."""
    digest = hashlib.sha256()
    for path in sorted(root.rglob("*.py")):
        digest.update(path.relative_to(root).as_posix().encode())
        digest.update(path.read_bytes())
    return digest.hexdigest()


@functools.cache
def source_hash() -> str:
    """:func:`tree_hash` of the idtool package: any edit of its source makes every
    program's key new (~5 ms, once per process)."""
    return tree_hash(Path(__file__).resolve().parents[1])


def program_folder() -> Path | None:
    """Where compiled programs are kept: ``idtool-programs`` in JAX's compilation cache
    folder, or None when that cache is off."""
    folder = jax.config.jax_compilation_cache_dir  # type: ignore[attr-defined]
    return Path(folder) / SUBFOLDER if folder else None


@functools.cache
def _environment() -> str:
    """What an executable depends on besides the program and its arguments."""
    device = jax.devices()[0]
    return repr(
        (
            _FORMAT,
            source_hash(),
            jax.__version__,
            jaxlib.__version__,
            sys.version_info[:2],
            device.platform,
            device.device_kind,
            device.client.platform_version,
            os.environ.get("XLA_FLAGS", ""),
        )
    )


@functools.lru_cache(maxsize=256)
def structure_text(tree: Any) -> str:
    """The tree structure ``tree`` as text for a program's key: node types, their static
    data and children, as ``str(tree)`` shows them, except that a static value whose
    class sets ``program_key`` (a string) shows as that string.

    Such a value is a label that no program computes with and that every instance of
    its class equals (:class:`idtool._data._blocks.DataLabels`: a dataset's name and
    trace ids): JAX's caches then take a second dataset of the same shape for the
    first, and with it keyed here by its string, so does the folder. Keyed by its
    repr, a new dataset's programs were traced and kept again. A program's output must
    hold no label (as for ``jax.jit``, whose cache would give the first call's):
    one that does is not kept on disk.

    Kept per tree structure (equal structures give equal texts: ~1 ms a call, 46 calls
    in a fit of the example)."""
    return _text(tree, [])


def _text(tree: Any, labels: list[str]) -> str:
    """:func:`structure_text`, appending the labels met to ``labels``."""
    data = tree.node_data()
    if data is None:
        return "*"
    kind, aux = data
    children = ", ".join(_text(child, labels) for child in tree.children())
    return f"{kind.__module__}.{kind.__qualname__}[{_static_text(aux, labels)}]({children})"


def _static_text(value: Any, labels: list[str]) -> str:
    """``repr(value)``, with :func:`structure_text`'s labels as their ``program_key``."""
    label = getattr(type(value), "program_key", None)
    if isinstance(label, str):
        labels.append(label)
        return label
    if isinstance(value, tuple | list):
        inner = ", ".join(_static_text(v, labels) for v in value)
        return f"({inner},)" if isinstance(value, tuple) else f"[{inner}]"
    if isinstance(value, dict):
        items = (f"{k!r}: {_static_text(v, labels)}" for k, v in value.items())
        return "{" + ", ".join(items) + "}"
    return repr(value)


def _has_label(tree: Any) -> bool:
    """Whether a static value of ``tree`` is a label (:func:`structure_text`)."""
    labels: list[str] = []
    _text(tree, labels)
    return bool(labels)


class Program:
    """``jax.jit(fn, **jit_options)`` whose executables are kept on disk
    (:func:`program_folder`, module docstring) and in memory, by the arguments' tree
    structure and abstract values. ``fn`` takes no static arguments (a static value
    belongs in a pytree's static fields, whose repr is part of the key: it must show
    the whole value, as equinox's static fields and dataclasses do; a label no program
    computes with may say so, :func:`structure_text`). Without ``compiler_options``,
    XLA's are :data:`QUICK_COMPILE`."""

    def __init__(self, fn: Callable[..., Any], **jit_options: Any):
        jit_options.setdefault("compiler_options", QUICK_COMPILE)
        self.jitted: Any = jax.jit(fn, **jit_options)
        self._fn = fn
        self._options = jit_options
        self._name = f"{fn.__module__}.{fn.__qualname__}"
        self._loaded: dict[str, tuple[Any, Any]] = {}  # key -> (executable, out tree)
        self._locks: dict[str, threading.Lock] = {}
        self._guard = threading.Lock()
        functools.update_wrapper(self, fn)

    def __call__(self, *args: Any) -> Any:
        folder = program_folder()
        if folder is None:
            return self.jitted(*args)
        leaves, tree = jax.tree.flatten(args)
        executable, out_tree = self._executable(folder, leaves, tree)
        return jax.tree.unflatten(out_tree, executable(*leaves))

    def compile_ahead(self, *args: Any) -> None:
        """Make the program for arguments like ``args`` ready (loaded or compiled, and
        kept), for a later call to find (:class:`~idtool._fit._prefetch.CompileAhead`)."""
        folder = program_folder()
        if folder is None:
            self.jitted.lower(*args).compile()
            return
        leaves, tree = jax.tree.flatten(args)
        self._executable(folder, leaves, tree)

    def _cache_size(self) -> int:
        """Programs held in this process (traced by ``jax.jit`` or kept here)."""
        return self.jitted._cache_size() + len(self._loaded)

    def key(self, leaves: list[Any], tree: Any) -> str:
        """The key of the executable for arguments ``tree.unflatten(leaves)``."""
        avals = [str(jax.typeof(x)) for x in leaves]
        text = repr((_environment(), self._name, self._options, structure_text(tree), avals))
        return hashlib.sha256(text.encode()).hexdigest()

    def _executable(self, folder: Path, leaves: list[Any], tree: Any) -> tuple[Any, Any]:
        key = self.key(leaves, tree)
        with self._guard:
            found = self._loaded.get(key)
            lock = self._locks.setdefault(key, threading.Lock())
        if found is not None:
            return found
        with lock:  # one thread compiles; another asking for it waits and reuses it
            found = self._loaded.get(key)
            if found is None:
                path = folder / f"{self._fn.__name__}-{key}.bin"
                found = self._load(path, leaves) or self._compile(path, leaves, tree)
                with self._guard:
                    self._loaded[key] = found
        return found

    def _compile(self, path: Path, leaves: list[Any], tree: Any) -> tuple[Any, Any]:
        """Trace and lower the function on the flat leaves (a flat tree is what
        ``jax.export`` serialises), keep it in ``path``, and compile it."""
        out_tree: list[Any] = []

        def flat(*xs: Any) -> list[Any]:  # named as fn in JAX's logs and XLA's dumps
            out, structure = jax.tree.flatten(self._fn(*jax.tree.unflatten(tree, xs)))
            out_tree.append(structure)
            return out

        flat.__name__ = flat.__qualname__ = self._fn.__name__
        try:
            exported = jax.export.export(jax.jit(flat))(*leaves)
        except Exception:  # not exportable (a host callback): compiled, not kept
            _log.info("could not export %s", self._name, exc_info=True)
            return jax.jit(flat, **self._options).lower(*leaves).compile(), out_tree[-1]
        if _has_label(out_tree[-1]):  # another dataset's call would get these labels
            _log.info("not keeping %s: its output holds a label", self._name)
            return self._compiled(exported, leaves), out_tree[-1]
        try:
            with io.BytesIO() as buffer:
                _Pickler(buffer).dump((bytes(exported.serialize()), out_tree[-1]))
                payload = buffer.getvalue()
            path.parent.mkdir(parents=True, exist_ok=True)
            with tempfile.NamedTemporaryFile(dir=path.parent, delete=False) as f:
                f.write(payload)
            os.replace(f.name, path)
        except Exception:  # not kept (no flatbuffers, disk full): traced again next time
            _log.info("could not keep the program in %s", path, exc_info=True)
        return self._compiled(exported, leaves), out_tree[-1]

    def _compiled(self, exported: jax.export.Exported, leaves: list[Any]) -> Any:
        """``exported`` compiled for ``leaves`` with this program's options (JAX's
        persistent compilation cache holds the executable of a repeated run)."""
        return jax.jit(exported.call, **self._options).lower(*leaves).compile()

    def _load(self, path: Path, leaves: list[Any]) -> tuple[Any, Any] | None:
        """The program kept in ``path``, compiled for ``leaves``, and its output tree;
        None if there is none or it cannot be read or compiled (then it is traced
        again and replaced)."""
        try:
            blob = path.read_bytes()
        except FileNotFoundError:
            return None
        try:
            serialized, out_tree = pickle.loads(blob)
            return self._compiled(jax.export.deserialize(bytearray(serialized)), leaves), out_tree
        except Exception:
            _log.info("ignoring the unreadable program %s", path, exc_info=True)
            return None


def _eqx_missing() -> object:
    """equinox's marker of a module's array fields in its tree structure."""
    return eqx_flatten.MISSING


class _Pickler(pickle.Pickler):
    """Pickles a tree structure of equinox modules so that it unflattens again:
    equinox tells array fields from static ones by the identity of its marker
    ``MISSING``, which plain pickling would copy (the unflattened module then took the
    marker for a static value and failed)."""

    def reducer_override(self, obj: object) -> Any:
        if obj is eqx_flatten.MISSING:
            return _eqx_missing, ()
        return NotImplemented


def program(**jit_options: Any) -> Callable[[Callable[..., Any]], Program]:
    """Decorator: ``@program(compiler_options=...)`` in place of
    ``@functools.partial(jax.jit, compiler_options=...)`` (:class:`Program`; without
    ``compiler_options``, :data:`QUICK_COMPILE`)."""
    return functools.partial(Program, **jit_options)
