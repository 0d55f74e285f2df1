"""Service processes forked from one prepared interpreter instead of started afresh.

`up` starts every service as its own OS process. Started afresh, each of them imports numpy,
numba, scipy and zenoh again — a second or more of CPU each, all at once on a 2-core machine — and
holds its own copy of what those imports build (numba's type system and LLVM: about 40 MB a
process). Forked from a server that imported them once (multiprocessing's forkserver, with those
modules preloaded), a service starts with them in place and shares their pages with every other
service until it writes them.

The server is a fresh interpreter started on the first fork (no threads, no Zenoh session: safe to
fork from); it also loads every service kernel from numba's cache (preloaded.py), which saves
another 40 MB a numba service. The services are its children, not `up`'s, so `ForkedProcess` gives
`up` the parts of subprocess.Popen it uses: pid, stdout, poll, wait and returncode. Each service is
the leader of a process group of its own and reads /dev/null, as with Popen(process_group=0,
stdin=DEVNULL); its stdout and stderr go to one pipe that `up` reads. It writes its own command line
over the server's (`ps`, `pgrep -f "omninav run"` and /proc/PID/cmdline show
`python -m omninav.cli.main run costmap …`, as if started afresh) and its name (`top`).

Measured on the room mission (`omninav bench footprint --worlds room --modes separate`, load 5–6):
started afresh 6.5 s to the first goal, 1016 MB PSS; forked from the server without the kernels
3.4 s, 905 MB; with them 2.9 s, 683 MB.
"""
from __future__ import annotations

import ctypes
import ctypes.util
import multiprocessing
import multiprocessing.connection
import importlib
import os
import subprocess
import sys

CLI = "omninav.cli.main"     # what `up` starts: `python -m omninav.cli.main run …`
# imported once in the server: what most services import and is slow to import
PRELOAD = ("numpy", "numba", "scipy.optimize", "scipy.sparse.csgraph", "scipy.spatial", "zenoh", "msgspec", "yaml",
           CLI, "omninav.services.runtime.run", "omninav.services.runtime.live",
           "omninav.services.runtime.preloaded")

_context: multiprocessing.context.ForkServerContext | None = None
PR_SET_NAME = 15      # prctl(2)
STAT_ARG_START = 45   # /proc/PID/stat fields 48 and 49 (arg_start, arg_end), counted after the command's ")"


def _forkserver() -> multiprocessing.context.ForkServerContext:
    global _context
    if _context is None:
        _context = multiprocessing.get_context("forkserver")
        _context.set_forkserver_preload(list(PRELOAD))
    return _context


def _serve(argv: list[str], env: dict[str, str], cwd: str, output: multiprocessing.connection.Connection) -> None:
    """In the forked child: become what `python -m omninav.cli.main *argv` with env, started in cwd,
    would be (the server stays where the first fork found it)."""
    os.setpgid(0, 0)
    os.chdir(cwd)
    os.dup2(output.fileno(), 1)
    os.dup2(output.fileno(), 2)
    output.close()
    os.environ.clear()
    os.environ.update(env)
    sys.stdout = open(1, "w", buffering=1, closefd=False)    # line by line, as PYTHONUNBUFFERED
    sys.stderr = open(2, "w", buffering=1, closefd=False)
    sys.argv = [sys.executable, *argv]
    _show_as([sys.executable, "-m", CLI, *argv])
    sys.exit(importlib.import_module(CLI).main(argv))


def _show_as(argv: list[str]) -> None:
    """Write argv over the process's own command line (cut to the room the server's leaves) and
    the service's name as the process's name."""
    with open("/proc/self/stat", "rb") as stat:
        fields = stat.read().rpartition(b")")[2].split()
    start, end = int(fields[STAT_ARG_START]), int(fields[STAT_ARG_START + 1])
    text = b"\0".join(arg.encode() for arg in argv)[:end - start - 1]
    ctypes.memmove(start, text.ljust(end - start, b"\0"), end - start)
    libc = ctypes.CDLL(ctypes.util.find_library("c"), use_errno=True)
    name = argv[4] if len(argv) > 4 else argv[-1]
    libc.prctl(PR_SET_NAME, name.encode()[:15], 0, 0, 0)


class ForkedProcess:
    """`python -m omninav.cli.main *argv` with environment env, forked from the server."""

    def __init__(self, argv: list[str], env: dict[str, str]):
        context = _forkserver()
        reader, writer = context.Pipe(duplex=False)
        self._argv = argv
        self._process = context.Process(target=_serve, args=(argv, env, os.getcwd(), writer), name=" ".join(argv[:2]))
        self._process.start()
        writer.close()
        self.pid: int = self._process.pid
        self.stdout = os.fdopen(os.dup(reader.fileno()), "rb")
        reader.close()
        self.returncode: int | None = None

    def poll(self) -> int | None:
        if self.returncode is None:
            self.returncode = self._process.exitcode
        return self.returncode

    def wait(self, timeout: float | None = None) -> int:
        self._process.join(timeout)
        if self.poll() is None:
            raise subprocess.TimeoutExpired(self._argv, timeout)
        return self.returncode
