"""Issue 37, nothing left behind: `navigate` ended by SIGTERM (`timeout`, a CI job's cancel), SIGHUP
(a closed terminal) or SIGINT stops its whole stack - `up`, its router and every service - with the
recording closed; killed outright (SIGKILL), it leaves nothing running either: `up` sees its parent
gone and stops the stack itself. (Each case runs a mission's stack in two containers, in lockstep.)"""
import os
import signal
import subprocess
import sys

import pytest
from mcap.reader import make_reader

from conftest import REPO, wait_until
from launching import processes_using, router_of, wait_for

# across the room and back three times: minutes at half real time, so the signal finds the mission under way
GOALS = [arg for _ in range(3) for goal in (("8.3", "3.8", "90"), ("1.5", "1.2", "0")) for arg in ("--goal", *goal)]


def started_navigate(out, log):
    """navigate as a script's background job (`… &`) starts it: with SIGINT ignored, which a process
    inherits; it must stop at an explicit SIGINT all the same (it ran its mission to the end, exit 0,
    in a suite started in the background)."""
    return subprocess.Popen([sys.executable, "-m", "omninav.cli.main", "navigate", "--world", "room", *GOALS,
                             "--localization", "truth", "--lockstep", "--rate", "0.5", "--timeout", "600",
                             "--composed", "-o", str(out)],
                            cwd=REPO, stdout=log, stderr=subprocess.STDOUT, start_new_session=True,
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_IGN))


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGHUP, signal.SIGINT, signal.SIGKILL],
                         ids=lambda s: signal.Signals(s).name)
def test_navigate_ended_by_a_signal_leaves_nothing_running_and_its_recording_closed(sig, tmp_path):
    out, said = tmp_path / "run", tmp_path / "navigate.log"
    with open(said, "wb") as log:
        navigate = started_navigate(out, log)
    router = None
    try:
        router = wait_for(lambda: router_of(out / "services.log"), navigate, "the router")
        recording = out / "run.mcap"
        wait_for(lambda: "services up" in said.read_text(errors="replace") and recording.exists()
                 and recording.stat().st_size > 10_000, navigate, "a running stack, recording")
        os.kill(navigate.pid, sig)              # navigate alone, as `timeout` or a closing terminal would
        navigate.wait(300)
        wait_until(lambda: processes_using(router) == [], timeout=120,
                   what=f"every process of the stack gone after {signal.Signals(sig).name} to navigate")
    finally:
        if navigate.poll() is None:
            os.killpg(navigate.pid, signal.SIGKILL)
        for pid in processes_using(router) if router else ():
            os.kill(pid, signal.SIGKILL)
    with open(out / "run.mcap", "rb") as recording:      # closed: its summary written
        summary = make_reader(recording).get_summary()
    assert summary is not None and summary.statistics.message_count > 0
    if sig != signal.SIGKILL:       # navigate stopped what it started, as on Ctrl-C (not killed by the signal)
        assert navigate.returncode == 130
