"""`omninav replay FILE --into SERVICE`: run one service's code on recorded inputs and compare its outputs.

The service runs exactly the live code (Node.process) on the recorded inputs, in the order the live
StampMerger releases them: order_key(stamp, input index, seq). It starts where the live service
started: the live node's Diagnostic carries the seq of the first message it processed per input key
("first_seq/<key>"), and everything recorded before that is skipped. Time comes only from the
recorded stamps and clock, so the outputs are the live outputs, byte for byte — `--compare` checks
it and names the first divergence. The node is built with the parameters the live service ran with
(its Diagnostic carries them as "params"), with --params and --set over them.
"""
from __future__ import annotations

import argparse
import dataclasses
import json
from collections import Counter
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Iterable

import numpy as np

from ..runtime.errors import UserError, exits_2_on_user_error
from ...schemas import MessageError, decode
from ...schemas.keys import KeyLayout
from ...schemas.messages import Diagnostic
from ..recorder.mcap_io import Record, RecordingError, RecordingWriter, read_records
from ..runtime.live import RUN_STARTED
from ..runtime.merge import order_key
from ..runtime.node import NS_PER_S, PARAMS_VALUE, Node, Publisher
from ..runtime.params import parse_overrides
from ...parameters.declare import ParamError
from ..runtime.service_registry import UnknownService, node_class
from ..runtime.run import build_node, configure_logging

FIRST_SEQ = "first_seq/"
# counters (see Node.diagnostic) that mean the live run did not process in pure stamp order
NOT_REPLAYABLE = ("late/", "sync_timeout")


class ReplayError(UserError):
    """A recording or request that cannot be replayed; the text says why."""


# ---------------------------------------------------------------- alignment with the live run

@dataclass(frozen=True)
class Alignment:
    first_seq: dict[str, int] | None            # None: the recording has no Diagnostic of the service
    not_replayable: dict[str, int]              # live counters that break exact replay (late, sync timeouts)
    run_started_ns: int | None = None           # wall time the last recorded run started (restarts)
    earlier_runs: int = 0                       # runs of the service before that one in the recording
    params: dict | None = None                  # every parameter's live value; None: not recorded


def _run_of(diag: Diagnostic) -> int:
    value = diag.values.get(RUN_STARTED, 0)
    return int(value) if isinstance(value, (int, float)) else 0


def find_alignment(records: Iterable[Record], diagnostics_key: str) -> Alignment:
    """Where the live service started, from the last Diagnostic of its last run in the recording."""
    last: Diagnostic | None = None
    runs: set[int] = set()
    for rec in records:
        if rec.key != diagnostics_key:
            continue
        try:
            diag = decode(rec.payload, Diagnostic, key=rec.key)
        except MessageError:
            continue            # a damaged diagnostic says nothing about alignment
        runs.add(_run_of(diag))
        if last is None or (_run_of(diag), diag.header.seq) > (_run_of(last), last.header.seq):
            last = diag
    if last is None:
        return Alignment(None, {})
    recorded = last.values.get(PARAMS_VALUE)
    try:
        params = json.loads(recorded) if isinstance(recorded, str) else None
    except ValueError:
        params = None
    first_seq = {name[len(FIRST_SEQ):]: int(v) for name, v in last.values.items()
                 if name.startswith(FIRST_SEQ) and isinstance(v, (int, float))}
    trouble = {name: int(v) for name, v in last.values.items()
               if name.startswith(NOT_REPLAYABLE) and isinstance(v, (int, float)) and v}
    return Alignment(first_seq, trouble, _run_of(last) or None, len(runs) - 1,
                     params if isinstance(params, dict) else None)


# ---------------------------------------------------------------- feeding the node

@dataclass
class ReplayRun:
    outputs: list[Record]                       # in the order the node published them
    fed: int = 0
    rejected: int = 0                           # malformed payloads, given to node.reject as live
    skipped: Counter = dataclasses.field(default_factory=Counter)   # key -> inputs the live run never processed
    first_fed: dict[str, int] = dataclasses.field(default_factory=dict)  # key -> seq of the first input fed


