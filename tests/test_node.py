import pytest

from omninav.schemas import MessageError, decode
from omninav.schemas.messages import Chatter, Clock, Header
from omninav.services.demo.listener import Listener, ListenerParams
from omninav.services.runtime.node import NS_PER_S, Ticks


def capture(node):
    out = []
    for pub in node.outputs.values():
        pub.sink = lambda p, payload, stamp: out.append((p.key, decode(payload)))
    return out


def clock(t_s):
    return Clock(header=Header(stamp_ns=round(t_s * NS_PER_S)))


def chatter(t_s, seq, value):
    return Chatter(header=Header(stamp_ns=round(t_s * NS_PER_S), seq=seq), text=f"m{seq}", value=value)


def test_listener_echoes_with_running_sum_and_timer_on_sim_time():
    node = Listener(ListenerParams(summary_period_s=1.0, gain=2.0))
    out = capture(node)
    index = {inp.key: i for i, inp in enumerate(node.inputs)}
    assert list(index) == ["omninav/sim/clock", "omninav/r1/chatter"]   # the clock goes first
    node.process(index["omninav/sim/clock"], clock(0.0))                # timer fires at the first tick
    node.process(index["omninav/r1/chatter"], chatter(0.5, 7, 1.0))
    node.process(index["omninav/sim/clock"], clock(0.9))                # not due yet
    node.process(index["omninav/r1/chatter"], chatter(0.95, 8, 0.5))
    node.process(index["omninav/sim/clock"], clock(2.5))                # due at 1.0 (2.0 was missed): fires once
    texts = [(k, m.text, m.value, m.header.seq, m.header.stamp_ns) for k, m in out]
    assert texts == [
        ("omninav/r1/echo", "summary: 0 messages", 0.0, 1, 0),
        ("omninav/r1/echo", "echo: m7", 2.0, 2, int(0.5 * NS_PER_S)),
        ("omninav/r1/echo", "echo: m8", 3.0, 3, int(0.95 * NS_PER_S)),
        ("omninav/r1/echo", "summary: 2 messages", 3.0, 4, int(2.5 * NS_PER_S)),
    ]
    assert node.first_seq["omninav/r1/chatter"] == 7
    node.process(index["omninav/sim/clock"], clock(3.0))                # next due was 3.0
    assert out[-1][1].text == "summary: 2 messages" and len(out) == 5


def test_malformed_input_is_counted_and_logged_once(caplog):
    node = Listener()
    node.reject("omninav/r1/chatter", MessageError("bad", field="value", type_name="Chatter"))
    node.reject("omninav/r1/chatter", MessageError("bad again"))
    assert node.counters["malformed/omninav/r1/chatter"] == 2
    assert len([r for r in caplog.records if "malformed" in r.message]) == 1
    diag = node.diagnostic()
    assert diag.level == 1 and diag.values["malformed/omninav/r1/chatter"] == 2


def test_publisher_refuses_the_wrong_type():
    node = Listener()
    with pytest.raises(TypeError, match="carries Chatter"):
        node.echo.publish(Clock())


def test_queryable_answers_the_last_echo():
    node = Listener()
    capture(node)
    assert node.answer("omninav/r1/echo", {}) is None
    node.process(1, chatter(0.1, 1, 4.0))
    assert node.answer("omninav/r1/echo", {}).value == 4.0


def test_ticks_fall_on_the_first_stamp_at_or_after_each_multiple_of_the_period():
    ticks = Ticks(10.0)                                   # every 0.1 s
    stamps = [int(s * NS_PER_S) for s in (0.05, 0.1, 0.15, 0.26, 0.29, 0.3, 0.52)]
    assert [s / NS_PER_S for s in stamps if ticks.due(s)] == [0.1, 0.26, 0.3, 0.52]


def test_a_handler_that_raises_is_counted_and_the_node_carries_on(caplog):
    class Fragile(Listener):
        def on_chatter(self, msg):
            if msg.value < 0:
                raise ZeroDivisionError("a value the handler cannot take")
            super().on_chatter(msg)

    node = Fragile(ListenerParams(summary_period_s=100.0))
    out = capture(node)
    chatter_index = next(i for i, inp in enumerate(node.inputs) if inp.key == "omninav/r1/chatter")
    for seq, value in enumerate([1.0, -1.0, -2.0, 2.0], start=1):
        node.process(chatter_index, chatter(0.1 * seq, seq, value))
    assert [m.text for _, m in out] == ["echo: m1", "echo: m4"]          # the bad ones dropped, the next handled
    assert node.counters["handler_errors/omninav/r1/chatter"] == 2
    assert sum("ZeroDivisionError" in r.getMessage() or r.exc_info is not None for r in caplog.records) == 1
    diag = node.diagnostic()
    assert diag.level == 1 and "handler_errors/omninav/r1/chatter" in diag.message
