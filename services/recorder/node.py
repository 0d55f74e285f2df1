"""The recorder service: every message on some key expressions into MCAP, counted per key.

One thread takes samples and writes them. Zenoh queues each subscription's samples in a bounded
FIFO; when the FIFO is full the network thread waits, which slows BLOCK publishers down instead of
dropping anything. The recorder must keep up with 100k small messages/s, and Python callbacks that
hand each sample to a writer thread (a GIL hand-off per message) measured 108k messages/s against
146k for this design, in the same run of `omninav bench recorder`'s recorder_run on 2 loaded cores.
log_time is therefore the wall time the recorder took the sample from the FIFO: its arrival plus
however long it waited there (up to _IDLE_S when the recorder was idle: each wake-up of a Python
thread costs tens of microseconds of CPU, so it does not poll more often). In a container
(container.py) the services beside the recorder hand it what they publish (take_local), stamped
with the wall time they published it.

Files are flushed every flush_period_s so that a SIGKILL loses at most that much (plus what sat in
the FIFO); `omninav recover` rewrites such a file into a valid one.
"""
from __future__ import annotations

import time
from collections import deque
from dataclasses import dataclass
from pathlib import Path

import zenoh

from ...schemas import MessageError
from ...schemas.attachment import unpack_attachment
from ...schemas.codec import peek_type
from ...schemas.keys import ALL, is_lockstep_key
from ..runtime.node import Node
from ..runtime.joining import LoginRefused
from ..runtime.zenoh_config import open_client
from .mcap_io import RecordingWriter
from .tally import SequenceTally
from ...parameters.declare import Parameters, param

RECORDINGS_DIR = "recordings"
_FIFO_CAPACITY = 16384      # samples; at 100k/s that is 160 ms of slack for a slow chunk write
_BATCH = 512                # samples taken from one subscription before looking at the clock again
_IDLE_S = 0.01            # wall s asleep when nothing was queued; measured CPU per idle second: 25 ms at 2 ms, 11.5 at 10, 6 at 20


@dataclass(frozen=True)
class RecorderParams(Parameters):
    output: str = ""                                      # "" = recordings/omninav-<local time>.mcap
    keys: tuple[str, ...] = param((ALL,), nonempty=True)  # Zenoh key expressions
    split_size_mb: float = param(0.0, ge=0)               # start the next numbered file past this size; 0 = never
    split_duration_s: float = param(0.0, ge=0)            # ... or after this long; 0 = never
    flush_period_s: float = param(0.5, gt=0)              # what a SIGKILL can lose, at most
    chunk_size: int = param(256 * 1024, gt=0)             # uncompressed bytes per zstd chunk


def default_output() -> Path:
    return Path(RECORDINGS_DIR) / time.strftime("omninav-%Y%m%d-%H%M%S.mcap")


def distinct_key_exprs(exprs: tuple[str, ...]) -> list[zenoh.KeyExpr]:
    """The key expressions, validated, without those another one already includes (no duplicates)."""
    parsed = []
    for expr in exprs:
        try:
            parsed.append(zenoh.KeyExpr(expr))
        except zenoh.ZError:
            raise ValueError(f"{expr!r} is not a valid Zenoh key expression") from None
    kept: list[zenoh.KeyExpr] = []
    for i, ke in enumerate(parsed):
        covered = any(other.includes(ke) and (not ke.includes(other) or j < i)
                      for j, other in enumerate(parsed) if j != i)
        if not covered:
            kept.append(ke)
    return kept


