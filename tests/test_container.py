"""Composition: several services in one OS process (`process:` in a compose file), messages between
them handed over in-process and still on the bus, the same recording and replay as separate
processes, one identity per container that may do only what its services may."""
import os
import shutil
import signal
import subprocess
import sys
import textwrap
import threading

import pytest
import zenoh

from omninav.schemas import encode
from omninav.schemas.keys import ALL, KeyLayout
from omninav.schemas.messages import Chatter, Header
from omninav.services.recorder.mcap_io import read_records
from omninav.services.runtime.acl import TOOL, access_control, write_credentials
from omninav.services.runtime.compose import ComposeError, load_compose
from omninav.services.runtime.container import Container
from omninav.services.runtime.launcher import identities
from omninav.services.runtime.node import Node
from omninav.services.runtime.zenoh_config import free_loopback_endpoint, open_client, open_router

from conftest import REPO, wait_alive, wait_until
from launching import count_echoes, echo_subscriber, launched

KEYS = KeyLayout("r1")
CHATTER, ECHO, CLOCK = KEYS.robot("chatter"), KEYS.robot("echo"), KEYS.resolve("sim/clock")


def recorded_demo(recording, together: tuple[str, ...]) -> str:
    """recorder, talker and listener; those named in `together` in one process `demo`."""
    process = {name: "\n        process: demo" if name in together else "" for name in ("recorder", "talker", "listener")}
    return f"""\
    services:
      - name: recorder
        service: recorder
        params: {{output: {recording}}}{process["recorder"]}
      - name: talker
        service: talker
        params: {{rate: 4}}{process["talker"]}
      - name: listener
        service: listener{process["listener"]}
    """


def run_demo(up, endpoint, compose_text: str, echoes_wanted: int = 20) -> list[int]:
    """Run it until this test's client (a third process) saw enough echoes; returns the processes up started."""
    launcher = up(compose_text)
    wait_alive(endpoint, ["recorder", "talker", "listener"])
    kids = launched(launcher.pid)
    echoes = []
    with open_client(endpoint) as session:
        sub = echo_subscriber(session, echoes)
        wait_until(lambda: count_echoes(echoes) >= echoes_wanted, 60, what="echoes on the bus")
        sub.undeclare()
    assert up.procs.stop(launcher) == 0, up.procs.log_of(launcher)
    shutil.rmtree(up.credentials)      # the next run's `up` writes new ones; wait for those
    return kids


def _payloads(path, keys) -> dict[tuple[str, int], bytes]:
    return {(r.key, r.seq): r.payload for r in read_records(path, keys)}


def test_a_composed_pair_talks_in_process_the_bus_sees_it_and_it_replays_as_a_separate_run(up, endpoint, tmp_path):
    composed = tmp_path / "composed.mcap"
    # the container's publishers send only to other processes: the listener hears the talker in-process
    kids = run_demo(up, endpoint, recorded_demo(composed, together=("talker", "listener")))
    assert len(kids) == 2       # the recorder's process and the container

    separate = tmp_path / "separate.mcap"
    assert len(run_demo(up, endpoint, recorded_demo(separate, together=()))) == 3

    keys = [CHATTER, ECHO, CLOCK]
    a, b = _payloads(composed, keys), _payloads(separate, keys)
    common = a.keys() & b.keys()
    assert {k for k, _ in common} == set(keys)
    assert sum(k == ECHO for k, _ in common) >= 20
    assert all(a[k] == b[k] for k in common)    # the same messages, whichever way it ran

    for recording in (composed, separate):
        done = subprocess.run([sys.executable, "-m", "omninav.cli.main", "replay", str(recording), "--into",
                               "listener", "--compare"], cwd=REPO, capture_output=True, text=True, timeout=120)
        assert done.returncode == 0, done.stdout + done.stderr
        assert "equal: 0" not in done.stdout


def test_a_recorder_composed_with_a_talker_takes_its_messages_in_process_and_the_others_from_the_bus(
        up, endpoint, tmp_path):
    recording = tmp_path / "run.mcap"
    assert len(run_demo(up, endpoint, recorded_demo(recording, together=("recorder", "talker")))) == 2
    seqs: dict[str, list[int]] = {}
    for record in read_records(recording, [CHATTER, ECHO]):
        seqs.setdefault(record.key, []).append(record.seq)
    # the talker's handed over in the container, the listener's (another process) through the
    # router: each message once, none missing
    assert len(seqs[CHATTER]) >= 20 and len(seqs[ECHO]) >= 20
    for key, taken in seqs.items():
        assert taken == list(range(taken[0], taken[0] + len(taken))), key


def _write(tmp_path, text: str):
    path = tmp_path / "compose.yaml"
    path.write_text(textwrap.dedent(text))
    return path


TALKER_LISTENER_IN_ONE = """\
    services:
      - name: talker
        service: talker
        process: demo
      - name: listener
        service: listener
        process: demo
    """


