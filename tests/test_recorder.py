"""Recording to MCAP: the writer's files, the gap bookkeeping, `omninav record` and `omninav recover` as processes."""
import hashlib
import json
import re
import signal
import zlib

import pytest
import zenoh
import zstandard
from mcap.reader import make_reader
from mcap.records import Chunk, Message, MessageIndex
from mcap.stream_reader import StreamReader, breakup_chunk

from omninav.schemas import decode
from omninav.schemas.attachment import pack_attachment
from omninav.schemas.codec import encode
from omninav.schemas.keys import KeyLayout
from omninav.schemas.messages import Chatter, Clock, Header
from omninav.services.recorder.mcap_io import RecordingError, RecordingWriter, read_readable_records, read_records
from omninav.services.recorder.node import RecorderNode, RecorderParams, distinct_key_exprs
from omninav.services.recorder.tally import SequenceTally
from omninav.services.runtime.zenoh_config import open_client

from conftest import wait_until

KEYS = KeyLayout()
CHATTER = KEYS.robot("chatter")


# ---------------------------------------------------------------- the bookkeeping

def test_tally_counts_messages_and_gaps_per_key():
    tally = SequenceTally()
    for seq in (5, 6, 7, 10, 11, 15):           # joined at 5: not a gap; 8-9 and 12-14 lost
        tally.add("a", "Chatter", seq)
    for seq in (1, 2, 3):
        tally.add("b", "Clock", seq)
    a, b = tally.keys["a"], tally.keys["b"]
    assert (a.messages, a.lost, a.gaps, a.first_seq, a.last_seq) == (6, 5, 2, 5, 15)
    assert (b.messages, b.lost, b.gaps) == (3, 0, 0)
    assert tally.total == 9 and tally.lost == 5
    assert "a lost 5 in 2 gap(s)" in tally.report()


def test_tally_restarts_and_unnumbered_messages_are_not_gaps():
    tally = SequenceTally()
    for seq in (1, 2, 3, 1, 2):                 # the publisher restarted
        tally.add("a", "Chatter", seq)
    for _ in range(4):                          # a foreign publisher without sequence numbers
        tally.add("raw", "", 0)
    assert (tally.keys["a"].lost, tally.keys["a"].restarts) == (0, 1)
    assert (tally.keys["raw"].messages, tally.keys["raw"].lost) == (4, 0)
    assert tally.report().endswith("no sequence gaps")


# ---------------------------------------------------------------- the writer's files

def _records(n):
    out = []
    for i in range(n):
        key = (CHATTER, KEYS.sim("clock"), "foreign/raw")[i % 3]
        if key == CHATTER:
            type_name, payload = "Chatter", encode(Chatter(header=Header(stamp_ns=i, seq=i + 1), text=f"m{i}"))
        elif key == "foreign/raw":
            type_name, payload = "", bytes([i % 256]) * (i % 50)
        else:
            type_name, payload = "Clock", encode(Clock(header=Header(stamp_ns=i)))
        out.append((key, type_name, payload, i + 1, i * 1000, 10_000 + i * 10 - (i % 7)))  # log times not sorted
    return out


def test_writer_output_reads_back_with_schemas_summary_and_message_indexes(tmp_path):
    path = tmp_path / "w.mcap"
    recs = _records(3000)
    with RecordingWriter(path, chunk_size=4096, metadata={"note": "x"}) as writer:
        for i, rec in enumerate(recs):
            writer.write(*rec)
            if i % 500 == 0:
                writer.flush()
    got = [(r.key, r.type_name, r.payload, r.seq, r.stamp_ns, r.log_time_ns) for r in read_records(path)]
    assert got == [(k, t or "unknown", p, s, st, lt) for k, t, p, s, st, lt in recs]
    with open(path, "rb") as f:
        reader = make_reader(f, validate_crcs=True)
        summary = reader.get_summary()
        assert summary.statistics.message_count == 3000
        assert summary.statistics.message_start_time == min(r[5] for r in recs)
        assert summary.statistics.message_end_time == max(r[5] for r in recs)
        assert sorted(summary.statistics.channel_message_counts.values()) == [1000, 1000, 1000]
        schemas = {ch.topic: summary.schemas.get(ch.schema_id) for ch in summary.channels.values()}
        assert schemas[CHATTER].name == "Chatter" and schemas[CHATTER].encoding == "jsonschema"
        assert json.loads(schemas[CHATTER].data)["title"] == "Chatter"
        assert schemas["foreign/raw"].encoding == ""
        ordered = [m.log_time for _, _, m in reader.iter_messages(log_time_order=True)]
        assert ordered == sorted(r[5] for r in recs)
        assert [m.metadata for m in reader.iter_metadata()] == [{"note": "x"}]
    # every message index entry points at a message of that channel with that log time
    checked = 0
    chunk = b""
    with open(path, "rb") as f:
        for record in StreamReader(f, emit_chunks=True, validate_crcs=True).records:
            if isinstance(record, Chunk):
                chunk = zstandard.ZstdDecompressor().decompress(record.data, max_output_size=record.uncompressed_size)
                assert zlib.crc32(chunk) == record.uncompressed_crc
            elif isinstance(record, MessageIndex):
                for log_time, offset in record.records:
                    first = breakup_chunk(Chunk("", chunk[offset:], 0, 0, 0, len(chunk) - offset))[0]
                    assert isinstance(first, Message)
                    assert (first.channel_id, first.log_time) == (record.channel_id, log_time)
                    checked += 1
    assert checked == 3000


