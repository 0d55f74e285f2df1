"""`omninav up`: services as separate processes, prefixed output, restarts, ordered stop, start failures."""
import os
import signal
import textwrap
import time

import pytest
from mcap.reader import make_reader

from omninav.services.runtime.zenoh_config import open_client

from conftest import free_port, wait_until
from launching import (TALKER_LISTENER, alive, children, count_echoes, echo_subscriber, processes_using,
                       service_pids)

# ------------------------------------------------------------------ tests

def test_up_runs_services_as_processes_restarts_a_killed_one_and_stops_in_reverse(up, endpoint):
    launcher = up(TALKER_LISTENER)
    pids = wait_until(lambda: (p := service_pids(launcher.pid)).keys() == {"talker", "listener"} and p,
                      30, what="talker and listener started by up")
    assert len({launcher.pid, *pids.values()}) == 3
    # forked from up's fork server, shared by the two: its children, not up's
    assert not set(pids.values()) & set(children(launcher.pid))

    echoes = []
    with open_client(endpoint) as session:
        sub = echo_subscriber(session, echoes)
        wait_until(lambda: count_echoes(echoes) >= 3, 30, what="echoes through the listener")

        os.kill(pids["listener"], signal.SIGKILL)
        restarted = wait_until(lambda: service_pids(launcher.pid).get("listener") not in (None, pids["listener"])
                               and service_pids(launcher.pid)["listener"], 30, what="the listener restarted")
        assert not alive(pids["listener"])
        before = count_echoes(echoes)  # the killed one publishes nothing more: new echoes are the new one's
        wait_until(lambda: count_echoes(echoes) >= before + 3, 30, what="echoes after the restart")
        sub.undeclare()

    assert up.procs.stop(launcher, signal.SIGINT) == 0
    for pid in (*pids.values(), restarted):
        assert not alive(pid)
    assert processes_using(endpoint) == []

    log = up.procs.log_of(launcher)
    lines = log.splitlines()
    starts = [line for line in lines if "started (robot r1)" in line]
    assert sorted(s.split()[0] for s in starts) == ["[listener]", "[listener]", "[talker]"]
    assert any(line.startswith("[up] listener ended with signal SIGKILL") and "restarting in 0.5s" in line
               for line in lines)
    stopped = [line for line in lines if line.endswith("] stopped") or " stopped (" in line]
    assert stopped == ["[listener] INFO [listener] stopped", "[up] listener stopped (exit code 0)",
                       "[talker] INFO [talker] stopped", "[up] talker stopped (exit code 0)",
                       "[up] stopped"], log   # reverse order, each cleanly, then the router


def test_a_bad_parameter_fails_with_exit_2_and_starts_nothing(up, endpoint):
    launcher = up(TALKER_LISTENER.replace("service: listener", "service: listener\n        params: {gian: 2}"))
    assert launcher.wait(60) == 2
    log = up.procs.log_of(launcher)
    assert "services[1] (listener).params: ListenerParams: unknown parameter 'gian' (did you mean 'gain'?)" in log
    assert "router listening" not in log and "started" not in log


def test_a_service_whose_setup_raises_makes_up_fail_with_its_error_before_the_router_opens(up, endpoint, tmp_path):
    (tmp_path / "omninav_test_crasher.py").write_text(textwrap.dedent("""\
        from omninav.services.runtime.node import Node

        class Crasher(Node):
            service = "crasher"

            def setup(self):
                raise RuntimeError("no wheels attached")
        """))
    launcher = up(TALKER_LISTENER.replace("service: listener", "module: omninav_test_crasher:Crasher")
                  .replace("name: listener", "name: crasher"), env={"PYTHONPATH": str(tmp_path)})
    assert launcher.wait(60) == 2   # up builds every node to make the ACL from its declarations
    log = up.procs.log_of(launcher)
    assert "crasher cannot be built to read what it declares: RuntimeError: no wheels attached" in log
    # the services that set no pace start while up builds the nodes (start-up time); they are stopped
    assert "router listening" not in log and "[up] crasher stopped" in log
    assert processes_using(endpoint) == []


def test_restart_always_with_max_restarts_then_up_ends_when_every_service_has(up, endpoint, tmp_path):
    (tmp_path / "omninav_test_oneshot.py").write_text(textwrap.dedent("""\
        from omninav.services.runtime.node import Node

        class OneShot(Node):
            service = "oneshot"

            def run_live(self, router, stop_event):
                print("one shot done", flush=True)
        """))
    launcher = up("""\
        services:
          - name: once
            module: omninav_test_oneshot:OneShot
            restart: always
            max_restarts: 2
        """, env={"PYTHONPATH": str(tmp_path)})
    assert launcher.wait(60) == 0
    lines = up.procs.log_of(launcher).splitlines()
    assert lines.count("[once] one shot done") == 3
    ended = [line for line in lines if line.startswith("[up] once ended with exit code 0")]
    assert [line.rpartition(";")[2] for line in ended] == [
        " restarting in 0.5s (restart 1)", " restarting in 1.0s (restart 2)", " giving up after 2 restart(s)"]
    assert "[up] every service has ended" in lines


def test_a_service_waiting_for_its_router_stops_when_asked(processes_no_router, tmp_path):
    """Started before any router (start order does not matter), it waits; SIGINT still ends it
    cleanly — a recorder with a whole, empty recording."""
    absent = f"tcp/127.0.0.1:{free_port()}"
    talker = processes_no_router.omninav("run", "talker", "--router", absent)
    recorder = processes_no_router.omninav("run", "recorder", "--router", absent,
                                           "--set", f"output={tmp_path / 'early.mcap'}")
    for proc in (talker, recorder):
        wait_until(lambda: "started" in processes_no_router.log_of(proc), 60, what="the service's start")
    time.sleep(1.5)    # into the wait for the router
    assert processes_no_router.stop(talker) == 0
    assert processes_no_router.stop(recorder) == 0
    assert "recorded 0 messages" in processes_no_router.log_of(recorder)
    with open(tmp_path / "early.mcap", "rb") as recording:
        assert make_reader(recording).get_summary() is not None


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGHUP], ids=lambda s: signal.Signals(s).name)
def test_up_stops_every_service_at_sigterm_and_sighup(up, endpoint, sig):
    """A CI job's cancel or a closed terminal stops the stack as Ctrl-C does: each service cleanly."""
    launcher = up(TALKER_LISTENER)
    pids = wait_until(lambda: (p := service_pids(launcher.pid)).keys() == {"talker", "listener"} and p,
                      30, what="talker and listener started by up")
    assert up.procs.stop(launcher, sig) == 0
    assert not any(alive(pid) for pid in pids.values()) and processes_using(endpoint) == []
    assert up.procs.log_of(launcher).splitlines()[-1] == "[up] stopped"
