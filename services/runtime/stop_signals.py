"""How a process is told to stop: SIGINT, SIGTERM and SIGHUP, and its parent's end.

A threading.Event that the stop signals set, without the deadlock of setting it in the handler.

Python runs a signal handler in the main thread between two bytecodes. A handler that calls
Event.set() itself deadlocks when the signal lands while the main thread, inside Event.wait(), holds
the event's condition lock (a plain Lock: not reentrant) — set() then waits for a lock its own
thread holds. A loop that waits on the event between every two messages (`replay --loop`) hits that
window often enough: once it stayed up 120 s after SIGINT. The handler hands set() — or whatever
stops the process — to a thread.

SIGHUP stops like the others: a closed terminal, or a session's end, must not leave a stack
running. A process whose parent ends (killed with SIGKILL, crashed) is re-parented; a supervisor
or service watching for that stops itself rather than run on with nobody left to stop it.
"""
from __future__ import annotations

import os
import signal
import threading
import time

STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)
PARENT_POLL_S = 0.5     # how often a process looks whether its parent is still there


def interrupt_on_stop_signals() -> None:
    """SIGINT, SIGTERM and SIGHUP raise KeyboardInterrupt in the main thread, so a command's
    `finally` (stopping what it started, closing its recording) runs whichever ended it: Ctrl-C,
    `timeout`, a CI job's cancel, a closed terminal. SIGINT too, explicitly: a command a script starts
    in the background (`omninav navigate … &`) inherits SIGINT ignored, and Python then installs no
    KeyboardInterrupt for it - `kill -INT` did nothing and the mission ran to its end."""
    for sig in STOP_SIGNALS:
        signal.signal(sig, signal.default_int_handler)


def on_parent_exit(callback) -> None:
    """callback() on a thread of its own once this process's parent has ended (it is re-parented)."""
    parent = os.getppid()

    def watch() -> None:
        while os.getppid() == parent:
            time.sleep(PARENT_POLL_S)
        callback()
    threading.Thread(target=watch, daemon=True, name="parent-watch").start()


def on_stop_signals(callback) -> None:
    """callback() on a thread of its own at SIGINT, SIGTERM or SIGHUP (installed only from the main
    thread, the one Python delivers signals to)."""
    if threading.current_thread() is threading.main_thread():
        for sig in STOP_SIGNALS:
            signal.signal(sig, lambda *_: threading.Thread(target=callback, daemon=True).start())


def stop_event() -> threading.Event:
    """An event set on SIGINT, SIGTERM or SIGHUP (off the main thread only set by hand)."""
    stop = threading.Event()
    on_stop_signals(stop.set)
    return stop
