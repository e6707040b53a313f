"""The command line's side of the idtool server (:mod:`idtool._cli._server`).

A command run from a shell is a fresh interpreter: importing JAX, equinox and idtool
(about 1.3 s) and tracing and lowering the fit's programs (about 2.5 s; the persistent
compilation cache only saves XLA's compile) come back every time, however often the
same kind of bench is fitted. ``idtool server start`` keeps one interpreter with all of
that in memory; while it runs, the ``idtool`` console script hands each command to it:
its arguments, working folder and environment, and its standard input, output and error
themselves (file descriptors passed over a Unix socket), so the command prints, writes
and exits exactly as it would in-process. Without a server, or with
``IDTOOL_SERVER=off``, or when the server is busy with another command, the command
runs in-process as ever.

A server serves only the installation that started it: its socket is named after a
:func:`fingerprint` of the Python executable, the installed distributions, idtool's own
sources and the environment variables read when JAX starts; edit a source file or
upgrade a package and the commands run in-process until a server of the new
installation is started.

This module imports nothing heavy: it runs before every command.
"""

from __future__ import annotations

import hashlib
import json
import os
import socket
import sys
from pathlib import Path
from typing import Any

from idtool._cli._cache import compilation_cache_settings

__all__ = [
    "Lines",
    "ServerGone",
    "fingerprint",
    "forward",
    "request",
    "send",
    "server_dir",
    "socket_path",
]

# environment variables read once, when JAX, XLA or idtool's cache start: a server
# started under other values would compute differently (or elsewhere) than in-process
# (not MPLBACKEND: the commands draw on bare Figures, written as PNG whatever it says)
_STARTUP_ENV = ("JAX_", "XLA_", "TF_CPP_", "IDTOOL_CACHE_DIR", "OMP_")
# set by every command from IDTOOL_CACHE_DIR (idtool._cli._cache.enable_compilation_cache)
_SET_BY_IDTOOL = tuple(name.upper() for name in compilation_cache_settings(""))


class ServerGone(RuntimeError):
    """The server closed the connection before saying the command's exit status."""


def server_dir() -> Path:
    """Where servers keep their sockets and logs: ``$IDTOOL_SERVER_DIR``, default
    ``~/.cache/idtool/server``."""
    default = Path("~/.cache/idtool/server").expanduser()
    return Path(os.environ.get("IDTOOL_SERVER_DIR") or default)


def fingerprint() -> str:
    """A hash of what decides a command's result besides its arguments and inputs:
    the interpreter, the installed distributions (their ``*.dist-info`` names carry
    the versions), idtool's source files and the start-up environment variables."""
    h = hashlib.sha256()
    h.update(sys.executable.encode())
    h.update(sys.version.encode())
    for entry in sys.path:
        if entry and os.path.isdir(entry):
            names = sorted(n for n in os.listdir(entry) if n.endswith(".dist-info"))
            h.update("\0".join(names).encode())
    root = Path(__file__).resolve().parents[1]
    for path in sorted(root.rglob("*.py")):
        h.update(path.relative_to(root).as_posix().encode())
        h.update(path.read_bytes())
    for name in sorted(os.environ):
        if name.startswith(_STARTUP_ENV) and not name.startswith(_SET_BY_IDTOOL):
            h.update(f"{name}={os.environ[name]}".encode())
    return h.hexdigest()[:20]


def socket_path() -> Path:
    """The socket of this installation's server."""
    return server_dir() / f"{fingerprint()}.sock"


def _connect(path: Path) -> socket.socket | None:
    sock = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    try:
        sock.connect(str(path))
    except OSError:  # no server, or a socket left by one that died
        sock.close()
        return None
    return sock


def send(sock: socket.socket, message: dict[str, Any], fds: list[int] | None = None) -> None:
    """One message: a line of JSON (with file descriptors passed alongside)."""
    data = (json.dumps(message) + "\n").encode()
    if fds:
        socket.send_fds(sock, [data], fds)
    else:
        sock.sendall(data)


class Lines:
    """The messages from a socket, one JSON line each; :meth:`next` is None once it
    closes. Its buffer survives a ``KeyboardInterrupt`` in the middle of a read."""

    def __init__(self, sock: socket.socket) -> None:
        self.sock, self.buffer = sock, b""

    def next(self) -> dict[str, Any] | None:
        while b"\n" not in self.buffer:
            chunk = self.sock.recv(65536)
            if not chunk:
                return None
            self.buffer += chunk
        line, self.buffer = self.buffer.split(b"\n", 1)
        return json.loads(line)


def request(path: Path, message: dict[str, Any], timeout_s: float = 5.0) -> dict | None:
    """Send ``message`` to the server at ``path`` and return its answer; None if no
    server answers there."""
    sock = _connect(path)
    if sock is None:
        return None
    with sock:
        sock.settimeout(timeout_s)
        try:
            send(sock, message)
            return Lines(sock).next()
        except (OSError, ValueError):
            return None


def _standard_fds_open() -> bool:
    try:
        for fd in (0, 1, 2):
            os.fstat(fd)
    except OSError:
        return False
    return True


def forward(argv: list[str]) -> int | None:
    """Run the command ``argv`` in this installation's server; its exit status, or
    None where it must run in-process (no server, ``IDTOOL_SERVER=off``, the server
    busy, a standard stream closed, or ``idtool server ...`` itself)."""
    if os.environ.get("IDTOOL_SERVER", "").lower() in ("off", "0", "no"):
        return None
    if not argv or argv[0] == "server" or not _standard_fds_open():
        return None
    sock = _connect(socket_path())
    if sock is None:
        return None
    with sock:
        try:
            run = {"op": "run", "argv": argv, "cwd": os.getcwd(), "env": dict(os.environ)}
            send(sock, run, [0, 1, 2])
            answers = Lines(sock)
            first = answers.next()
        except OSError:
            return None
        if first is None or first.get("op") != "started":
            return None  # busy with another command (or going away): run it here
        return _wait(sock, answers)


def _wait(sock: socket.socket, answers: Lines) -> int:
    """The command's exit status once the server sends it; Ctrl-C here interrupts the
    command there (which cleans up and exits with 130, as in-process)."""
    while True:
        try:
            message = answers.next()
        except KeyboardInterrupt:
            try:
                send(sock, {"op": "interrupt"})
            except OSError:
                return 130
            continue
        if message is None:
            raise ServerGone(
                f"the idtool server stopped during the command (its log: "
                f"{socket_path().with_suffix('.log')}); run the command again "
                "(with IDTOOL_SERVER=off to run it without the server)"
            )
        if message.get("op") == "exit":
            return int(message["code"])
