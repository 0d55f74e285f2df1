"""stop_event: SIGINT and SIGTERM set the event, even when they land while the main thread holds
the event's own lock (where a handler calling Event.set() itself deadlocks)."""
import os
import signal
import subprocess
import sys
import threading

import pytest

from omninav.services.runtime.stop_signals import STOP_SIGNALS, stop_event


@pytest.fixture
def saved_handlers():
    before = {sig: signal.getsignal(sig) for sig in STOP_SIGNALS}
    yield
    for sig, handler in before.items():
        signal.signal(sig, handler)


@pytest.mark.parametrize("sig", STOP_SIGNALS)
def test_a_signal_sets_the_event(saved_handlers, sig):
    stop = stop_event()
    os.kill(os.getpid(), sig)
    assert stop.wait(10)


INSIDE_THE_LOCK = """
import os, signal, time
from omninav.services.runtime.stop_signals import stop_event
stop = stop_event()
# the main thread inside Event.wait's critical section, as a waiting loop is a thousand times a second
with stop._cond:
    os.kill(os.getpid(), signal.SIGINT)
    deadline = time.monotonic() + 0.2
    while time.monotonic() < deadline:      # the handler runs here, between two bytecodes
        pass
print("set" if stop.wait(10) else "not set", flush=True)
"""


def test_a_signal_landing_inside_the_events_lock_still_sets_it():
    # in a child: a handler that deadlocks would hang this process for good (SIGTERM included)
    child = subprocess.Popen([sys.executable, "-c", INSIDE_THE_LOCK], stdout=subprocess.PIPE, text=True)
    try:
        out, _ = child.communicate(timeout=60)
    except subprocess.TimeoutExpired:
        child.kill()
        child.communicate()
        pytest.fail("the signal handler deadlocked on the event's lock")
    assert out.strip() == "set"


def test_off_the_main_thread_no_handler_is_installed(saved_handlers):
    before = signal.getsignal(signal.SIGINT)
    made = []
    worker = threading.Thread(target=lambda: made.append(stop_event()))
    worker.start()
    worker.join()
    assert signal.getsignal(signal.SIGINT) is before and not made[0].is_set()
