"""Drive a Node from Zenoh: callbacks only enqueue; one thread decodes, merges by stamp, processes.

What a callback enqueues is a Received payload, which every node of a process that takes it shares
and decodes once (per message type) — in a container (container.py) the seven services that take
odometry would otherwise decode each of its 100 messages a second seven times.

The wait bound (sync_timeout_s, wall time) exists only so a dead input stream cannot stall the
service forever; when it is hit the service counts it in its Diagnostic, because that run is no
longer exactly replayable.
"""
from __future__ import annotations

import json
import math
import os
import queue
import threading
import time
from typing import Callable, Iterable

import zenoh

from ...schemas import MessageError, decode
from ...schemas.attachment import pack_attachment, unpack_attachment
from ...schemas.codec import encode
from ...schemas.messages import Diagnostic
from .lockstep import Barrier, Lockstep, Report
from .merge import StampMerger
from .node import NS_PER_S, Node, Publisher, QueryError
from .selector import parse_parameters
from .zenoh_config import MAX_MESSAGE_SIZE, client_config, open_client

POLL_S = 0.05           # wall s a runner waits for input before it looks at its clocks again
_REPORT_AGAIN_S = 0.5   # a lockstep participant's unchanged progress is repeated this often (wall)
_STALL_LOG_S = 10.0     # a lockstep step held up this long (wall) is logged with who holds it
RUN_STARTED = "run_started_ns"
# set by `up` for every process it starts: the liveliness tokens (comma-separated) of the run's
# services that set no pace of their own; a source waits for them before it declares anything, so
# its first messages find everyone listening while every process starts at once
LISTENERS_ENV = "OMNINAV_LISTENERS"
LISTENERS_TIMEOUT_S = 60.0      # imports and numba caches on a loaded 2-core machine take a while


def tokens_present(session: zenoh.Session, keys: Iterable[str], timeout_s: float = 0.5) -> set[str]:
    """Which of these liveliness tokens (KeyLayout.alive: a service is ready) are declared now; one
    query per robot namespace rather than one per service."""
    wanted = set(keys)
    found: set[str] = set()
    for expr in {key.rpartition("/")[0] + "/*" for key in wanted}:
        found.update(str(reply.ok.key_expr) for reply in session.liveliness().get(expr, timeout=timeout_s)
                     if reply.ok is not None)
    return found & wanted


def await_tokens(session: zenoh.Session, keys: Iterable[str], timeout_s: float,
                 give_up: Callable[[], bool] = lambda: False) -> set[str]:
    """Until each of these liveliness tokens is declared, give_up() says so, or timeout_s (wall) has
    passed; the keys still missing."""
    missing = set(keys)
    deadline = time.monotonic() + timeout_s
    while missing and not give_up() and time.monotonic() < deadline:
        missing -= tokens_present(session, missing)
        if missing:
            time.sleep(POLL_S)
    return missing


def listeners_from_env() -> tuple[str, ...]:
    """The tokens a source waits for ($OMNINAV_LISTENERS); none when no launcher set them."""
    return tuple(filter(None, os.environ.get(LISTENERS_ENV, "").split(",")))


def _seq_of(sample) -> int | None:
    attachment = sample.attachment
    envelope = unpack_attachment(attachment.to_bytes()) if attachment is not None else None
    return None if envelope is None else envelope.seq


class Received:
    """A payload on a key, shared by the nodes of this process that take it: decoded on the first
    node's thread that asks for its type, then the one message handed to each (read-only, as
    InProcessRunner shares one). Thread-safe; a payload that does not decode gives the MessageError
    to everyone who asks."""
    __slots__ = ("payload", "key", "_decoded", "_lock")

    def __init__(self, payload: bytes, key: str):
        self.payload, self.key = payload, key
        self._decoded: dict[type, object] = {}
        self._lock = threading.Lock()

    def message(self, msg_type: type):
        """The decoded message, or the MessageError saying why there is none."""
        with self._lock:
            if msg_type not in self._decoded:
                try:
                    self._decoded[msg_type] = decode(self.payload, msg_type, key=self.key)
                except MessageError as exc:
                    self._decoded[msg_type] = exc
            return self._decoded[msg_type]


def received_from(sample) -> tuple[Received, int | None]:
    """A Zenoh sample's payload as Received and the sequence number in its attachment (None without)."""
    return Received(sample.payload.to_bytes(), str(sample.key_expr)), _seq_of(sample)


class PayloadTooLarge(ValueError):
    """A message over what the transport carries; inside a handler the node's guard logs and counts it."""


def deliver(takers, received: Received, seq: int | None) -> None:
    """Into the inbox of each (runner, input index) that takes the payload's key."""
    for runner, index in takers:
        runner._inbox.put(("msg", index, received, seq))


