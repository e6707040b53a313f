"""``idtool server start|stop|status``: one interpreter that keeps JAX, idtool and the
traced programs in memory, and runs the commands of the ``idtool`` console script.

A repeated ``idtool fit`` of the example takes about 8 s in a fresh interpreter (with
the persistent compilation cache warm), most of it importing and tracing; in the
server, about 2.5 s. Opt-in: nothing starts a server but ``idtool server start``, and
it stops after ``--idle-minutes`` without a command (default 30) or on ``idtool server
stop``. How a command reaches it, and when it does not: :mod:`idtool._cli._client`.

The server runs one command at a time, in its main thread, as ``idtool`` would: with
the client's arguments, working folder, environment and standard streams (so output,
``--force``, the atomic outputs and the exit statuses are the command line's own); a
command arriving while it is busy runs in its own interpreter instead. Ctrl-C in the
client interrupts the command in the server (exit status 130, nothing written).
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import queue
import signal
import socket
import subprocess
import sys
import threading
import time
import traceback
from pathlib import Path
from typing import Any

from idtool._cli import _client
from idtool._cli._args import load_numerics
from idtool._cli._main import build_parser, main
from idtool._errors import IdtoolError

__all__ = ["register", "serve"]

_STOP = object()


def _log(text: str) -> None:
    # the server's own stdout is its log file (between commands)
    print(f"{time.strftime('%Y-%m-%d %H:%M:%S')} {text}", flush=True)


def _warm_imports() -> None:
    """What every fitting command imports, before the first command waits for it."""
    import matplotlib

    matplotlib.use("Agg")  # the server has no display; idtool only writes files
    load_numerics()  # the fit, its models and JAX (no freeze here: _collect does it)
    build_parser()


class _Server:
    """The listening socket, the queue of commands and the state ``status`` reports."""

    def __init__(self, path: Path, idle_s: float) -> None:
        self.path, self.idle_s = path, idle_s
        self.jobs: queue.Queue = queue.Queue()
        self.busy = threading.Lock()  # held from accepting a command to its exit status
        self.started = time.time()
        self.served = 0
        self.sent_back = 0  # commands that arrived busy and ran in their own process
        self.running: socket.socket | None = None  # the connection of the running command
        self.state = threading.Lock()  # guards `running` against a late interrupt

    def status(self) -> dict[str, Any]:
        return {
            "op": "status",
            "pid": os.getpid(),
            "socket": str(self.path),
            "started": self.started,
            "served": self.served,
            "sent_back": self.sent_back,
            "busy": self.busy.locked(),
            "idle_minutes": self.idle_s / 60.0,
        }

    def accept_forever(self, listener: socket.socket) -> None:
        """Acceptor thread: answers ``status`` and ``stop`` at once, queues a command
        if the server is free, else tells the client to run it itself."""
        while True:
            conn, _ = listener.accept()
            fds: list[int] = []
            try:
                conn.settimeout(5.0)  # a client that says nothing must not hold the door
                data, fds, _flags, _addr = socket.recv_fds(conn, 1 << 20, 3)
                while data and b"\n" not in data:  # a long environment, in pieces
                    chunk = conn.recv(1 << 20)
                    if not chunk:
                        break
                    data += chunk
                message = json.loads(data.split(b"\n", 1)[0])
                conn.settimeout(None)
            except (OSError, ValueError):
                for fd in fds:
                    os.close(fd)
                conn.close()
                continue
            op = message.get("op")
            if op == "run" and len(fds) == 3 and self.busy.acquire(blocking=False):
                self.jobs.put((conn, message, fds))
                continue
            for fd in fds:
                os.close(fd)
            with conn, contextlib.suppress(OSError):
                if op == "status":
                    _client.send(conn, self.status())
                elif op == "stop":
                    _client.send(conn, self.status() | {"op": "stopping"})
                    self.jobs.put(_STOP)
                else:
                    self.sent_back += 1
                    _client.send(conn, {"op": "busy"})

    def watch(self, conn: socket.socket) -> None:
        """While a command runs: the client's Ctrl-C (or its end: nobody waits for the
        result any more) interrupts it."""
        answers = _client.Lines(conn)
        while True:
            try:
                message = answers.next()
            except (OSError, ValueError):
                message = None
            if message is not None and message.get("op") != "interrupt":
                continue
            with self.state:
                if self.running is conn:
                    import _thread

                    _thread.interrupt_main()
            return

    def run(self, conn: socket.socket, message: dict[str, Any], fds: list[int]) -> None:
        """One command, with the client's streams, folder and environment."""
        argv = [str(a) for a in message["argv"]]
        began = time.perf_counter()
        code = 1
        saved = [os.dup(i) for i in range(3)]
        env, cwd = dict(os.environ), os.getcwd()
        try:
            with self.state:
                self.running = conn
            threading.Thread(target=self.watch, args=(conn,), daemon=True).start()
            _client.send(conn, {"op": "started"})
            for i, fd in enumerate(fds):
                os.dup2(fd, i)
            os.chdir(message["cwd"])
            os.environ.clear()
            os.environ.update(message["env"])
            code = _run_command(argv)
        except KeyboardInterrupt:  # a late interrupt, after the command had finished
            pass
        except OSError as err:  # the client went away, or its folder did
            print(f"idtool: {err}", file=sys.stderr)
        finally:
            with self.state:
                self.running = None
            for stream in (sys.stdout, sys.stderr):
                with contextlib.suppress(Exception):
                    stream.flush()
            for i, fd in enumerate(saved):
                os.dup2(fd, i)
                os.close(fd)
            for fd in fds:
                os.close(fd)
            os.environ.clear()
            os.environ.update(env)
            os.chdir(cwd)
            with contextlib.suppress(OSError):
                _client.send(conn, {"op": "exit", "code": code})
            conn.close()
            self.served += 1
            _release_programs_if_many()
            self.busy.release()
        _log(f"{' '.join(argv)}: exit {code} in {time.perf_counter() - began:.2f} s")

    def loop(self) -> None:
        """Main thread: run the queued commands until ``stop`` or ``idle_s`` without."""
        while True:
            try:
                job = self.jobs.get(timeout=self.idle_s)
            except queue.Empty:
                _log(f"idle for {self.idle_s / 60:g} minutes: stopping")
                return
            except KeyboardInterrupt:  # a late interrupt, between commands
                continue
            if job is _STOP:
                _log("stopping, as asked")
                return
            self.run(*job)
            _collect()