class SplitWriter:
    """A RecordingWriter that moves on to the next numbered file past a size or an age."""

    def __init__(self, output: Path, params: RecorderParams):
        self.output, self.params = output, params
        self.split = params.split_size_mb > 0 or params.split_duration_s > 0
        self.files: list[Path] = []
        self.writer: RecordingWriter | None = None
        self._opened_at = 0.0

    def path(self, index: int) -> Path:
        if not self.split:
            return self.output
        return self.output.with_name(f"{self.output.stem}_{index:03d}{self.output.suffix}")

    def existing(self) -> list[Path]:
        """Files this recording would overwrite."""
        if self.output.exists():
            return [self.output]
        if self.split:
            return sorted(self.output.parent.glob(f"{self.output.stem}_[0-9][0-9][0-9]{self.output.suffix}"))
        return []

    def open_next(self, now: float) -> RecordingWriter:
        if self.writer is not None:
            self.writer.close()
        path = self.path(len(self.files))
        self.writer = RecordingWriter(path, chunk_size=self.params.chunk_size,
                                      metadata={"recorder_keys": " ".join(self.params.keys)})
        self.files.append(path)
        self._opened_at = now
        return self.writer

    def due(self, now: float) -> bool:
        """Whether the current file is full (by size on disk or by age)."""
        p = self.params
        return ((p.split_size_mb > 0 and self.writer.file_bytes >= p.split_size_mb * 1e6)
                or (p.split_duration_s > 0 and now - self._opened_at >= p.split_duration_s))

    def close(self) -> None:
        if self.writer is not None:
            self.writer.close()


