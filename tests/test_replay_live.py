"""`omninav replay FILE …` (live): recorded payloads back onto the bus, in order, filtered, sped up, with a clock."""
import signal

import pytest

from omninav.schemas import decode
from omninav.schemas.attachment import unpack_attachment
from omninav.schemas.codec import encode
from omninav.schemas.keys import KeyLayout
from omninav.schemas.messages import Chatter, Clock, Header
from omninav.services.recorder.mcap_io import RecordingWriter, read_records
from omninav.services.runtime.zenoh_config import open_client

from conftest import wait_alive, wait_until
from launching import TALKER_LISTENER

KEYS = KeyLayout()
CHATTER, ECHO, CLOCK = KEYS.robot("chatter"), KEYS.robot("echo"), KEYS.sim("clock")
MS = 1_000_000
T0 = 1_700_000_000_000 * MS         # log times are wall times


def make_recording(path, n=60, with_clock=False, spacing_ms=20):
    """n messages alternating chatter / echo, spacing_ms apart in log time, stamps 10 ms apart."""
    with RecordingWriter(path) as writer:
        for i in range(n):
            stamp = (i + 1) * 10 * MS
            if with_clock:
                writer.write(CLOCK, "Clock", encode(Clock(header=Header(stamp_ns=stamp, seq=i + 1))), i + 1, stamp,
                             T0 + i * spacing_ms * MS)
            key = (CHATTER, ECHO)[i % 2]
            msg = Chatter(header=Header(stamp_ns=stamp, seq=i // 2 + 1), text=f"{key} {i}", value=float(i))
            writer.write(key, "Chatter", encode(msg), msg.header.seq, stamp, T0 + i * spacing_ms * MS + 1)
    return path


class Collector:
    """Everything published under omninav/** while it is open: (key, payload, envelope)."""

    def __init__(self, endpoint):
        self.got = []
        self._session = open_client(endpoint)
        self._sub = self._session.declare_subscriber("omninav/**", lambda s: self.got.append((
            str(s.key_expr), s.payload.to_bytes(),
            unpack_attachment(s.attachment.to_bytes() if s.attachment is not None else None))))

    def close(self):
        self._sub.undeclare()
        self._session.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


def replay(processes, *args):
    proc = processes.omninav("replay", *map(str, args))
    assert proc.wait(60) == 0, processes.log_of(proc)
    return processes.log_of(proc)


def recorded(path, keys=None):
    return [(r.key, r.payload, (r.seq, r.stamp_ns, r.type_name)) for r in read_records(path)
            if keys is None or r.key in keys]


def test_replay_republishes_every_payload_in_order_with_its_attachment(processes, router_endpoint, tmp_path):
    path = make_recording(tmp_path / "rec.mcap")
    with Collector(router_endpoint) as bus:
        log = replay(processes, path, "--rate", "4")
        wait_until(lambda: len(bus.got) >= 60, 20, what="the replayed messages")
    assert [(k, p, tuple(e)) for k, p, e in bus.got] == recorded(path)
    assert "replayed 60 messages on 2 keys" in log


def test_keys_filter_by_key_expression_and_rate_speeds_up(processes, router_endpoint, tmp_path):
    path = make_recording(tmp_path / "rec.mcap", n=200, spacing_ms=50)     # 10 s of recording
    with Collector(router_endpoint) as bus:
        replay(processes, path, "--keys", "omninav/*/chatter", "--rate", "100")
        wait_until(lambda: len(bus.got) >= 100, 20, what="the replayed chatter")
    assert [(k, p, tuple(e)) for k, p, e in bus.got] == recorded(path, {CHATTER})


def test_start_offset_skips_the_beginning(processes, router_endpoint, tmp_path):
    path = make_recording(tmp_path / "rec.mcap", n=40, spacing_ms=100)     # log times 0 .. 3.9 s
    with Collector(router_endpoint) as bus:
        replay(processes, path, "--start-offset", "2.05", "--rate", "10")
        wait_until(lambda: len(bus.got) >= 19, 20, what="the second half")
    assert [(k, p, tuple(e)) for k, p, e in bus.got] == recorded(path)[21:]   # from 2.1 s on


def test_clock_from_stamps_goes_out_before_the_messages_it_times(processes, router_endpoint, tmp_path):
    path = make_recording(tmp_path / "rec.mcap", n=30)
    with Collector(router_endpoint) as bus:
        replay(processes, path, "--clock", "--rate", "5")
        wait_until(lambda: sum(k != CLOCK for k, _, _ in bus.got) >= 30, 20, what="the replay")
    clock_now = -1
    clocks = 0
    for key, payload, envelope in bus.got:
        if key == CLOCK:
            msg = decode(payload, Clock)
            assert msg.header.stamp_ns > clock_now and envelope.stamp_ns == msg.header.stamp_ns
            assert envelope.type_name == "Clock" and msg.header.seq == clocks + 1
            clock_now, clocks = msg.header.stamp_ns, clocks + 1
        else:
            assert envelope.stamp_ns <= clock_now            # never ahead of the clock
    assert clocks == 30                                      # one per stamp: they are 10 ms apart


def test_clock_option_adds_nothing_when_the_recording_has_a_clock(processes, router_endpoint, tmp_path):
    path = make_recording(tmp_path / "rec.mcap", n=20, with_clock=True)
    with Collector(router_endpoint) as bus:
        replay(processes, path, "--clock", "--rate", "5")
        wait_until(lambda: len(bus.got) >= 40, 20, what="the replay")
    assert [(k, p, tuple(e)) for k, p, e in bus.got] == recorded(path)


def test_loop_repeats_until_sigint(processes, router_endpoint, tmp_path):
    path = make_recording(tmp_path / "rec.mcap", n=10, spacing_ms=10)
    with Collector(router_endpoint) as bus:
        proc = processes.omninav("replay", str(path), "--loop", "--rate", "2")
        wait_until(lambda: len(bus.got) >= 25, 30, what="more than two passes")
        assert processes.stop(proc, signal.SIGINT) == 0
    once = recorded(path)
    got = [(k, p, tuple(e)) for k, p, e in bus.got]
    assert got[:20] == once + once
    assert "stopped" in processes.log_of(proc)


@pytest.mark.parametrize("content, error", [
    (None, "no such recording"),
    (b"definitely not mcap" * 20, "not an MCAP file"),
    ("cut", "not a finished recording"),
])
def test_missing_or_damaged_file_is_a_clear_error(processes, tmp_path, content, error):
    path = tmp_path / "bad.mcap"
    if content == "cut":
        whole = make_recording(tmp_path / "whole.mcap").read_bytes()
        path.write_bytes(whole[: len(whole) // 2])
    elif content is not None:
        path.write_bytes(content)
    proc = processes.omninav("replay", str(path))
    assert proc.wait(60) == 2
    log = processes.log_of(proc)
    assert error in log and "Traceback" not in log


def test_under_acl_replay_puts_each_key_as_its_publisher_and_nothing_without_identities(up, endpoint, tmp_path):
    path = make_recording(tmp_path / "rec.mcap", n=20)
    launcher = up(TALKER_LISTENER)
    wait_alive(endpoint, ["talker", "listener"])
    played = {(k, p) for k, p, _ in recorded(path)}
    with Collector(endpoint) as bus:        # the tool identity: it may listen to everything
        as_tool = up.procs.omninav("replay", str(path), "--router", endpoint)
        assert as_tool.wait(60) == 0        # its puts are refused by the router, silently
        as_services = up.procs.omninav("replay", str(path), "--router", endpoint, "--credentials", str(up.credentials))
        assert as_services.wait(60) == 0, up.procs.log_of(as_services)
        wait_until(lambda: played <= {(k, p) for k, p, _ in bus.got}, 10, what="the replayed chatter and echo")
        arrived = [(k, p) for k, p, _ in bus.got if (k, p) in played]
    assert len(arrived) == len(played)      # once each: from the services' identities, none as the tool
    assert up.procs.stop(launcher) == 0
