"""A service as its own OS process on the bus: data flows, `get` answers, SIGINT stops it cleanly."""
import time

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


def test_a_source_started_by_up_waits_for_the_listeners_tokens_before_it_declares_or_says_anything(
        router_endpoint, monkeypatch):
    """`up` starts every process at once; a source holds back until the services it lists are ready."""
    import threading

    from omninav.schemas.keys import KeyLayout
    from omninav.services.demo.talker import Talker, TalkerParams
    from omninav.services.runtime.live import LISTENERS_ENV, LiveRunner

    keys = KeyLayout("r1")
    monkeypatch.setenv(LISTENERS_ENV, f"{keys.alive('listener')},{keys.alive('recorder')}")
    runner = LiveRunner(Talker(TalkerParams(), robot="r1"), router_endpoint)
    heard = []
    with open_client(router_endpoint) as session:
        session.declare_subscriber(keys.robot("chatter"), lambda s: heard.append(s))
        thread = threading.Thread(target=runner.run, daemon=True)
        thread.start()
        try:
            listener = session.liveliness().declare_token(keys.alive("listener"))
            time.sleep(1.0)     # one of the two: the talker still waits, its token undeclared
            assert not heard and not list(session.liveliness().get(keys.alive("talker"), timeout=1.0))
            recorder = session.liveliness().declare_token(keys.alive("recorder"))
            wait_until(lambda: heard, 10, what="the talker's chatter once both listeners are ready")
            assert list(session.liveliness().get(keys.alive("talker"), timeout=1.0))
            listener.undeclare()
            recorder.undeclare()
        finally:
            runner.stop()
            thread.join(10)


def test_a_lockstep_service_drops_at_its_stop_what_it_held_for_a_step_that_never_came(router_endpoint):
    """A chatter waits in the listener's merger for its clock to pass it. Stopped live, the listener
    handles it; stopped in lockstep, where the run has ended at its last step, it does not: what it
    would publish then races the recorder's own stop (one `costmap/local` more in one of two runs)."""
    import threading

    from omninav.schemas import encode
    from omninav.schemas.messages import Header
    from omninav.services.demo.listener import Listener, ListenerParams
    from omninav.services.runtime.live import LiveRunner
    from omninav.services.runtime.lockstep import Lockstep

    handled = {}
    for how, lockstep in (("live", None), ("lockstep", Lockstep())):
        listener = Listener(ListenerParams(), robot="r1")
        runner = LiveRunner(listener, router_endpoint, sync_timeout_s=600.0, lockstep=lockstep)
        thread = threading.Thread(target=runner.run, daemon=True)
        thread.start()
        try:
            with open_client(router_endpoint) as session:
                wait_until(lambda: list(session.liveliness().get("omninav/r1/alive/listener", timeout=1.0)), 20,
                           what="the listener's token")
                session.put("omninav/r1/chatter", encode(Chatter(header=Header(stamp_ns=2_000_000_000), text="held")))
                wait_until(lambda: len(runner._merger) == 1, 20, what="the chatter held for the clock")
        finally:
            runner.stop()
            thread.join(20)
        handled[how] = listener.count
    assert handled == {"live": 1, "lockstep": 0}


def test_a_runner_stopping_with_another_event_is_woken_when_it_is_set():
    """The ros2 bridge's inner runner stops with `omninav run`'s event: setting it must also put the
    wake-up item in the runner's inbox (a get(timeout) a signal interrupted blocks until the next
    put). `event.wait() or put(...)` never put it - wait() returns True - and the idle bridge
    waiting for a robot's router hung at SIGINT in about one run of two."""
    import queue
    import threading

    from omninav.services.demo.listener import Listener, ListenerParams
    from omninav.services.runtime.live import LiveRunner

    runner = LiveRunner(Listener(ListenerParams(), robot="r1"), "tcp/127.0.0.1:7447")
    event = threading.Event()
    runner.stops_with(event)
    event.set()
    try:
        assert runner._inbox.get(timeout=10) == ("wake",)
    except queue.Empty:
        raise AssertionError("no wake-up item after the event was set") from None
    assert runner.stop_event.is_set()