def capture_outputs(node: Node) -> list[Record]:
    """Point every output publisher (not the diagnostics: they count wall-time events) at a list."""
    out: list[Record] = []

    def sink(pub: Publisher, payload: bytes, stamp_ns: int) -> None:
        out.append(Record(pub.key, pub.type_name, payload, pub.seq, stamp_ns, stamp_ns))

    for pub in node.outputs.values():
        pub.sink = sink
    return out


def replay_into(node: Node, records: Iterable[Record], first_seq: dict[str, int] | None) -> ReplayRun:
    """Feed the node the recorded inputs it processed live, in live merge order; return what it published.

    first_seq None means no alignment is known: every recorded input is fed.
    """
    index_of = {inp.key: i for i, inp in enumerate(node.inputs)}
    run = ReplayRun(capture_outputs(node))
    queue = []
    for rec in records:
        index = index_of.get(rec.key)
        if index is None:
            continue
        if first_seq is not None and (rec.key not in first_seq or rec.seq < first_seq[rec.key]):
            run.skipped[rec.key] += 1
            continue
        run.first_fed[rec.key] = min(rec.seq, run.first_fed.get(rec.key, rec.seq))
        try:
            msg = decode(rec.payload, node.inputs[index].msg_type, key=rec.key)
        except MessageError as exc:
            node.reject(rec.key, exc)
            run.rejected += 1
            continue
        queue.append((order_key(msg.header.stamp_ns, index, msg.header.seq), index, msg))
    queue.sort(key=lambda item: item[0])
    for _, index, msg in queue:
        node.process(index, msg)
    run.fed = len(queue)
    node.close()
    return run


# ---------------------------------------------------------------- comparing with the recording

@dataclass(frozen=True)
class Divergence:
    key: str
    seq: int
    stamp_ns: int
    differences: tuple[str, ...]


@dataclass(frozen=True)
class Comparison:
    compared: int                   # recorded outputs checked
    equal: int                      # of those, byte-identical to the replay
    beyond: int                     # replayed outputs after the last recorded one on their key
    unrecorded: int                 # replayed outputs inside the recorded range that the recording lacks
    first: Divergence | None        # the earliest divergence in stamp order
    diverged: int                   # how many recorded outputs diverge

    @property
    def ok(self) -> bool:
        return self.compared > 0 and self.first is None


def compare(recorded: Iterable[Record], replayed: Iterable[Record]) -> Comparison:
    """Match outputs by (key, seq): each recorded output must have a byte-identical replayed one."""
    want: dict[tuple[str, int], Record] = {}
    for rec in recorded:
        if (rec.key, rec.seq) in want:
            raise ReplayError(f"the recording has two outputs on {rec.key} with seq {rec.seq}: the service "
                              "restarted while recording; replay a recording of one run")
        want[(rec.key, rec.seq)] = rec
    got = {(rec.key, rec.seq): rec for rec in replayed}
    last_seq: dict[str, int] = {}
    for key, seq in want:
        last_seq[key] = max(seq, last_seq.get(key, seq))
    divergences = []
    for (key, seq), rec in want.items():
        mine = got.get((key, seq))
        if mine is None:
            count = sum(1 for k, _ in got if k == key)
            divergences.append(Divergence(key, seq, rec.stamp_ns, (f"the replay published no seq {seq} on this "
                                                                   f"key (it published {count})",)))
        elif mine.payload != rec.payload:
            divergences.append(Divergence(key, seq, rec.stamp_ns, tuple(payload_differences(rec.payload, mine.payload))))
    extra = [(key, seq) for key, seq in got if (key, seq) not in want]
    beyond = sum(1 for key, seq in extra if seq > last_seq.get(key, 0))
    first = min(divergences, key=lambda d: (d.stamp_ns, d.key, d.seq), default=None)
    return Comparison(len(want), len(want) - len(divergences), beyond, len(extra) - beyond, first, len(divergences))


