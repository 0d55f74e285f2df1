"""A service as its own OS process on the bus: data flows, `get` answers, SIGINT stops it cleanly."""
from omninav.schemas import decode
from omninav.schemas.messages import Chatter
from omninav.services.runtime.zenoh_config import open_client

from conftest import wait_until


def test_talker_and_listener_processes_echo_and_answer_get(processes, router_endpoint):
    talker = processes.omninav("run", "talker", "--set", "rate=4")
    listener = processes.omninav("run", "listener")
    echoes = []
    with open_client(router_endpoint) as session:
        sub = session.declare_subscriber("omninav/r1/echo", lambda s: echoes.append(decode(s.payload.to_bytes())))
        wait_until(lambda: sum(m.text.startswith("echo:") for m in echoes) >= 5, 20, what="echoes")

        def got_reply():
            replies = list(session.get("omninav/r1/echo", timeout=2.0))
            return replies and replies[0].ok and decode(replies[0].ok.payload.to_bytes(), Chatter)

        reply = wait_until(got_reply, 10, what="a get reply")
        assert reply.text.startswith("echo: hello")
        sub.undeclare()
    sums = [m.value for m in echoes if m.text.startswith("echo:")]
    assert len(set(sums)) > 1                       # a running sum, not a constant
    assert processes.stop(listener) == 0 and processes.stop(talker) == 0
    assert "stopped" in processes.log_of(listener)


def test_unknown_service_and_bad_parameter_fail_clearly(processes):
    bad = processes.omninav("run", "nosuch")
    assert bad.wait(30) == 2 and "unknown service 'nosuch'" in processes.log_of(bad)
    bad = processes.omninav("run", "listener", "--set", "gian=2")
    assert bad.wait(30) == 2 and "unknown parameter 'gian' (did you mean 'gain'?)" in processes.log_of(bad)
