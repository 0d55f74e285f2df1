"""`omninav topics / echo / hz / get` as processes against a talker and a listener; the readable form."""
import json
import re

import numpy as np
import pytest
import zenoh

from omninav.cli.introspect import RateWindow
from omninav.schemas import decode, encode
from omninav.schemas.keys import KeyLayout
from omninav.schemas.messages import Chatter, Clock, Header, LaserScan, Odometry
from omninav.schemas.readable import HEAD, to_plain, to_text
from omninav.services.runtime.zenoh_config import open_client

from conftest import wait_until

KEYS = KeyLayout("r1")
EXIT_TIMEOUT_S = 60


def _wait_for(session, key: str, what: str, count: int = 1) -> None:
    seen = []
    sub = session.declare_subscriber(key, lambda s: seen.append(1))
    wait_until(lambda: len(seen) >= count, 30, what=what)
    sub.undeclare()


def _finished(processes, proc) -> tuple[int, str]:
    return proc.wait(EXIT_TIMEOUT_S), processes.log_of(proc)


def test_commands_against_talker_and_listener(processes, router_endpoint):
    processes.omninav("run", "talker", "--set", "rate=4")
    processes.omninav("run", "listener")
    with open_client(router_endpoint) as session:
        _wait_for(session, KEYS.robot("echo"), "the listener's echoes", count=3)
    echo_key = KEYS.robot("echo")
    # all at once: the commands only listen or query, so they do not disturb each other
    topics_json = processes.omninav("topics", "--duration", "3", "--json")
    topics_text = processes.omninav("topics", "--duration", "3")
    echo = processes.omninav("echo", echo_key, "--count", "3")
    echo_wild = processes.omninav("echo", "omninav/*/chatter", "--count", "2", "--json")
    hz = processes.omninav("hz", KEYS.robot("chatter"), "--duration", "3")
    get = processes.omninav("get", echo_key)
    get_params = processes.omninav("get", f"{echo_key};a=1;b=2", "--json")
    get_nobody = processes.omninav("get", KEYS.robot("plan"), "--timeout", "2")

    code, out = _finished(processes, topics_json)
    assert code == 0, out
    rows = {r["key"]: r for r in json.loads(out.strip().splitlines()[-1])["topics"]}
    assert rows[KEYS.robot("chatter")]["type"] == "Chatter"
    assert rows[KEYS.sim("clock")]["type"] == "Clock"
    assert rows[echo_key]["type"] == "Chatter"
    assert rows[KEYS.diagnostics("talker")]["type"] == "Diagnostic"
    assert rows[KEYS.robot("chatter")]["count"] > 1 and rows[KEYS.robot("chatter")]["rate_hz"] > 0

    code, out = _finished(processes, topics_text)
    assert code == 0, out
    assert re.search(r"^omninav/sim/clock\s+Clock\s+\d+\s+[\d.]+$", out, re.M), out

    code, out = _finished(processes, echo)
    assert code == 0, out
    assert out.count(f"--- {echo_key} (Chatter)") == 3, out
    assert 'frame_id: "listener"' in out and re.search(r'^text: "(echo: hello \d+|summary: .*)"$', out, re.M)

    code, out = _finished(processes, echo_wild)
    assert code == 0, out
    lines = [json.loads(line) for line in out.splitlines() if line.startswith("{")]
    assert len(lines) == 2 and {line["key"] for line in lines} == {KEYS.robot("chatter")}
    assert all(line["message"]["_type"] == "Chatter" and line["message"]["text"].startswith("hello ")
               for line in lines)

    code, out = _finished(processes, hz)
    assert code == 0, out
    rates = [float(r) for r in re.findall(r"average rate: ([\d.]+)", out)]
    assert rates and rates[-1] > 0, out
    assert re.search(r"min: [\d.]+s max: [\d.]+s std dev: [\d.]+s window: \d+", out)

    code, out = _finished(processes, get)
    assert code == 0, out
    assert f"--- {echo_key} (Chatter)" in out and 'text: "echo: hello' in out

    code, out = _finished(processes, get_params)
    assert code == 0, out
    reply = json.loads(out.strip().splitlines()[-1])
    assert reply["key"] == echo_key and reply["message"]["text"].startswith("echo: hello")

    code, out = _finished(processes, get_nobody)
    assert code == 1
    assert f"no reply on {KEYS.robot('plan')} within 2 s" in out


def test_get_error_reply_goes_to_stderr_with_exit_1(processes, router_endpoint):
    processes.omninav("run", "listener")  # no talker: its queryable has no value yet
    with open_client(router_endpoint) as session:
        _wait_for(session, KEYS.diagnostics("listener"), "the listener's first diagnostic")
    code, out = _finished(processes, processes.omninav("get", KEYS.robot("echo")))
    assert code == 1
    assert "omninav get: error reply: omninav/r1/echo: no value yet" in out


