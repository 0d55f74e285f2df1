"""Deterministic replay into one service: a live multi-process run replays byte for byte, divergences are named."""
from __future__ import annotations

import argparse
import dataclasses
import json
import random
import re
import subprocess
import sys
import time

import numpy as np
import pytest

from omninav.schemas import decode, encode
from omninav.schemas.attachment import unpack_attachment
from omninav.schemas.keys import ALL, KeyLayout
from omninav.schemas.messages import Chatter, Diagnostic, LaserScan
from omninav.services.demo.listener import Listener, ListenerParams
from omninav.services.demo.talker import Talker
from omninav.services.recorder.mcap_io import Record, RecordingWriter, read_records
from omninav.services.replay import cli
from omninav.services.replay.into import (capture_outputs, compare, find_alignment, main_into,
                                          payload_differences, replay_into)
from omninav.services.runtime.merge import StampMerger
from omninav.services.runtime.node import PARAMS_VALUE
from omninav.services.runtime.service_registry import SERVICES
from omninav.services.runtime.run import build_node
from omninav.services.runtime.zenoh_config import open_client, open_router

from conftest import REPO, Processes, free_port, wait_until

KEYS = KeyLayout("r1")
ECHO, CHATTER, CLOCK = KEYS.robot("echo"), KEYS.robot("chatter"), KEYS.resolve("sim/clock")
LISTENER_DIAG = KEYS.diagnostics("listener")
PROBE = KEYS.diagnostics("probe")


def replay(*argv: str) -> int:
    parser = argparse.ArgumentParser()
    cli.add_arguments(parser)
    return main_into(parser.parse_args([str(a) for a in argv]))


def write(path, records) -> None:
    with RecordingWriter(path) as writer:
        for rec in records:
            writer.write_record(rec)


# ---------------------------------------------------------------- a real multi-process run

def _decoded(received, key, cls):
    return [decode(payload, cls) for k, payload, _, _ in list(received) if k == key]


def _final_listener_diagnostic(received) -> bool:
    """A listener Diagnostic that accounts for every echo of a chatter recorded (its last one)."""
    echoes = sum(m.text.startswith("echo:") for m in _decoded(received, ECHO, Chatter))
    return any(d.values.get(f"received/{CHATTER}") == echoes
               for d in _decoded(received, LISTENER_DIAG, Diagnostic))


@pytest.fixture(scope="module")
def live_recording(tmp_path_factory):
    """talker and listener as OS processes; everything on omninav/** recorded by this process."""
    tmp = tmp_path_factory.mktemp("live")
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    received = []   # (key, payload, attachment, wall receipt time); list.append is thread-safe
    with open_router(endpoint), open_client(endpoint) as session:
        procs = Processes(tmp, endpoint)
        try:
            sub = session.declare_subscriber(ALL, lambda s: received.append(
                (str(s.key_expr), s.payload.to_bytes(), s.attachment.to_bytes() if s.attachment else None,
                 time.time_ns())))
            with open_client(endpoint) as prober:   # the subscription is in place before anything starts
                wait_until(lambda: prober.put(PROBE, b"probe") or any(k == PROBE for k, *_ in received),
                           30, interval=0.2, what="the recording subscriber")
            talker = procs.omninav("run", "talker", "--set", "rate=4")
            listener = procs.omninav("run", "listener")
            wait_until(lambda: len(_decoded(received, ECHO, Chatter)) >= 30, 60, what="30 echoes")
            assert procs.stop(listener) == 0, procs.log_of(listener)
            wait_until(lambda: _final_listener_diagnostic(received), 30, what="the listener's final diagnostic")
            chatter_at_stop = len(_decoded(received, CHATTER, Chatter))
            wait_until(lambda: len(_decoded(received, CHATTER, Chatter)) >= chatter_at_stop + 5, 30,
                       what="chatter after the listener stopped")
            procs.stop(talker)      # how the talker exits is test_live_node's business, not replay's
            sub.undeclare()
        finally:
            procs.stop_all()
    path = tmp / "live.mcap"
    with RecordingWriter(path) as writer:
        for key, payload, attachment, log_time in received:
            envelope = unpack_attachment(attachment)
            if envelope is not None:    # only the probe has none
                writer.write(key, envelope.type_name, payload, envelope.seq, envelope.stamp_ns, log_time)
    return path


