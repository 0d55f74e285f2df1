"""Work that needs heavy modules, done in a child process, so a process that lives on does not hold
them: `up` loading a compose file and building every Node to read what it declares (numba, scipy,
pymunk, maps and JIT caches: over 100 MB), `navigate` checking its goals on the map (numba and
scipy) and preparing its compose file for `up` in the same child. The child is a fresh interpreter
(`python -m` this module) that reads the pickled call on stdin and writes each pickled outcome on
stdout as soon as it has it; it ends with everything it imported. Its stderr is the parent's. Its
answers may be relayed to a third process (Child.relay), which reads them as Answers."""
from __future__ import annotations

import contextlib
import inspect
import pickle
import signal
import subprocess
import sys
import threading
from typing import IO, Any, Callable


class ChildDied(RuntimeError):
    """The child process ended without the answer waited for."""


class Answers:
    """The answers of a child's function read from a stream as they come: `next()` is its result or,
    for a generator, the next value it yields; what it raised is raised by `next()`."""

    def __init__(self, stream: IO[bytes], what: str):
        self.stream, self.what = stream, what

    def next(self) -> Any:
        try:
            ok, outcome = pickle.load(self.stream)
        except (EOFError, pickle.UnpicklingError):
            raise ChildDied(f"the process running {self.what} ended{self._exit()} before it answered") from None
        if not ok:
            raise outcome
        return outcome

    def _exit(self) -> str:
        return ""

    def close(self) -> None:
        """Nothing to stop: whoever runs the child does."""

    def __enter__(self) -> Answers:
        return self

    def __exit__(self, *_exc) -> None:
        self.close()


class Child(Answers):
    """function(*args) running in a child process. The function (module-level), its arguments,
    values and exceptions must pickle."""

    def __init__(self, function: Callable[..., Any], *args: Any):
        self.proc = subprocess.Popen([sys.executable, "-m", __spec__.name], stdin=subprocess.PIPE,
                                     stdout=subprocess.PIPE)
        self.proc.stdin.write(pickle.dumps((function, args)))
        self.proc.stdin.close()
        super().__init__(self.proc.stdout, function.__qualname__)

    def _exit(self) -> str:
        return f" (exit {self.proc.wait()})"

    def relay(self, sink: IO[bytes]) -> threading.Thread:
        """Copy the answers not yet read onto sink as they come, in a thread, close it after the last
        and reap the child: the process reading sink takes them as Answers (`up --prepared` those of
        navigate's child)."""
        def copy() -> None:
            try:
                while chunk := self.stream.read1(1 << 16):
                    sink.write(chunk)
                    sink.flush()
            except BrokenPipeError:     # the reader ended (up stopped): nothing more to hand over
                pass
            with contextlib.suppress(BrokenPipeError):
                sink.close()
            self.proc.wait()        # reaped now, not left in the process table for the run
        thread = threading.Thread(target=copy, name=f"relay-{self.what}", daemon=True)
        thread.start()
        return thread

    def close(self) -> None:
        """Stop the child if it is still working and reap it."""
        if self.proc.poll() is None:
            self.proc.kill()
        self.proc.wait()
        self.proc.stdout.close()


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