def payload_differences(recorded: bytes, replayed: bytes) -> list[str]:
    """The fields in which two payloads differ, as 'path: recorded X, replay Y'."""
    try:
        a = decode(recorded)
    except MessageError as exc:
        return [f"the recorded payload does not decode: {exc}"]
    try:
        b = decode(replayed)
    except MessageError as exc:
        return [f"the replayed payload does not decode: {exc}"]
    return field_differences(a, b) or ["the bytes differ although every field decodes equal (map key order?)"]


def field_differences(a: Any, b: Any, path: str = "") -> list[str]:
    where = path or "message"
    if type(a) is not type(b):
        return [f"{where}: recorded a {type(a).__name__}, replay a {type(b).__name__}"]
    if dataclasses.is_dataclass(a):
        out = []
        for f in dataclasses.fields(a):
            out += field_differences(getattr(a, f.name), getattr(b, f.name), f"{path}.{f.name}" if path else f.name)
        return out
    if isinstance(a, np.ndarray):
        return _array_differences(a, b, where)
    if isinstance(a, dict):
        out = []
        for name in sorted(set(a) | set(b), key=str):
            sub = f"{where}[{name!r}]"
            if name not in a or name not in b:
                out.append(f"{sub}: {'only in the replay' if name not in a else 'only in the recording'}")
            else:
                out += field_differences(a[name], b[name], sub)
        return out
    # repr tells -0.0 from 0.0 and equates NaNs, as the bytes do
    same = repr(a) == repr(b) if isinstance(a, float) else a == b
    return [] if same else [f"{where}: recorded {a!r}, replay {b!r}"]


def _array_differences(a: np.ndarray, b: np.ndarray, where: str) -> list[str]:
    if a.dtype != b.dtype or a.shape != b.shape:
        return [f"{where}: recorded {a.dtype}{list(a.shape)}, replay {b.dtype}{list(b.shape)}"]

    def bits(arr: np.ndarray) -> np.ndarray:   # compare bit patterns, like the payload bytes
        size = arr.dtype.itemsize
        return np.ascontiguousarray(arr).view(f"u{size}") if size in (1, 2, 4, 8) else arr

    differ = np.flatnonzero(bits(a).ravel() != bits(b).ravel())
    if differ.size == 0:
        return []
    at = np.unravel_index(differ[0], a.shape)
    index = ",".join(str(int(i)) for i in at)
    return [f"{where}[{index}]: recorded {a[at]!r}, replay {b[at]!r} ({differ.size} of {a.size} elements differ)"]


# ---------------------------------------------------------------- the command

def _seconds(stamp_ns: int) -> str:
    return f"{stamp_ns / NS_PER_S:.9f} s"


def _load(path: str, keys: set[str]) -> list[Record]:
    try:
        return list(read_records(path, keys))
    except RecordingError as exc:
        raise ReplayError(str(exc)) from None


def _alignment_notes(node: Node, alignment: Alignment, run: ReplayRun, diag_key: str) -> list[str]:
    if alignment.first_seq is None:
        return [f"no Diagnostic on {diag_key} in the recording: fed every recorded input (if the live service "
                "started after the recording did, expect a divergence at the start)"]
    notes = []
    for inp in node.inputs:
        want = alignment.first_seq.get(inp.key)
        if want is None:
            if run.skipped[inp.key]:
                notes.append(f"{inp.key}: the live service processed none of it; skipped all {run.skipped[inp.key]}")
        elif run.first_fed.get(inp.key) != want:
            found = run.first_fed.get(inp.key)
            notes.append(f"{inp.key}: the live service started at seq {want} but the recording "
                         + (f"resumes at seq {found}" if found is not None else "has nothing from there on")
                         + ": expect a divergence")
        elif run.skipped[inp.key]:
            notes.append(f"{inp.key}: skipped {run.skipped[inp.key]} recorded before the live service's first "
                         f"(seq {want})")
    for name, count in sorted(alignment.not_replayable.items()):
        notes.append(f"the live run counted {name}={count}: it did not process in pure stamp order, so it is not "
                     "exactly replayable")
    return notes