def _summary_numbers(text: str) -> dict[str, int]:
    found = re.search(r"outputs compared: (\d+), equal: (\d+); replayed beyond the end of the recording: (\d+)", text)
    assert found, text
    return dict(zip(("compared", "equal", "beyond"), map(int, found.groups())))


def test_replay_of_a_live_run_reproduces_the_listener_byte_for_byte(live_recording):
    done = subprocess.run([sys.executable, "-m", "omninav.cli.main", "replay", str(live_recording),
                           "--into", "listener", "--compare"], cwd=REPO, capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stdout + done.stderr
    numbers = _summary_numbers(done.stdout)
    assert numbers["compared"] > 0 and numbers["equal"] == numbers["compared"]
    assert numbers["beyond"] > 0                 # the talker went on after the listener stopped
    diag = max(_decoded([(r.key, r.payload, None, 0) for r in read_records(live_recording, [LISTENER_DIAG])],
                        LISTENER_DIAG, Diagnostic), key=lambda d: d.header.seq)
    assert diag.level == 0, diag.message            # the live run was exactly replayable


def test_a_different_parameter_diverges_at_the_first_echo_and_names_the_field(live_recording, capsys):
    assert replay(live_recording, "--into", "listener", "--set", "gain=3", "--compare") == 1
    out = capsys.readouterr().out
    divergence = out[out.index("FIRST DIVERGENCE"):]
    assert ECHO in divergence and re.search(r"^\s+value: recorded", divergence, re.M), out
    assert "text:" not in divergence                # only the sum is scaled


def test_a_tampered_output_is_found_at_its_seq(live_recording, tmp_path, capsys):
    records = list(read_records(live_recording))
    echoes = sorted((r for r in records if r.key == ECHO), key=lambda r: r.seq)
    victim = echoes[4]
    msg = decode(victim.payload, Chatter)
    original = msg.value
    msg.value = original + 0.5
    tampered = [Record(r.key, r.type_name, encode(msg), r.seq, r.stamp_ns, r.log_time_ns) if r is victim else r
                for r in records]
    write(tmp_path / "tampered.mcap", tampered)
    assert replay(tmp_path / "tampered.mcap", "--into", "listener", "--compare") == 1
    out = capsys.readouterr().out
    assert f"{ECHO} seq {victim.seq} " in out and "(1 of" in out
    assert re.search(rf"value: recorded {msg.value!r}, replay {original!r}", out), out


def test_out_writes_the_replayed_outputs_that_were_compared(live_recording, tmp_path, capsys):
    out_file = tmp_path / "replayed.mcap"
    assert replay(live_recording, "--into", "listener", "--out", out_file, "--compare") == 0
    written = {(r.key, r.seq): r for r in read_records(out_file)}
    recorded = [r for r in read_records(live_recording) if r.key == ECHO]
    assert recorded and all(written[(r.key, r.seq)].payload == r.payload for r in recorded)
    assert all(r.log_time_ns == r.stamp_ns and r.type_name == "Chatter" for r in written.values())
    numbers = _summary_numbers(capsys.readouterr().out)
    assert len(written) == numbers["equal"] + numbers["beyond"]


# ---------------------------------------------------------------- a synthetic run that starts mid-stream

def _sink_into(records):
    return lambda pub, payload, stamp: records.append(Record(pub.key, pub.type_name, payload, pub.seq, stamp, stamp))


def synthetic_run(seed: int, skip: dict[str, int], stop_s: float, listener: Listener | None = None):
    """A talker's outputs, and a 'live' listener that joined late and stopped early, fed like LiveRunner does.

    Returns every record such a recording would hold, in a shuffled file order.
    """
    talker = Talker()
    talker_out = capture_outputs(talker)
    for _ in range(400):                                    # 4 s of sim time
        talker.tick()
    listener = listener or Listener()
    listener_out = capture_outputs(listener)
    diagnostics = []
    listener.diagnostics.sink = _sink_into(diagnostics)
    streams = [[r for r in talker_out if r.key == inp.key][skip.get(inp.key, 0):] for inp in listener.inputs]
    streams = [[r for r in s if r.stamp_ns <= stop_s * 1e9] for s in streams]
    rng = random.Random(seed)
    merger = StampMerger([inp.synced for inp in listener.inputs])
    while any(streams):
        index = rng.choice([i for i, s in enumerate(streams) if s])     # per-stream FIFO, streams interleaved
        msg = decode(streams[index].pop(0).payload, listener.inputs[index].msg_type)
        assert merger.push(index, msg.header.stamp_ns, (index, msg))
        for i, m in merger.pop_ready():
            listener.process(i, m)
            if rng.random() < 0.05:                         # a periodic diagnostic mid-run
                listener.diagnostics.publish(listener.diagnostic())
    for i, m in merger.drain():
        listener.process(i, m)
    listener.close()
    listener.diagnostics.publish(listener.diagnostic())
    records = talker_out + listener_out + diagnostics
    rng.shuffle(records)
    return records, listener_out


@pytest.mark.parametrize("seed", range(5))
def test_a_service_that_joined_mid_stream_replays_aligned(seed):
    records, live_out = synthetic_run(seed, {CHATTER: 7, CLOCK: 23}, stop_s=3.0)
    alignment = find_alignment(records, LISTENER_DIAG)
    assert alignment.first_seq == {CLOCK: 24, CHATTER: 8} and alignment.not_replayable == {}
    run = replay_into(Listener(), records, alignment.first_seq)
    assert run.skipped[CHATTER] == 7 and run.skipped[CLOCK] == 23
    result = compare([r for r in records if r.key == ECHO], run.outputs)
    assert result.ok and result.compared == len(live_out) > 0 and result.beyond > 0
    # without the alignment the replay sums chatter the live service never saw
    unaligned = compare([r for r in records if r.key == ECHO], replay_into(Listener(), records, None).outputs)
    assert not unaligned.ok and unaligned.first.key == ECHO


def test_the_command_reports_the_alignment(tmp_path, capsys):
    records, _ = synthetic_run(0, {CHATTER: 7}, stop_s=3.0)
    write(tmp_path / "mid.mcap", records)
    assert replay(tmp_path / "mid.mcap", "--into", "listener", "--compare") == 0
    out = capsys.readouterr().out
    assert f"{CHATTER}: skipped 7 recorded before the live service's first (seq 8)" in out
    lost_first = [r for r in records if (r.key, r.seq) != (CHATTER, 8)]     # the recorder missed one
    write(tmp_path / "lost.mcap", lost_first)
    assert replay(tmp_path / "lost.mcap", "--into", "listener", "--compare") == 1
    assert f"{CHATTER}: the live service started at seq 8 but the recording resumes at seq 9" in capsys.readouterr().out
    no_diag = [r for r in records if r.key != LISTENER_DIAG]
    write(tmp_path / "nodiag.mcap", no_diag)
    assert replay(tmp_path / "nodiag.mcap", "--into", "listener", "--compare") == 1
    assert f"no Diagnostic on {LISTENER_DIAG}" in capsys.readouterr().out


def test_replay_builds_the_service_with_the_live_runs_parameters(tmp_path, capsys):
    records, _ = synthetic_run(0, {}, stop_s=2.0, listener=Listener(ListenerParams(gain=3.0)))
    write(tmp_path / "gain3.mcap", records)
    assert replay(tmp_path / "gain3.mcap", "--into", "listener", "--compare") == 0
    assert "  parameters: the live run's, from its Diagnostic\n" in capsys.readouterr().out
    assert replay(tmp_path / "gain3.mcap", "--into", "listener", "--set", "gain=1", "--compare") == 1
    out = capsys.readouterr().out
    assert "from its Diagnostic; given here: gain" in out and "FIRST DIVERGENCE" in out
    # a recording from before the parameters were recorded: replay builds with the defaults and says so
    unnamed = [_without_params(r) if r.key == LISTENER_DIAG else r for r in records]
    write(tmp_path / "unnamed.mcap", unnamed)
    assert replay(tmp_path / "unnamed.mcap", "--into", "listener", "--compare") == 1
    assert "the recording does not name listener's" in capsys.readouterr().out
    assert replay(tmp_path / "unnamed.mcap", "--into", "listener", "--set", "gain=3", "--compare") == 0
    # a parameter the live version had and this one has not is ignored, and named
    older = [_with_params(r, gain=3.0, offset=1.0) if r.key == LISTENER_DIAG else r for r in records]
    write(tmp_path / "older.mcap", older)
    assert replay(tmp_path / "older.mcap", "--into", "listener", "--compare") == 0
    assert "from its Diagnostic; ignored, unknown to this code: offset" in capsys.readouterr().out


def _without_params(rec: Record) -> Record:
    diag = decode(rec.payload, Diagnostic)
    del diag.values[PARAMS_VALUE]
    return dataclasses.replace(rec, payload=encode(diag))


def _with_params(rec: Record, **params) -> Record:
    diag = decode(rec.payload, Diagnostic)
    diag.values[PARAMS_VALUE] = json.dumps(params)
    return dataclasses.replace(rec, payload=encode(diag))


@pytest.mark.parametrize("service", sorted(set(SERVICES) - {"map_server"}))    # map_server needs a map file
def test_the_recorded_parameters_build_the_same_parameters(service):
    live = build_node(service, overrides={"robot_radius": 0.3} if service == "local_planner" else None)
    recorded = decode(encode(live.diagnostic()), Diagnostic).values[PARAMS_VALUE]
    assert build_node(service, base=json.loads(recorded)).params == live.params


def test_array_fields_name_the_first_differing_index():
    fan = dict(angle_increment=0.01, angle_max=0.49, range_max=5.0)
    a = LaserScan(ranges=np.linspace(1, 2, 50, dtype="<f4"), intensities=np.zeros(50, "<f4"), **fan)
    b = LaserScan(ranges=a.ranges.copy(), intensities=a.intensities.copy(), **fan)
    b.ranges[17] += 1.0
    b.ranges[30] = np.inf
    b.intensities[0] = -0.0                                 # equal as a number, not as bytes
    diffs = payload_differences(encode(a), encode(b))
    assert diffs[0].startswith("ranges[17]: recorded") and "(2 of 50 elements differ)" in diffs[0]
    assert diffs[1].startswith("intensities[0]:") and len(diffs) == 2


# ---------------------------------------------------------------- bad input fails clearly

@pytest.fixture
def small_recording(tmp_path):
    records, _ = synthetic_run(1, {}, stop_s=1.0)
    path = tmp_path / "small.mcap"
    write(path, records)
    return path


@pytest.mark.parametrize("argv, error", [
    (["{missing}", "--into", "listener"], "no such recording"),
    (["{garbage}", "--into", "listener"], "not an MCAP file"),
    (["{small}", "--into", "nosuch"], "unknown service 'nosuch'"),
    (["{small}", "--into", "listener", "--set", "gian=2"], "unknown parameter 'gian' (did you mean 'gain'?)"),
    (["{small}", "--into", "listener", "--params", "{missing}"], "no such file"),
    (["{small}", "--into", "talker"], "talker has no inputs"),
    (["{small}", "--into", "listener", "--out", "{small}"], "is the recording itself"),
    (["{talker_only}", "--into", "listener", "--compare"], "has no outputs of listener"),
])
def test_bad_requests_fail_clearly_and_leave_the_recording_intact(argv, error, small_recording, tmp_path, capsys):
    (tmp_path / "garbage.mcap").write_bytes(b"not an mcap file" * 8)
    write(tmp_path / "talker_only.mcap", [r for r in read_records(small_recording) if r.key in (CHATTER, CLOCK)])
    before = small_recording.read_bytes()
    paths = {"missing": tmp_path / "missing.mcap", "garbage": tmp_path / "garbage.mcap",
             "small": small_recording, "talker_only": tmp_path / "talker_only.mcap"}
    assert replay(*(a.format(**paths) for a in argv)) == 2
    err = capsys.readouterr().err
    assert err.startswith("omninav replay: error:") and error in err and "Traceback" not in err
    assert small_recording.read_bytes() == before