def test_echo_reports_a_malformed_payload_and_goes_on(processes, router_endpoint):
    key = KEYS.robot("chatter")
    echo = processes.omninav("echo", key, "--count", "3")
    good = encode(Chatter(header=Header(stamp_ns=1, seq=1), text="fine", value=1.5))
    bad = [b"\xc1 not msgpack", encode(Clock())]  # garbage, and a valid message of the wrong type
    with open_client(router_endpoint) as session:
        pub = session.declare_publisher(key, congestion_control=zenoh.CongestionControl.BLOCK)
        sent = 0

        def publish_until_echo_exits():  # alternating, so any 3 in a row hold a good and a bad one
            nonlocal sent
            pub.put(bad[sent // 2 % 2] if sent % 2 == 0 else good)
            sent += 1
            return echo.poll() is not None

        wait_until(publish_until_echo_exits, 60, interval=0.2, what="echo to print 3 messages")
        pub.undeclare()
    code, out = echo.returncode, processes.log_of(echo)
    assert code == 0, out
    assert "Traceback" not in out
    errors = [line for line in out.splitlines() if line.startswith("malformed message: ")]
    assert errors and all(line.startswith(f"malformed message: {key}: ") for line in errors), out
    assert any("not a msgpack payload" in e or "got Clock, expected Chatter" in e for e in errors)
    assert f"--- {key} (Chatter)" in out and 'text: "fine"' in out


def test_bad_arguments_fail_at_once(processes):
    for args, message in ((["echo", "omninav/$$x"], "invalid key expression 'omninav/$$x'"),
                          (["get", "omninav/r1/echo", "--router", "tcp/10.1.2.3:7447"], "not a loopback"),
                          (["hz", "omninav/r1/echo", "--window", "0"], "--window must be at least 1")):
        proc = processes.omninav(*args)
        code, out = _finished(processes, proc)
        assert code == 2 and message in out, out


# ---------------------------------------------------------------- pure parts

def test_rate_window_reports_like_rostopic_hz():
    window = RateWindow(window=4)
    assert window.stats() is None
    for t in (0.0, 0.5, 0.6, 0.7, 0.8, 0.9):  # one slow period, then 10 Hz
        window.add(t)
    stats = window.stats()
    assert window.count == 6 and stats.periods == 4  # the slow period left the window
    assert stats.rate_hz == pytest.approx(10.0) and stats.min_s == pytest.approx(0.1)
    assert stats.max_s == pytest.approx(0.1) and stats.std_s == pytest.approx(0.0, abs=1e-9)
    unbounded = RateWindow()
    for t in (0.0, 1.0, 3.0):
        unbounded.add(t)
    assert unbounded.stats().rate_hz == pytest.approx(2 / 3)  # 2 periods over 3 s
    assert unbounded.stats().min_s == 1.0 and unbounded.stats().max_s == 2.0


def test_readable_form_summarises_large_arrays_and_is_strict_json():
    ranges = np.linspace(0.5, 5.0, 360).astype("<f4")
    ranges[1] = np.inf
    scan = decode(encode(LaserScan(header=Header(stamp_ns=7, frame_id="laser", seq=3), range_max=6.0,
                                   angle_increment=0.01, angle_max=3.59, ranges=ranges,
                                   intensities=np.ones(360, "<f4"))))
    plain = to_plain(scan)
    assert plain["_type"] == "LaserScan" and plain["header"] == {"stamp_ns": 7, "frame_id": "laser", "seq": 3}
    summary = plain["ranges"]
    assert summary["dtype"] == "float32" and summary["shape"] == [360] and len(summary["first"]) == HEAD
    assert summary["first"][:2] == [0.5, "inf"]  # float32 printed short, inf spelled for JSON
    json.dumps(plain, allow_nan=False)
    full = to_plain(scan, full=True)["ranges"]
    assert len(full) == 360 and full[2] == float(str(ranges[2]))
    text = to_text(scan)
    assert 'frame_id: "laser"' in text.splitlines()[2] and text.splitlines()[0] == "header:"
    assert "ranges: float32[360] [0.5, inf, " in text and text.count("...") == 2


def test_readable_form_shows_small_arrays_and_nested_structs_whole():
    odom = Odometry(pose_covariance=np.eye(3))
    odom.pose.x = 1.25
    plain = to_plain(odom)
    assert plain["pose_covariance"] == [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]
    assert plain["twist"]["header"]["seq"] == 0
    text = to_text(odom)
    assert "pose:\n  x: 1.25\n  y: 0.0" in text
    assert "pose_covariance: [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]" in text