def _run_command(argv: list[str]) -> int:
    """``idtool ARGV`` as the console script runs it; its exit status."""
    import warnings

    try:
        with warnings.catch_warnings():  # a command's filters stay its own
            return main(argv)
    except SystemExit as stop:  # argparse: --help, --version, bad arguments
        if stop.code is None or isinstance(stop.code, int):
            return stop.code or 0
        print(stop.code, file=sys.stderr)
        return 1
    except KeyboardInterrupt:  # before main's own handler (parsing)
        return 130
    except Exception:  # an idtool bug: the traceback the console script would print
        traceback.print_exc()
        return 1
    finally:
        pyplot = sys.modules.get("matplotlib.pyplot")
        if pyplot is not None:  # a figure a command left open is not the next one's
            pyplot.close("all")


# Every compiled XLA program keeps its code memory-mapped; past the kernel's limit
# (vm.max_map_count, 65 530 by default) XLA's compiler crashes (tests/conftest.py). A
# server fitting benches of many shapes drops its programs well before: they are in
# the disk cache, and only tracing them again is lost.
_MAX_MAPPINGS = 30_000


def _collect() -> None:
    """Between commands (their clients have their exit status): collect what the last
    one left, and exempt what survives (imports, traced programs, caches) from the
    collector's later scans (``gc.freeze``). A full collection over the server's heap
    took 0.2 s inside a command; with it frozen, 0.02-0.05 s."""
    import gc

    gc.collect()
    gc.freeze()


def _release_programs_if_many() -> None:
    try:
        with open("/proc/self/maps", "rb") as maps:
            mappings = sum(1 for _ in maps)
    except OSError:  # not Linux
        return
    if mappings > _MAX_MAPPINGS:
        import gc

        import jax

        gc.unfreeze()  # the programs dropped are frozen (_collect): let them go
        jax.clear_caches()
        gc.collect()
        _log(f"{mappings} memory mappings: compiled programs released")