def _parameters_note(node: Node, alignment: Alignment, overridden: list[str], unknown: list[str]) -> str:
    over = f"; given here: {', '.join(overridden)}" if overridden else ""
    if alignment.params is None:
        return (f"parameters: the recording does not name {node.name}'s (no \"{PARAMS_VALUE}\" in its Diagnostic): "
                f"defaults{over} (give the live run's with --params / --set)")
    dropped = f"; ignored, unknown to this code: {', '.join(unknown)}" if unknown else ""
    return f"parameters: the live run's, from its Diagnostic{over}{dropped}"


@exits_2_on_user_error("replay")
def main_into(args: argparse.Namespace) -> int:
    try:
        overrides = parse_overrides(args.set)
        cls = node_class(args.into)
        diag_key = KeyLayout(args.robot).diagnostics(args.name or cls.service)
    except (UnknownService, ParamError, ValueError) as exc:   # ValueError: a bad robot or instance name
        raise ReplayError(str(exc)) from None
    # first where the live service started and with which parameters, then the node built like it
    alignment = find_alignment(_load(args.file, {diag_key}), diag_key)
    known = {f.name for f in dataclasses.fields(cls.Params) if f.init}
    # the live run's state files are its own: a replay neither resumes from them nor writes them
    recorded = {k: v for k, v in (alignment.params or {}).items() if k in known} | dict.fromkeys(cls.state_files, "")
    unknown = sorted(set(alignment.params or {}) - known)     # recorded by an older version of the service
    try:
        node = build_node(args.into, args.params, overrides, args.robot, args.name,
                          base=recorded if alignment.params is not None else None)
    except (UnknownService, ParamError, ValueError) as exc:
        raise ReplayError(str(exc)) from None
    configure_logging(f"replay {node.name}", "WARNING")
    if not node.inputs:
        raise ReplayError(f"{args.into} has no inputs (it is a source): there is nothing to replay into it")
    if args.out and Path(args.out).resolve() == Path(args.file).resolve():
        raise ReplayError(f"--out {args.out} is the recording itself; choose another file")
    records = _load(args.file, {i.key for i in node.inputs} | set(node.outputs) | {diag_key})
    run = replay_into(node, records, alignment.first_seq)

    print(f"replay {args.file} into {node.name}: {run.fed} inputs fed, {sum(run.skipped.values())} skipped, "
          f"{run.rejected} malformed")
    given = [*(["--params " + args.params] if args.params else []), *overrides]
    print(f"  {_parameters_note(node, alignment, given, unknown)}")
    for note in _alignment_notes(node, alignment, run, diag_key):
        print(f"  {note}")
    per_key = Counter(rec.key for rec in run.outputs)
    print(f"outputs produced: {len(run.outputs)}" + "".join(f", {k} {n}" for k, n in sorted(per_key.items())))
    if args.out:
        try:
            with RecordingWriter(args.out, metadata={"replay_of": args.file, "service": node.name}) as writer:
                for rec in run.outputs:
                    writer.write_record(rec)
        except OSError as exc:
            raise ReplayError(f"--out {args.out}: cannot write ({exc})") from None
        print(f"wrote {len(run.outputs)} outputs to {args.out}")
    if not args.compare:
        return 0

    # a restarted service starts its seqs again: compare only what its last run published
    since = alignment.run_started_ns or 0
    recorded = [rec for rec in records if rec.key in node.outputs and rec.log_time_ns >= since]
    if alignment.earlier_runs:
        print(f"  the recording holds {alignment.earlier_runs} earlier run(s) of {node.name}: comparing the last")
    if not recorded:
        raise ReplayError(f"{args.file} has no outputs of {node.name} (keys {sorted(node.outputs)}) to compare with")
    result = compare(recorded, run.outputs)
    print(f"outputs compared: {result.compared}, equal: {result.equal}; replayed beyond the end of the recording: "
          f"{result.beyond}, missing from the recording: {result.unrecorded}")
    if result.first is not None:
        d = result.first
        print(f"FIRST DIVERGENCE ({result.diverged} of {result.compared} differ): {d.key} seq {d.seq} "
              f"stamp {_seconds(d.stamp_ns)}")
        for line in d.differences:
            print(f"  {line}")
        return 1
    print("replay reproduces the recorded outputs byte for byte")
    return 0
