"""The in-process runner drives real nodes in lockstep: same outputs as processing in stamp order."""
from omninav.schemas import decode
from omninav.services.demo.listener import Listener
from omninav.services.demo.talker import Talker, TalkerParams
from omninav.services.runtime.inprocess import InProcessRunner
from omninav.services.runtime.node import NS_PER_S


def run_demo(steps):
    talker, listener = Talker(TalkerParams(clock_hz=100, chatter_hz=10)), Listener()
    runner = InProcessRunner([talker, listener])
    seen = []
    runner.tap(lambda key, payload, stamp: seen.append((key, payload)))
    runner.run_until(lambda: False, steps)
    runner.close()
    return listener, seen


def test_lockstep_pipeline_is_deterministic_and_complete():
    listener, seen = run_demo(250)
    echoes = [decode(p) for k, p in seen if k == "omninav/r1/echo"]
    texts = [m.text for m in echoes]
    # the 25th chatter, of the last step, waits for a clock past it that never comes: dropped at the close
    assert [t for t in texts if t.startswith("echo:")] == [f"echo: hello {n}" for n in range(1, 25)]
    assert listener.counters["dropped_at_stop"] == 1
    assert sum(t.startswith("summary:") for t in texts) == 3          # at 0.01 s, 1.01 s and 2.01 s
    assert echoes[-1].header.stamp_ns <= 250 * NS_PER_S // 100
    assert listener.counters.get("sync_timeouts", 0) == 0 and not any(k.startswith("late/") for k in listener.counters)
    assert run_demo(250)[1] == seen                                     # byte for byte, every run


def test_needs_a_source():
    import pytest
    with pytest.raises(ValueError, match="source"):
        InProcessRunner([Listener()])


def test_watch_hands_over_the_messages_the_subscribers_get():
    talker, listener = Talker(TalkerParams(clock_hz=100, chatter_hz=10)), Listener()
    runner = InProcessRunner([talker, listener])
    payloads, watched, handled = [], [], []
    chatter = next(i for i in listener.inputs if i.key.endswith("/chatter"))
    chatter.handler = (lambda handle: lambda msg: (handled.append(msg), handle(msg)))(chatter.handler)
    runner.tap(lambda key, payload, stamp: payloads.append(payload) if key == chatter.key else None)
    runner.watch([chatter.key], lambda key, msg: watched.append((key, msg)))
    runner.run_until(lambda: False, 100)
    runner.close()
    assert len(watched) == len(payloads) == 10
    assert [m.text for _, m in watched] == [decode(p).text for p in payloads]
    assert all(a is b for (_, a), b in zip(watched, handled))      # decoded once, shared