def test_a_container_has_one_identity_with_its_services_rights_and_no_more(tmp_path, monkeypatch):
    monkeypatch.delenv("OMNINAV_CREDENTIALS", raising=False)
    compose = load_compose(_write(tmp_path, TALKER_LISTENER_IN_ONE))
    assert [(p.name, [s.name for s in p.services]) for p in compose.processes] == [("demo", ["talker", "listener"])]
    grants = identities(compose)
    assert "talker" not in grants and "listener" not in grants
    assert set(grants["demo"].put) == {CLOCK, CHATTER, ECHO, *(f(name) for name in ("talker", "listener")
                                                              for f in (KEYS.diagnostics, KEYS.lockstep))}
    assert set(grants["demo"].token) == {KEYS.alive("talker"), KEYS.alive("listener")}

    folder = tmp_path / "ids"
    dictionary = write_credentials(folder, grants)
    endpoint = free_loopback_endpoint()
    seen = []
    with open_router(endpoint, dictionary, access_control(grants)), \
            open_client(endpoint, str(folder / TOOL)) as tool, open_client(endpoint, str(folder / "demo")) as demo:
        tool.declare_subscriber(ALL, lambda s: seen.append(str(s.key_expr)))
        goal = KEYS.robot("goal")
        wait_until(lambda: demo.put(ECHO, b"x") or ECHO in seen, 20, interval=0.2, what="the container's echo")
        for _ in range(10):
            demo.put(goal, b"x")       # none of its services sends goals
            demo.put(ECHO, b"x")
        wait_until(lambda: seen.count(ECHO) >= 11, 20, what="the container's later echoes")
    assert goal not in seen


@pytest.mark.parametrize("text, error", [
    (TALKER_LISTENER_IN_ONE.replace("process: demo\n      - name: listener", "process: demo\n        restart: always\n"
                                    "      - name: listener"),
     "listener (restart on-failure, max_restarts None) runs in process 'demo' with talker (restart always"),
    (TALKER_LISTENER_IN_ONE.replace("process: demo\n      - name: listener", "process: listener\n"
                                    "      - name: listener"),
     "process 'listener' has the name of service 'listener', which runs in process 'demo'"),
    (TALKER_LISTENER_IN_ONE.replace("process: demo\n", "process: 'a b'\n", 1), "services[0] (talker).process:"),
])
def test_bad_processes_are_one_line_compose_errors(tmp_path, text, error):
    with pytest.raises(ComposeError, match=None) as caught:
        load_compose(_write(tmp_path, text))
    assert error in str(caught.value)
    assert "\n" not in str(caught.value)


def test_zenoh_keeps_a_remote_only_put_from_its_own_sessions_subscribers():
    """What the container relies on: a publisher with destination REMOTE reaches other sessions only."""
    endpoint = free_loopback_endpoint()
    mine, theirs = [], []
    with open_router(endpoint), open_client(endpoint) as own, open_client(endpoint) as other:
        own.declare_subscriber(CHATTER, lambda s: mine.append(1))
        other.declare_subscriber(CHATTER, lambda s: theirs.append(1))
        pub = own.declare_publisher(CHATTER, allowed_destination=zenoh.Locality.REMOTE)
        wait_until(lambda: pub.put(b"x") or theirs, 20, interval=0.2, what="the other session")
    assert not mine


def test_a_killed_container_is_restarted_as_a_whole_by_its_services_policy(up, endpoint):
    launcher = up(TALKER_LISTENER_IN_ONE.replace("process: demo\n", "process: demo\n        max_restarts: 1\n"))
    wait_alive(endpoint, ["talker", "listener"])
    [first] = launched(launcher.pid)
    echoes = []
    with open_client(endpoint) as session:
        sub = echo_subscriber(session, echoes)
        wait_until(lambda: count_echoes(echoes) >= 3, 60, what="echoes from the container")
        os.kill(first, signal.SIGKILL)
        wait_until(lambda: launched(launcher.pid) not in ([], [first]), 60, what="the container restarted")
        before = count_echoes(echoes)
        wait_until(lambda: count_echoes(echoes) >= before + 3, 60, what="echoes after the restart")
        sub.undeclare()
    assert up.procs.stop(launcher) == 0
    log = up.procs.log_of(launcher)
    assert "[up] demo ended with signal SIGKILL" in log and "restarting in 0.5s (restart 1)" in log


class _Taker(Node):
    """Keeps every chatter message it is handed."""
    service = "taker"

    def setup(self) -> None:
        self.taken = []
        self.threads: set[int] = set()
        self.subscribe("chatter", self.take, synced=False)

    def take(self, msg: Chatter) -> None:
        self.taken.append(msg)
        self.threads.add(threading.get_ident())


def test_a_container_takes_each_payload_once_from_the_bus_for_all_its_nodes_and_decodes_it_once():
    endpoint = free_loopback_endpoint()
    nodes = [_Taker(name="first"), _Taker(name="second")]
    container = Container(nodes, endpoint)
    with open_router(endpoint), open_client(endpoint) as other:
        thread = threading.Thread(target=container.run)
        thread.start()
        try:
            wait_alive(endpoint, ["first", "second"], timeout=60)
            pub = other.declare_publisher(CHATTER, congestion_control=zenoh.CongestionControl.BLOCK)
            pub.put(b"not msgpack")
            for k in range(5):
                pub.put(encode(Chatter(header=Header(stamp_ns=k + 1, seq=k + 1), text=f"m{k}", value=k)))
            wait_until(lambda: all(len(n.taken) == 5 for n in nodes), 30, what="both nodes to take five messages")
        finally:
            container.stop()
            thread.join(60)
    assert [m.text for m in nodes[0].taken] == [f"m{k}" for k in range(5)]
    assert all(a is b for a, b in zip(nodes[0].taken, nodes[1].taken))     # one message, not one per node
    assert len(nodes[0].threads | nodes[1].threads) == 1        # one thread drives both
    assert all(n.counters[f"malformed/{CHATTER}"] == 1 for n in nodes)
