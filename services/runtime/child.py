"""Work that needs heavy modules, done in a child process, so a process that lives on does not hold
them: `up` loading a compose file and building every Node to read what it declares (numba, scipy,
pymunk, maps and JIT caches: over 100 MB), `navigate` checking its goals on the map (numba and
scipy). The child is a fresh interpreter (`python -m` this module) that reads the pickled call on
stdin and writes each pickled outcome on stdout as soon as it has it; it ends with everything it
imported. Its stderr is the parent's."""
from __future__ import annotations

import inspect
import pickle
import signal
import subprocess
import sys
from typing import Any, Callable


class ChildDied(RuntimeError):
    """The child process ended without the answer waited for."""


class Child:
    """function(*args) running in a child process; `next()` is its result or, for a generator, the
    next value it yields. The function (module-level), its arguments, values and exceptions must
    pickle; what it raises is raised by `next()`."""

    def __init__(self, function: Callable[..., Any], *args: Any):
        self.what = function.__qualname__
        self.proc = subprocess.Popen([sys.executable, "-m", __spec__.name], stdin=subprocess.PIPE,
                                     stdout=subprocess.PIPE)
        self.proc.stdin.write(pickle.dumps((function, args)))
        self.proc.stdin.close()

    def next(self) -> Any:
        try:
            ok, outcome = pickle.load(self.proc.stdout)
        except (EOFError, pickle.UnpicklingError):
            raise ChildDied(f"the process running {self.what} ended (exit {self.proc.wait()}) before it "
                            "answered") from None
        if not ok:
            raise outcome
        return outcome

    def close(self) -> None:
        """Stop the child if it is still working and reap it."""
        if self.proc.poll() is None:
            self.proc.kill()
        self.proc.wait()
        self.proc.stdout.close()

    def __enter__(self) -> Child:
        return self

    def __exit__(self, *_exc) -> None:
        self.close()


def call_in_child(function: Callable[..., Any], *args: Any) -> Any:
    """function(*args) in a child process: its result, or what it raised."""
    with Child(function, *args) as child:
        return child.next()


def _serve() -> None:
    signal.signal(signal.SIGINT, signal.SIG_IGN)     # a Ctrl-C is the parent's to handle
    function, args = pickle.loads(sys.stdin.buffer.read())
    out = sys.stdout.buffer
    sys.stdout = sys.stderr             # what the function prints must not mix with the answers
    try:
        outcome = function(*args)
        for value in outcome if inspect.isgenerator(outcome) else (outcome,):
            out.write(pickle.dumps((True, value)))
            out.flush()
    except Exception as exc:
        out.write(pickle.dumps((False, exc)))


if __name__ == "__main__":
    _serve()