class RecorderNode(Node):
    service = "recorder"
    # killed before its footer the recording is unreadable until `omninav recover`: under heavy load
    # draining its queue and writing the index took more than the default 10 s (a kill experiment)
    stop_timeout_s = 120.0
    Params = RecorderParams

    def setup(self) -> None:
        self.key_exprs = distinct_key_exprs(self.params.keys)
        self.out = SplitWriter(Path(self.params.output) if self.params.output else default_output(), self.params)
        clash = self.out.existing()
        if clash:
            raise ValueError(f"{clash[0]} exists; the recorder never overwrites a recording (choose another output)")
        self.tally = SequenceTally()
        self.failed = False
        self._types: dict[str, str] = {}      # key -> type, for samples without our attachment
        # in a container: what the services beside it published (take_local), for the recording thread
        self.local: deque[tuple[str, str, bytes, int, int, int]] = deque()
        self._records_key: dict[str, bool] = {}

    def subscriptions(self) -> list[str]:
        return [str(ke) for ke in self.key_exprs]

    def _type_of(self, key: str, payload: bytes) -> str:
        name = self._types.get(key)
        if name is None:
            try:
                name = peek_type(payload)
            except MessageError:
                name = ""       # not an omninav message: recorded raw, without a schema
            self._types[key] = name
        return name

    def take_local(self, key: str, type_name: str, payload: bytes, seq: int, stamp_ns: int) -> None:
        """A message a service beside it in a container published, handed over on that service's
        thread: queued for the recording thread with the wall time now as its log time. It never
        crosses the router: in a container the recorder's subscriptions take only what other
        processes publish (record's `session`)."""
        records = self._records_key.get(key)
        if records is None:
            records = self._records_key[key] = not is_lockstep_key(key) and any(
                ke.intersects(zenoh.KeyExpr(key)) for ke in self.key_exprs)
        if records:
            self.local.append((key, type_name, payload, seq, stamp_ns, time.time_ns()))

    def run_live(self, router: str | None, stop_event, session: zenoh.Session | None = None) -> None:
        """Record until stop_event is set, finish the file(s), print the report."""
        started = time.monotonic()
        try:
            self.record(router, stop_event, session)
        except OSError as exc:      # disk full, directory not writable ...
            self.failed = True
            self.log.error("cannot write the recording: %s; what was flushed before is readable with "
                           "`omninav recover FILE`", exc)
        print(self.report(time.monotonic() - started), flush=True)

    def record(self, router: str | None, stop_event, session: zenoh.Session | None = None) -> None:
        """On its own session, or on a container's (`session`, which it does not close), whose other
        services hand it what they publish (take_local): its subscriptions then take only what comes
        from other sessions."""
        self.out.open_next(time.monotonic())
        if session is not None:
            self._record_on(session, stop_event, zenoh.Locality.REMOTE)
            return
        try:    # as a tool where $OMNINAV_CREDENTIALS names no identity (under `up` it names the recorder's)
            own = open_client(router, stopped=stop_event.is_set, as_tool=True, warn=self.log.warning)
        except LoginRefused:
            self.close()
            raise
        if own is None:     # stopped while waiting for the router: the files are empty, but whole
            self.close()
            return
        with own:
            self._record_on(own, stop_event, None)

    def _record_on(self, session: zenoh.Session, stop_event, origin: zenoh.Locality | None) -> None:
        subscribers = [session.declare_subscriber(ke, zenoh.handlers.FifoChannel(_FIFO_CAPACITY), allowed_origin=origin)
                       for ke in self.key_exprs]
        handlers = [s.handler for s in subscribers]
        alive = session.liveliness().declare_token(self.keys.alive(self.name))
        self.log.info("recording %s to %s%s", " ".join(map(str, self.key_exprs)), self.out.files[0],
                      " and the next numbered files" if self.out.split else "")
        try:
            self._record(handlers, stop_event)
        finally:
            alive.undeclare()
            for sub in subscribers:
                sub.undeclare()
        self._drain(handlers)   # what was queued before the undeclare
        # finish the files before closing the session: a Zenoh session close can hang, and
        # the recording must be complete whatever happens after this point
        self.close()

    def _take_local(self, limit: int) -> int:
        """Write up to `limit` of the messages handed over in-process; returns how many."""
        writer, add, local = self.out.writer, self.tally.add, self.local
        taken = 0
        while local and taken < limit:
            key, type_name, payload, seq, stamp, log_time = local.popleft()
            writer.write(key, type_name, payload, seq, stamp, log_time)
            add(key, type_name, seq)
            taken += 1
        return taken

    def _take(self, handler, limit: int) -> int:
        """Write up to `limit` queued samples of one subscription; returns how many."""
        writer, add = self.out.writer, self.tally.add
        now_ns = time.time_ns
        taken = 0
        while taken < limit:
            sample = handler.try_recv()
            if sample is None:
                break
            key = str(sample.key_expr)
            taken += 1
            if is_lockstep_key(key):
                continue
            payload = sample.payload.to_bytes()
            attachment = sample.attachment
            envelope = unpack_attachment(attachment.to_bytes()) if attachment is not None else None
            if envelope is None:
                seq = stamp = 0
                type_name = self._type_of(key, payload)
            else:
                seq, stamp, type_name = envelope
            writer.write(key, type_name, payload, seq, stamp, now_ns())
            add(key, type_name, seq)
        return taken

    def _record(self, handlers: list, stop_event) -> None:
        period = self.params.flush_period_s
        next_flush = time.monotonic() + period
        while not stop_event.is_set():
            taken = sum(self._take(h, _BATCH) for h in handlers) + self._take_local(_BATCH)
            now = time.monotonic()
            if self.out.split and self.out.due(now):
                self.out.open_next(now)
                next_flush = now + period
            elif now >= next_flush:
                self.out.writer.flush()
                next_flush = now + period
            if not taken:
                stop_event.wait(_IDLE_S)

    def _drain(self, handlers: list) -> None:
        while self._take_local(_BATCH):
            pass
        for handler in handlers:
            try:
                while self._take(handler, _BATCH):
                    pass
            except zenoh.ZError:    # "empty and closed": everything is out
                pass

    def close(self) -> None:
        self.out.close()

    def report(self, elapsed_s: float) -> str:
        files = ", ".join(map(str, self.out.files)) or "no file"
        keys = len(self.tally.keys)
        head = (f"recorded {self.tally.total} messages on {keys} key{'' if keys == 1 else 's'} in {elapsed_s:.1f} s"
                f" to {files}")
        return head + "\n" + self.tally.report()
