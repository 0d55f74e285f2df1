"""Run several Nodes in one thread, in lockstep: the whole pipeline deterministic and as fast as
the CPU allows, for evaluations and benchmarks.

Each published message is decoded again from its bytes and pushed into every subscriber's
StampMerger (the same bytes and the same order rules as live), so the nodes run exactly their live
code. It is decoded once and the one message handed to every subscriber, as ROS 2's intra-process
communication shares one const message: handlers treat what they receive as read-only (its arrays
are read-only views over the payload; nothing may assign to its fields). Sources (the
sim) are ticked one step at a time, and after each tick every node processes whatever its merger
releases until nothing moves: the sim never runs ahead of a slow service.
"""
from __future__ import annotations

import time
from collections import Counter, defaultdict
from typing import Any, Callable, Iterable

from ...schemas import MessageError, decode
from .merge import StampMerger
from .node import Input, Node, Publisher


DELIVERY = "delivery (decode, merge)"
RECORDING = "recording (MCAP)"
WATCHING = "watchers (mission scoring)"


class CpuMeter:
    """This thread's CPU time split between what it works for — a node's handlers and ticks (its
    outputs' encoding included), the runner's delivery, the recording — each charged only for its
    own time (a node's handler that publishes is not charged for the delivery of what it published).
    `omninav bench cpu` reads it: where a mission's CPU goes, service by service."""

    def __init__(self, first: str = "other"):
        self.ns: Counter[str] = Counter()
        self.calls: Counter[str] = Counter()
        self._stack = [first]
        self.start()

    def start(self) -> None:
        """Charge from now on (what came before, the nodes' setup, is not a run's steady cost);
        process_started_ns: the whole process's CPU time then (time.process_time_ns)."""
        self.ns.clear()
        self.calls.clear()
        self._since = time.thread_time_ns()
        self.process_started_ns = time.process_time_ns()

    def enter(self, what: str) -> None:
        now = time.thread_time_ns()
        self.ns[self._stack[-1]] += now - self._since
        self._since = now
        self._stack.append(what)
        self.calls[what] += 1

    def leave(self) -> None:
        now = time.thread_time_ns()
        self.ns[self._stack.pop()] += now - self._since
        self._since = now


class InProcessRunner:
    def __init__(self, nodes: Iterable[Node], meter: CpuMeter | None = None):
        self.nodes = list(nodes)
        self.meter = meter
        if meter is not None:
            meter.start()
        self.sources = [n for n in self.nodes if n.pace_s() is not None]
        if not self.sources:
            raise ValueError("an in-process run needs a source node (the sim) to advance time")
        self._mergers = [StampMerger([i.synced for i in n.inputs]) for n in self.nodes]
        # which mergers were pushed to since they last released: only those can have become ready
        self._pushed = [False] * len(self.nodes)
        self._routes: dict[str, list[tuple[int, int, Input]]] = defaultdict(list)
        for position, node in enumerate(self.nodes):
            for index, inp in enumerate(node.inputs):
                self._routes[inp.key].append((position, index, inp))
        self._taps: list[Callable[[str, bytes, int], None]] = []
        self._watchers: dict[str, list[Callable[[str, Any], None]]] = defaultdict(list)
        self._writers: list = []
        for node in self.nodes:
            for pub in (*node.outputs.values(), node.diagnostics):
                pub.sink = self._deliver

    def tap(self, callback: Callable[[str, bytes, int], None]) -> None:
        """Also hand every published (key, payload, stamp_ns) to callback — a recorder, a probe."""
        self._taps.append(callback)

    def watch(self, keys: Iterable[str], callback: Callable[[str, Any], None]) -> None:
        """Also hand every message published on these keys to callback(key, message), decoded: the
        one message the subscribers get, so read-only. A payload that does not decode is skipped."""
        for key in keys:
            self._watchers[key].append(callback)

    def record(self, writer) -> None:
        """Also write every published message to a recording (a RecordingWriter), as the recorder
        would; its log time is the sim stamp, so the same run gives the same file byte for byte."""
        self._writers.append(writer)

    def _metered(self, what: str, call: Callable, *args) -> Any:
        """call(*args), its CPU time charged to `what` when a meter is on."""
        if self.meter is None:
            return call(*args)
        self.meter.enter(what)
        try:
            return call(*args)
        finally:
            self.meter.leave()

    def _deliver(self, pub: Publisher, payload: bytes, stamp_ns: int) -> None:
        self._metered(DELIVERY, self._hand_over, pub, payload, stamp_ns)

    def _record(self, pub: Publisher, payload: bytes, stamp_ns: int) -> None:
        for writer in self._writers:
            writer.write(pub.key, pub.type_name, payload, pub.seq, stamp_ns, stamp_ns)

    def _hand_over(self, pub: Publisher, payload: bytes, stamp_ns: int) -> None:
        if self._writers:
            self._metered(RECORDING, self._record, pub, payload, stamp_ns)
        for tap in self._taps:
            tap(pub.key, payload, stamp_ns)
        decoded: dict[type, Any] = {}      # one message per type, handed to everyone who takes it

        def message(msg_type: type) -> Any:
            if msg_type not in decoded:
                decoded[msg_type] = decode(payload, msg_type, key=pub.key)
            return decoded[msg_type]

        for position, index, inp in self._routes.get(pub.key, ()):
            try:
                msg = message(inp.msg_type)
            except MessageError as exc:
                self.nodes[position].reject(pub.key, exc)
                continue
            self._pushed[position] = True
            if not self._mergers[position].push(index, msg.header.stamp_ns, (index, msg)):
                self.nodes[position].counters[f"late/{pub.key}"] += 1
        watchers = self._watchers.get(pub.key, ())
        if watchers:
            self._metered(WATCHING, self._watch, watchers, pub, message)

    @staticmethod
    def _watch(watchers: list, pub: Publisher, message: Callable[[type], Any]) -> None:
        for callback in watchers:
            try:
                msg = message(pub.msg_type)
            except MessageError:
                return      # watchers skip what does not decode
            callback(pub.key, msg)

    def _settle(self) -> None:
        moved = True
        while moved:
            moved = False
            for position, node in enumerate(self.nodes):
                if not self._pushed[position]:
                    continue
                self._pushed[position] = False
                for index, msg in self._mergers[position].pop_ready():
                    self._metered(node.name, node.process, index, msg)
                    moved = True

    def step(self) -> None:
        """One tick of every source, then every node works until nothing more is ready."""
        for source in self.sources:
            self._metered(source.name, source.tick)
        self._settle()

    def run_until(self, done: Callable[[], bool], max_steps: int) -> int:
        """Step until done() is true or max_steps have run; returns the steps taken."""
        for steps in range(1, max_steps + 1):
            self.step()
            if done():
                return steps
        return max_steps

    def close(self) -> None:
        # the run ends at its last step, as a lockstep run of processes does (live.py): what a node
        # held for a later step is dropped, not handled in the order the nodes happen to be closed
        for node, merger in zip(self.nodes, self._mergers):
            node.counters["dropped_at_stop"] += len(merger.drain())
        for node in self.nodes:
            node.close()
            node.diagnostics.publish(node.diagnostic())     # as a live service does when it stops