class LiveRunner:
    def __init__(self, node: Node, router: str | None = None, *, sync_timeout_s: float = 1.0,
                 diagnostics_period_s: float = 1.0, lockstep: Lockstep | None = None):
        self.node = node
        # lockstep.py: on when the launcher set OMNINAV_LOCKSTEP; the sim coordinates, the others report
        self.lockstep = lockstep if lockstep is not None else Lockstep.from_env()
        self.listeners = listeners_from_env()
        self.barrier = Barrier(self.lockstep.wait_for) if self.lockstep and node.coordinates_lockstep else None
        self._received: dict[str, int] = {}      # key -> last seq taken (lockstep progress)
        self._reported: tuple | None = None
        self._report_again = 0.0
        self.router = router
        self.sync_timeout_s = sync_timeout_s
        self.diagnostics_period_s = diagnostics_period_s
        self.stop_event = threading.Event()
        self._inbox: queue.SimpleQueue = queue.SimpleQueue()
        self._merger = StampMerger([i.synced for i in node.inputs])
        self._zpubs: dict[str, zenoh.Publisher] = {}
        # the largest message every session of the run accepts (they share one configuration):
        # a bigger one would be dropped by the receiving side, so it is refused here with its size
        self.max_payload = json.loads(client_config(router).get_json(MAX_MESSAGE_SIZE))
        # identifies this run of the service in its diagnostics, so replay can tell a restarted
        # service's runs apart in one recording (wall time: diagnostics are never compared)
        self.started_ns = time.time_ns()
        # in a container (container.py): key -> the (runner, input index) of this process that take it;
        # those get a published message straight into their inbox, the bus carries it to the others,
        # and the container subscribes once per key for all of them
        self.local: dict[str, list[tuple[LiveRunner, int]]] | None = None
        # in a container: (key, type name, payload, seq, stamp_ns) of every message published is also
        # handed to these (a recorder beside it: RecorderNode.take_local)
        self.taps: list[Callable[[str, str, bytes, int, int], None]] = []

    def stop(self) -> None:
        """Ask the loop to finish, from any thread (at a signal on_stop_signals calls it on one of its
        own). The wake-up item matters: on CPython 3.11 a SimpleQueue.get(timeout) interrupted by a
        signal can block until the next put, and a source (no inputs) would never get one."""
        self.stop_event.set()
        self._inbox.put(("wake",))

    def stops_with(self, event: threading.Event) -> None:
        """Stop when `event` is set (a run_live's caller's, which `omninav run`'s signal handlers set),
        waking this runner's own inbox as stop() does: the caller's handlers wake only theirs, and a
        get(timeout) a signal interrupted can block until the next put (the ros2 bridge, idle, did
        not stop at SIGINT within 120 s)."""
        self.stop_event = event

        def wake_when_set() -> None:
            event.wait()
            self._inbox.put(("wake",))
        threading.Thread(target=wake_when_set, daemon=True, name="stop-wake").start()

    # ------------------------------------------------------------ wiring

    def _sink(self, pub: Publisher, payload: bytes, stamp_ns: int) -> None:
        if len(payload) > self.max_payload:
            raise PayloadTooLarge(f"{pub.key}: a {pub.type_name} of {len(payload):,d} bytes is over the "
                                  f"{self.max_payload:,d} bytes a Zenoh message may carry here "
                                  f"({MAX_MESSAGE_SIZE}); not sent")
        self._zpubs[pub.key].put(payload, attachment=pack_attachment(pub.seq, stamp_ns, pub.type_name))
        if self.local is not None:
            deliver(self.local.get(pub.key, ()), Received(payload, pub.key), pub.seq)
        for tap in self.taps:
            tap(pub.key, pub.type_name, payload, pub.seq, stamp_ns)

    def _declare(self, session: zenoh.Session) -> list:
        handles = []
        # in a container the session's own subscribers are this process's nodes, which _sink serves
        destination = None if self.local is None else zenoh.Locality.REMOTE
        for key, pub in self.node.outputs.items():
            self._zpubs[key] = session.declare_publisher(
                key, congestion_control=zenoh.CongestionControl.BLOCK, reliability=zenoh.Reliability.RELIABLE,
                allowed_destination=destination)
            pub.sink = self._sink
        diag = self.node.diagnostics
        self._zpubs[diag.key] = session.declare_publisher(diag.key, congestion_control=zenoh.CongestionControl.BLOCK,
                                                          allowed_destination=destination)
        diag.sink = self._sink
        if self.local is None:      # a container subscribes for its nodes
            for index, inp in enumerate(self.node.inputs):
                handles.append(session.declare_subscriber(
                    inp.key, lambda s, i=index: self._inbox.put(("msg", i, *received_from(s)))))
        for key in self.node.queryables:
            handles.append(session.declare_queryable(key, lambda q: self._inbox.put(("query", q))))
        if self.lockstep is not None:
            handles += self._declare_lockstep(session)
        # last: `omninav up` starts the next service only once this one can hear and speak
        handles.append(session.liveliness().declare_token(self.node.keys.alive(self.node.name)))
        return handles

    def _declare_lockstep(self, session: zenoh.Session) -> list:
        keys = self.node.keys
        self._report_pub = Publisher(keys.lockstep(self.node.name), Diagnostic)
        self._zpubs[self._report_pub.key] = session.declare_publisher(
            self._report_pub.key, congestion_control=zenoh.CongestionControl.BLOCK,
            reliability=zenoh.Reliability.RELIABLE)
        self._report_pub.sink = self._sink
        if self.barrier is None:
            return []
        def on_token(sample) -> None:
            if sample.kind == zenoh.SampleKind.DELETE:
                self._inbox.put(("left", keys.service_of_alive(str(sample.key_expr))))

        return [session.declare_subscriber(keys.lockstep_of_all(),
                                           lambda s: self._inbox.put(("report", s.payload.to_bytes()))),
                session.liveliness().declare_subscriber(keys.alive_of_all(), on_token)]

    # ------------------------------------------------------------ the processing thread

    def run(self, session: zenoh.Session | None = None) -> None:
        """Process until stop_event is set; then drain what is buffered and undeclare. On its own
        session (closed at the end), or on a container's shared one."""
        if session is None:
            own = open_client(self.router, stopped=self.stop_event.is_set, warn=self.node.log.warning)
            if own is not None:     # else stopped while waiting for the router
                with own:
                    self.run(own)
            return
        self.open(session)
        while not self.stop_event.is_set():
            self._take_inbox(self.wait_s())
            self.turn()
        self.close()

    def open(self, session: zenoh.Session) -> None:
        """Declare everything on the session and start the clocks of the turns. A source first
        waits for the run's listeners ($OMNINAV_LISTENERS), so its first messages find them."""
        if self.listeners and self.node.pace_s() is not None:
            late = await_tokens(session, self.listeners, LISTENERS_TIMEOUT_S, self.stop_event.is_set)
            if late and not self.stop_event.is_set():
                self.node.log.warning("%s not ready within %.0f s; starting anyway", ", ".join(sorted(late)),
                                      LISTENERS_TIMEOUT_S)
        self._handles = self._declare(session)
        pacer = self.node.pace_s()
        self._pacer = pacer
        # in lockstep the wall clock decides nothing: the sim ticks when the barrier lets it, any
        # other paced node (teleop) on its inputs' sim time
        self._stepped = self.lockstep is not None and pacer is not None and pacer != math.inf
        now = time.monotonic()
        self._next_tick = now
        self._next_tick_ns: int | None = None
        self._next_diag = now + self.diagnostics_period_s
        self._stalled_since = now
        self._ready = False     # lockstep: the barrier's answer after the last inputs; then only the pace is waited for

    def close(self) -> None:
        """Process what is buffered, close the node, publish its last Diagnostic and undeclare."""
        self._finish()
        for handle in self._handles:
            handle.undeclare()
        for zpub in self._zpubs.values():
            zpub.undeclare()

    def wait_s(self) -> float:
        """How long this runner may wait for input before its next turn: until its next tick when
        paced (in lockstep: once the barrier let it), else a poll period."""
        if self._pacer is None or (self._stepped and not self._ready):
            return POLL_S
        return max(0.0, min(POLL_S, self._next_tick - time.monotonic()))

    def turn(self) -> None:
        """After taking the inbox: process what the merger releases, tick when due, report."""
        self._release()
        now = time.monotonic()
        if self._stepped:
            self._lockstep_tick(now)
        elif self._pacer is not None and now >= self._next_tick:
            self.node.tick()
            self._next_tick = max(self._next_tick + self._pacer, now - 10 * self._pacer)  # never burst more than 10 ticks
        self._report_progress()
        if now >= self._next_diag:
            self._publish_diagnostic()
            self._next_diag = now + self.diagnostics_period_s

    def _take_inbox(self, wait_s: float) -> None:
        try:
            self._handle(self._inbox.get(timeout=wait_s))
            while True:  # take everything queued before merging, so stamps sort in one go
                self._handle(self._inbox.get_nowait())
        except queue.Empty:
            pass

    def _lockstep_tick(self, now: float) -> None:
        """The coordinator ticks once the barrier lets it and, with a pace (the sim's rate), not
        before its wall time: paced lockstep is real time while the services keep up, slower when
        they do not, and never late. The others tick on their inputs' sim time."""
        if self.barrier is not None:
            self._ready = self._may_step()
            if self._ready and now >= self._next_tick:
                self.node.tick()
                self._ready = False       # the step's messages are on their way
                self._next_tick = max(self._next_tick + self._pacer, now - 10 * self._pacer)
                self._stalled_since = now
            elif not self._ready and now - self._stalled_since > _STALL_LOG_S:
                self.node.log.info("lockstep: waiting for %s", ", ".join(self._waiting_on()) or "inputs")
                self._stalled_since = now
        elif self.node.now_ns and (self._next_tick_ns is None or self.node.now_ns >= self._next_tick_ns):
            self.node.tick()
            self._next_tick_ns = self.node.now_ns + round(self._pacer * NS_PER_S)

    def _published(self) -> dict[str, int]:
        return {key: pub.seq for key, pub in self.node.outputs.items() if pub.seq}

    def _may_step(self) -> bool:
        return self.barrier.ready(self._published(), self._received, self.node.subscriptions())

    def _waiting_on(self) -> list[str]:
        return self.barrier.waiting_on(self._published())

    def _report_progress(self) -> None:
        """A participant's progress, when it changed (lockstep.py); only after its work is done."""
        if self.lockstep is None or self.barrier is not None:
            return
        hold, published = self.node.holds_lockstep(), self._published()
        state = (tuple(self._received.items()), tuple(published.items()), hold)
        now = time.monotonic()
        # again now and then while idle: a coordinator that subscribed late missed the last one
        if state == self._reported and now < self._report_again:
            return
        self._reported, self._report_again = state, now + _REPORT_AGAIN_S
        report = Report(self.node.name, self.started_ns, tuple(self.node.subscriptions()), dict(self._received),
                        published, hold)
        self._report_pub.publish(report.to_message(self.node.now_ns))

    def _handle(self, item: tuple) -> None:
        if item[0] == "wake":
            return
        if item[0] == "query":
            self._answer(item[1])
            return
        if item[0] == "report":
            self._take_report(item[1])
            return
        if item[0] == "left":
            self.barrier.leave(item[1])
            return
        _, index, received, seq = item
        key = received.key
        if seq is not None:
            self._received[key] = seq
        inp = self.node.inputs[index]
        msg = received.message(inp.msg_type)
        if isinstance(msg, MessageError):
            self.node.reject(key, msg)
            return
        stamp = msg.header.stamp_ns
        in_order = self._merger.push(index, stamp, (index, msg), time.monotonic())
        if not in_order and stamp + inp.max_delay_ns < self._merger.released_upto:
            self.node.counters[f"late/{key}"] += 1

    def _release(self) -> None:
        for index, msg in self._merger.pop_ready():
            self.node.process(index, msg)
        if self.lockstep is not None:
            return      # nothing is waited out: the sim does not step until every input is in
        waited_since = self._merger.head_enqueued_at()
        if waited_since is not None and time.monotonic() - waited_since > self.sync_timeout_s:
            self.node.counters["sync_timeouts"] += 1
            if self.node.counters["sync_timeouts"] == 1:
                self.node.log.warning("an input stream stopped for %.1fs; processing without it "
                                      "(this run is not exactly replayable)", self.sync_timeout_s)
            index, msg = self._merger.pop_oldest()
            self.node.process(index, msg)

    def _take_report(self, payload: bytes) -> None:
        try:
            report = Report.from_message(decode(payload, Diagnostic))
        except (MessageError, ValueError) as exc:
            self.node.reject(self.node.keys.lockstep_of_all(), MessageError(str(exc)))
            return
        if report.name != self.node.name:
            self.barrier.update(report)

    def _answer(self, query: zenoh.Query) -> None:
        key = str(query.key_expr)
        params = parse_parameters(str(query.parameters))
        try:
            reply = self.node.answer(key, params)
        except QueryError as exc:
            query.reply_err(str(exc).encode())
        else:
            if reply is None:
                query.reply_err(f"{key}: no value yet".encode())
            else:
                query.reply(key, encode(reply))
        finally:
            query.drop()

    def _publish_diagnostic(self) -> None:
        diag = self.node.diagnostic()
        diag.values[RUN_STARTED] = self.started_ns
        self.node.diagnostics.publish(diag)

    def _finish(self) -> None:
        held = self._merger.drain()
        if self.lockstep is None:
            for index, msg in held:
                self.node.process(index, msg)
        else:
            # a lockstep run ends at its last step: what waited for a step that never came would come
            # out now, and whether the recorder is still there to take it is a race of the stopping
            self.node.counters["dropped_at_stop"] += len(held)
        self._report_progress()
        self.node.close()
        self._publish_diagnostic()