def serve(path: Path, idle_minutes: float) -> None:
    """Listen on ``path`` and run commands until stopped or idle (the server process)."""
    _warm_imports()
    _collect()
    # a command's stdout is often a terminal: print line by line as in-process there
    sys.stdout.reconfigure(line_buffering=True)  # type: ignore[union-attr]
    server = _Server(path, idle_minutes * 60.0)
    listener = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    with contextlib.suppress(FileNotFoundError):
        path.unlink()  # left by a server that died (start checked nobody answers there)
    listener.bind(str(path))
    os.chmod(path, 0o600)
    listener.listen(16)
    threading.Thread(target=server.accept_forever, args=(listener,), daemon=True).start()
    # kill PID: stop as on 'idtool server stop' (the socket removed), not mid-write
    signal.signal(signal.SIGTERM, lambda *_: server.jobs.put(_STOP))
    _log(f"serving on {path} (pid {os.getpid()})")
    try:
        server.loop()
    finally:
        with contextlib.suppress(FileNotFoundError):
            path.unlink()
        listener.close()


def _start(args: argparse.Namespace) -> int:
    path = _client.socket_path()
    answer = _client.request(path, {"op": "status"})
    if answer is not None:
        print(f"idtool server already running (pid {answer['pid']}), on {path}")
        return 0
    path.parent.mkdir(parents=True, exist_ok=True, mode=0o700)
    if len(str(path)) > 100:  # AF_UNIX paths: 108 bytes on Linux
        raise IdtoolError(
            f"the server's socket path {path} is too long for a Unix socket; "
            "set IDTOOL_SERVER_DIR to a shorter folder"
        )
    log = path.with_suffix(".log")
    with open(log, "a") as out:
        process = subprocess.Popen(
            [sys.executable, "-m", "idtool._cli._server", str(path), str(args.idle_minutes)],
            stdin=subprocess.DEVNULL,
            stdout=out,
            stderr=subprocess.STDOUT,
            start_new_session=True,  # the terminal's Ctrl-C is for the client
            cwd="/",
        )
    deadline = time.monotonic() + args.wait_s
    while time.monotonic() < deadline:
        answer = _client.request(path, {"op": "status"})
        if answer is not None:
            if not args.quiet:
                print(
                    f"idtool server running (pid {answer['pid']}); it stops after "
                    f"{args.idle_minutes:g} idle minutes, or on 'idtool server stop'"
                )
            return 0
        if process.poll() is not None:
            break
        time.sleep(0.1)
    process.kill()
    raise IdtoolError(f"the idtool server did not start; its log: {log}")


def _servers() -> list[tuple[Path, dict]]:
    """Every server answering in :func:`~idtool._cli._client.server_dir` (this
    installation's and others')."""
    found = []
    for path in sorted(_client.server_dir().glob("*.sock")):
        answer = _client.request(path, {"op": "status"})
        if answer is not None:
            found.append((path, answer))
    return found


def _stop(args: argparse.Namespace) -> int:
    stopped = 0
    for path, _ in _servers():
        if _client.request(path, {"op": "stop"}) is not None:
            stopped += 1
            deadline = time.monotonic() + args.wait_s
            while path.exists() and time.monotonic() < deadline:
                time.sleep(0.05)
    if not args.quiet:
        print(f"stopped {stopped} idtool server{'s' if stopped != 1 else ''}")
    return 0


def _status(args: argparse.Namespace) -> int:
    mine = _client.socket_path()
    found = [answer | {"current": path == mine} for path, answer in _servers()]
    if args.json:
        print(json.dumps({"socket": str(mine), "servers": found}, indent=2))
        return 0
    if not found:
        print("no idtool server running")
    for s in found:
        which = "this installation" if s["current"] else "another installation (or sources)"
        print(
            f"pid {s['pid']}: {which}; {s['served']} commands served "
            f"({s['sent_back']} sent back busy), "
            f"{'busy' if s['busy'] else 'idle'}, up {time.time() - s['started']:.0f} s; "
            f"{s['socket']}"
        )
    return 0


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "server",
        help="keep idtool in memory for fast repeated commands (start, stop, status)",
        description=__doc__.split("\n\n")[0].replace("``", "'"),
    )
    p.add_argument("action", choices=("start", "stop", "status"))
    p.add_argument(
        "--idle-minutes",
        type=float,
        default=30.0,
        help="start: stop after this many minutes without a command (default 30)",
    )
    p.add_argument(
        "--wait-s", type=float, default=60.0, help="how long start and stop wait (default 60)"
    )
    p.add_argument("--json", action="store_true", help="status: as JSON")
    actions = {"start": _start, "stop": _stop, "status": _status}
    p.set_defaults(func=lambda args: actions[args.action](args))


if __name__ == "__main__":
    serve(Path(sys.argv[1]), float(sys.argv[2]))
