"""Issue 2 end to end, as a user does it: `omninav up` a compose of recorder, talker and listener;
look at the bus with topics/echo/hz/get; kill a service and see it restarted; stop cleanly; replay
the recording deterministically into the listener (--compare) and live onto the bus."""
import json
import os
import signal
import subprocess
import sys

from omninav.schemas import decode
from omninav.services.runtime.acl import CREDENTIALS_ENV
from omninav.services.runtime.zenoh_config import ROUTER_ENV, open_client

from conftest import REPO, wait_until
from launching import count_echoes, echo_subscriber, service_pids

DEMO = """\
    services:
      - name: recorder
        service: recorder
        params: {{output: {output}}}
      - name: talker
        service: talker
        params: {{rate: 4}}
      - name: listener
        service: listener
    """


def omninav(endpoint, *args, timeout=120):
    done = subprocess.run([sys.executable, "-m", "omninav.cli.main", *args], cwd=REPO, capture_output=True,
                          text=True, timeout=timeout, env={**os.environ, ROUTER_ENV: endpoint})
    return done.returncode, done.stdout + done.stderr


def test_up_introspect_restart_record_replay(up, endpoint, router_endpoint, tmp_path, monkeypatch):
    recording = tmp_path / "demo.mcap"
    launcher = up(DEMO.format(output=recording))
    pids = wait_until(lambda: len(p := service_pids(launcher.pid)) == 3 and p, 60, what="three services up")

    echoes = []
    with open_client(endpoint) as session:
        sub = echo_subscriber(session, echoes)
        wait_until(lambda: count_echoes(echoes) >= 3, 60, what="echoes")

        code, out = omninav(endpoint, "topics", "--duration", "2", "--json")
        assert code == 0, out
        listed = json.loads(out)
        text = json.dumps(listed)
        for key, type_name in (("omninav/r1/chatter", "Chatter"), ("omninav/r1/echo", "Chatter"),
                               ("omninav/sim/clock", "Clock")):
            assert key in text and type_name in text
        code, out = omninav(endpoint, "echo", "omninav/r1/echo", "--count", "2")
        assert code == 0 and "echo: hello" in out, out
        code, out = omninav(endpoint, "hz", "omninav/sim/clock", "--duration", "3")
        assert code == 0 and "average rate" in out, out
        code, out = omninav(endpoint, "get", "omninav/r1/echo")
        assert code == 0 and "echo: hello" in out, out

        os.kill(pids["listener"], signal.SIGKILL)
        wait_until(lambda: service_pids(launcher.pid).get("listener") not in (None, pids["listener"]), 60,
                   what="the listener restarted")
        before = count_echoes(echoes)
        wait_until(lambda: count_echoes(echoes) >= before + 3, 60, what="echoes from the restarted listener")
        sub.undeclare()

    assert up.procs.stop(launcher, signal.SIGINT) == 0, up.procs.log_of(launcher)
    assert "no sequence gaps" in up.procs.log_of(launcher)

    # the listener ran twice: replay aligns with its last run and compares what that run published
    code, out = omninav(endpoint, "replay", str(recording), "--into", "listener", "--compare")
    assert code == 0, out
    assert "1 earlier run(s) of listener: comparing the last" in out and "byte for byte" in out

    replayed = []   # up and its router are gone: live replay onto another bus, one without identities
    monkeypatch.delenv(CREDENTIALS_ENV)
    with open_client(router_endpoint) as session:
        sub = session.declare_subscriber("omninav/r1/chatter", lambda s: replayed.append(decode(s.payload.to_bytes())))
        code, out = omninav(router_endpoint, "replay", str(recording), "--rate", "20", "--keys", "omninav/r1/chatter")
        assert code == 0, out
        wait_until(lambda: len(replayed) > 5, 30, what="replayed chatter")
        sub.undeclare()
    assert [m.header.seq for m in replayed] == sorted(m.header.seq for m in replayed)
