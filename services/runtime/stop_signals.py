"""A threading.Event that SIGINT and SIGTERM set, without the deadlock of setting it in the handler.

Python runs a signal handler in the main thread between two bytecodes. A handler that calls
Event.set() itself deadlocks when the signal lands while the main thread, inside Event.wait(), holds
the event's condition lock (a plain Lock: not reentrant) — set() then waits for a lock its own
thread holds. A loop that waits on the event between every two messages (`replay --loop`) hits that
window often enough: once it stayed up 120 s after SIGINT. The handler hands set() — or whatever
stops the process — to a thread.
"""
from __future__ import annotations

import signal
import threading

STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM)


def on_stop_signals(callback) -> None:
    """callback() on a thread of its own at SIGINT or SIGTERM (installed only from the main thread,
    the one Python delivers signals to)."""
    if threading.current_thread() is threading.main_thread():
        for sig in STOP_SIGNALS:
            signal.signal(sig, lambda *_: threading.Thread(target=callback, daemon=True).start())


def stop_event() -> threading.Event:
    """An event set on SIGINT or SIGTERM (off the main thread only set by hand)."""
    stop = threading.Event()
    on_stop_signals(stop.set)
    return stop