def test_a_file_cut_after_a_flush_keeps_everything_flushed(tmp_path):
    path = tmp_path / "cut.mcap"
    recs = _records(100)
    writer = RecordingWriter(path)
    for rec in recs[:60]:
        writer.write(*rec)
    writer.flush()
    for rec in recs[60:]:
        writer.write(*rec)          # never flushed: lost, as with a SIGKILL
    cut = tmp_path / "copy.mcap"
    cut.write_bytes(path.read_bytes())
    writer.close()
    with pytest.raises(RecordingError, match="omninav recover"):
        list(read_records(cut))
    readable, why = read_readable_records(cut)
    assert len(readable) == 60 and why


def test_key_expressions_are_validated_and_deduplicated():
    kept = distinct_key_exprs(("omninav/r1/*", "omninav/**", "omninav/**", "other/x"))
    assert [str(k) for k in kept] == ["omninav/**", "other/x"]
    with pytest.raises(ValueError, match="not a valid Zenoh key expression"):
        distinct_key_exprs(("a//b",))


def test_recorder_refuses_to_overwrite_a_recording(tmp_path):
    existing = tmp_path / "old.mcap"
    existing.write_bytes(b"precious")
    with pytest.raises(ValueError, match="never overwrites"):
        RecorderNode(RecorderParams(output=str(existing)))
    (tmp_path / "run_000.mcap").write_bytes(b"precious")
    with pytest.raises(ValueError, match="never overwrites"):
        RecorderNode(RecorderParams(output=str(tmp_path / "run.mcap"), split_size_mb=1.0))
    assert existing.read_bytes() == b"precious"


# ---------------------------------------------------------------- as processes

def _report(log: str) -> dict[str, tuple[str, int, int]]:
    """key -> (type, messages, lost) from the recorder's report table."""
    rows = re.findall(r"^(omninav/\S+)\s+(\S+)\s+(\d+)\s+(\d+)\s+(\d+)", log, re.M)
    return {key: (type_name, int(n), int(lost)) for key, type_name, n, lost, _ in rows}


def _burst(router_endpoint, n, key=CHATTER, text=lambda i: f"hello {i}"):
    """Publish n Chatter messages with seq 1..n as omninav publishers do (BLOCK, attachment)."""
    with open_client(router_endpoint) as session:
        pub = session.declare_publisher(key, congestion_control=zenoh.CongestionControl.BLOCK,
                                        reliability=zenoh.Reliability.RELIABLE)
        wait_until(lambda: pub.matching_status.matching, 20, what="the recorder's subscription")
        for i in range(1, n + 1):
            msg = Chatter(header=Header(stamp_ns=i * 1000, seq=i), text=text(i), value=float(i))
            pub.put(encode(msg), attachment=pack_attachment(i, i * 1000, "Chatter"))
        pub.undeclare()


def _started(processes, proc):
    wait_until(lambda: "recording " in processes.log_of(proc) or proc.poll() is not None, 30, what="the recorder")
    assert proc.poll() is None, processes.log_of(proc)


def test_record_talker_and_listener_then_stop_with_sigint(processes, router_endpoint, tmp_path):
    out = tmp_path / "run.mcap"
    recorder = processes.omninav("record", "-o", str(out))
    _started(processes, recorder)
    processes.omninav("run", "talker", "--set", "rate=4")
    processes.omninav("run", "listener")
    echoes = []
    with open_client(router_endpoint) as session:
        sub = session.declare_subscriber(KEYS.robot("echo"), lambda s: echoes.append(1))
        wait_until(lambda: len(echoes) >= 15, 30, what="echoes on the bus")
        sub.undeclare()
    assert processes.stop(recorder, signal.SIGINT) == 0
    log = processes.log_of(recorder)
    report = _report(log)
    assert "no sequence gaps" in log

    records = list(read_records(out))
    with open(out, "rb") as f:
        summary = make_reader(f).get_summary()
    topics = [ch.topic for ch in summary.channels.values()]
    assert len(topics) == len(set(topics))                      # one channel per key
    assert {KEYS.robot("chatter"), KEYS.robot("echo"), KEYS.sim("clock")} <= set(topics)
    for ch in summary.channels.values():
        schema = summary.schemas[ch.schema_id]
        assert schema.name == ch.metadata["type"] and schema.encoding == "jsonschema"
        assert json.loads(schema.data)["properties"]["_type"]["const"] == schema.name
    per_key = {}
    for rec in records:
        per_key.setdefault(rec.key, []).append(rec)
    assert {k: (v[0].type_name, len(v), 0) for k, v in per_key.items()} == report
    for key, recs in per_key.items():
        seqs = [r.seq for r in recs]
        assert seqs == list(range(seqs[0], seqs[0] + len(seqs))), f"{key}: lost or reordered"
        for rec in recs:
            msg = decode(rec.payload, key=key)
            assert (msg.header.seq, msg.header.stamp_ns) == (rec.seq, rec.stamp_ns)


def test_sigkilled_recorder_file_is_recovered_completely(processes, router_endpoint, tmp_path):
    out = tmp_path / "killed.mcap"
    n = 5000
    recorder = processes.omninav("record", "-o", str(out), "--flush-period", "0.2", CHATTER)
    _started(processes, recorder)
    _burst(router_endpoint, n)
    # the flush timer alone (no stop, no more traffic) must bring every message to disk
    wait_until(lambda: len(read_readable_records(out)[0]) == n, 30, what="the burst flushed to disk")
    processes.stop(recorder, signal.SIGKILL)
    with pytest.raises(RecordingError, match="omninav recover"):
        list(read_records(out))
    before = hashlib.sha256(out.read_bytes()).hexdigest()

    fixed = processes.omninav("recover", str(out))
    assert fixed.wait(60) == 0, processes.log_of(fixed)
    assert f"saved {n} messages" in processes.log_of(fixed)
    assert hashlib.sha256(out.read_bytes()).hexdigest() == before          # the input is untouched
    recovered = list(read_records(tmp_path / "killed.recovered.mcap"))
    assert [r.seq for r in recovered] == list(range(1, n + 1))
    assert [decode(r.payload, Chatter).text for r in recovered[:3]] == ["hello 1", "hello 2", "hello 3"]
    assert {(r.key, r.type_name) for r in recovered} == {(CHATTER, "Chatter")}
    assert [r.stamp_ns for r in recovered] == [i * 1000 for i in range(1, n + 1)]

    again = processes.omninav("recover", str(out))                       # would overwrite: refused
    assert again.wait(60) == 2 and "exists; use --force" in processes.log_of(again)


def test_recover_fails_clearly_on_missing_or_foreign_files(processes, tmp_path):
    missing = processes.omninav("recover", str(tmp_path / "nope.mcap"))
    assert missing.wait(60) == 2 and "no such recording" in processes.log_of(missing)
    garbage = tmp_path / "garbage.mcap"
    garbage.write_bytes(b"not an mcap file at all" * 10)
    bad = processes.omninav("recover", str(garbage))
    assert bad.wait(60) == 2 and "not an MCAP file" in processes.log_of(bad)
    assert "Traceback" not in processes.log_of(missing) + processes.log_of(bad)
    assert not (tmp_path / "garbage.recovered.mcap").exists()


def test_split_by_size_gives_valid_files_holding_everything(processes, router_endpoint, tmp_path):
    n = 20000
    recorder = processes.omninav("record", "-o", str(tmp_path / "part.mcap"), "--split-size", "0.1", CHATTER)
    _started(processes, recorder)
    noise = [zlib.crc32(str(i).encode()).to_bytes(4, "little").hex() * 8 for i in range(n + 1)]  # poorly compressible
    _burst(router_endpoint, n, text=lambda i: noise[i])
    wait_until(lambda: sum(len(read_readable_records(p)[0]) for p in tmp_path.glob("part_*.mcap")) == n, 30,
               what="the burst written")
    assert processes.stop(recorder, signal.SIGINT) == 0
    files = sorted(tmp_path.glob("part_*.mcap"))
    assert len(files) >= 2 and not (tmp_path / "part.mcap").exists()
    seqs = []
    for path in files:
        seqs += [r.seq for r in read_records(path)]        # each file is finished and valid on its own
    assert seqs == list(range(1, n + 1))
    assert _report(processes.log_of(recorder)) == {CHATTER: ("Chatter", n, 0)}

