"""The Node base: what a service declares and how its inputs are processed, independent of transport.

A service subclasses Node, declares its inputs, outputs, queryables and sim-time timers in setup(),
and writes handlers that call its pure core. Drivers feed it: live.py from Zenoh, replay from a
recording. Both go through process(), so a replayed service runs exactly the live code.
"""
from __future__ import annotations

import dataclasses
import json
import logging
from collections import Counter
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Callable, ClassVar

from ...schemas import MessageError
from ...schemas.codec import encode
from ...schemas.keys import DEFAULT_ROBOT, KeyLayout, type_for_key
from ...schemas.messages import Clock, Diagnostic, Header
from ...schemas.registry import type_info
from ...parameters.declare import Parameters

if TYPE_CHECKING:
    from .deferred import Deferred

CLOCK_TOPIC = "sim/clock"
NS_PER_S = 1_000_000_000
PARAMS_VALUE = "params"     # Diagnostic value: the service's parameters, as JSON (params_json)


@dataclass(frozen=True)
class NoParams(Parameters):
    """For services without parameters."""


def params_json(params: Any) -> str:
    """A parameter dataclass as JSON, every field its constructor takes (the Params class loads it
    back: lists become tuples again by the type hints); "" when JSON cannot carry a value."""
    if not dataclasses.is_dataclass(params):
        return ""
    values = {f.name: getattr(params, f.name) for f in dataclasses.fields(params) if f.init}
    try:
        return json.dumps(values, sort_keys=True, allow_nan=False)
    except (TypeError, ValueError):
        return ""


@dataclass
class Input:
    key: str
    msg_type: type
    handler: Callable[[Any], None]
    synced: bool          # others wait for this stream to pass a stamp (see merge.py)
    # a sporadic input whose effect the node defers by this much sim time may arrive that late
    # (after inputs stamped up to stamp + max_delay_ns) without changing the outputs
    max_delay_ns: int = 0
    received: str = dataclasses.field(init=False)      # its counter's name, made once

    def __post_init__(self) -> None:
        self.received = f"received/{self.key}"


class Publisher:
    """Stamps the per-key sequence number, encodes and hands the payload to the driver's sink."""

    def __init__(self, key: str, msg_type: type):
        self.key, self.msg_type = key, msg_type
        self.type_name = type_info(msg_type)[0]
        self.seq = 0
        self.sink: Callable[[Publisher, bytes, int], None] | None = None

    def publish(self, msg: Any) -> None:
        if type(msg) is not self.msg_type:
            raise TypeError(f"{self.key} carries {self.type_name}, not {type(msg).__name__}")
        self.seq += 1
        msg.header.seq = self.seq
        if self.sink is not None:
            self.sink(self, encode(msg), msg.header.stamp_ns)


@dataclass
class _Timer:
    period_ns: int
    handler: Callable[[], None]
    next_ns: int | None = None


class Ticks:
    """A rate on a synced input's stamps rather than on the clock: a tick at each multiple of the
    period, falling on the first stamp at or after it (stamps in between are not ticks)."""

    def __init__(self, frequency_hz: float):
        self.period_ns = round(NS_PER_S / frequency_hz)
        self.next_ns: int | None = None

    def due(self, stamp_ns: int) -> bool:
        """Whether the message stamped stamp_ns is a tick (stamps come in order)."""
        if self.next_ns is None:
            self.next_ns = -(-stamp_ns // self.period_ns) * self.period_ns    # the first multiple ≥ the stamp
        if stamp_ns < self.next_ns:
            return False
        self.next_ns = (stamp_ns // self.period_ns + 1) * self.period_ns
        return True


class QueryError(Exception):
    """A query that cannot be answered; the text goes back to the caller."""


class Node:
    service: ClassVar[str] = ""
    Params: ClassVar[type] = NoParams
    # parameters naming files the service keeps its state in to resume after a restart
    # (services/runtime/state_file.py); a replay runs without them
    state_files: ClassVar[tuple[str, ...]] = ()
    # the source whose ticks the others follow in a lockstep run (lockstep.py): the simulator
    coordinates_lockstep: ClassVar[bool] = False
    # wall s `up` waits after SIGINT before SIGKILL: what finishes files may need longer on a loaded machine
    stop_timeout_s: ClassVar[float] = 10.0

    def __init__(self, params: Any = None, robot: str = DEFAULT_ROBOT, name: str | None = None):
        self.params = params if params is not None else self.Params()
        self.name = name or self.service
        self.keys = KeyLayout(robot)
        self.log = logging.getLogger(f"omninav.{self.name}")
        self.inputs: list[Input] = []
        self.outputs: dict[str, Publisher] = {}
        self.queryables: dict[str, Callable[[dict[str, str]], Any]] = {}
        self.counters: Counter[str] = Counter()
        self.first_seq: dict[str, int] = {}
        self.now_ns = 0
        # every parameter's value, defaults included, in every Diagnostic: a replay of the recording
        # builds the same node without the compose file, even after a default changed in the code
        self.params_record = params_json(self.params)
        self._timers: list[_Timer] = []
        self._logged_bad_keys: set[str] = set()
        self._logged_failures: set[tuple[str, str]] = set()
        # not in self.outputs: diagnostics count wall-time events, so replay does not compare them
        self.diagnostics = Publisher(self.keys.diagnostics(self.name), Diagnostic)
        self.setup()
        if self._timers:
            # the clock goes first so a timer at t fires before inputs stamped t, after those before t
            self.inputs.insert(0, Input(self.keys.resolve(CLOCK_TOPIC), Clock, self._on_clock, True))

    # ------------------------------------------------------------ declarations (in setup)

    def setup(self) -> None:
        """Declare inputs, outputs, queryables and timers."""

    def subscribe(self, topic: str, handler: Callable[[Any], None], *, synced: bool = True,
                  max_delay_s: float = 0.0) -> None:
        key = self.keys.resolve(topic)
        if any(i.key == key for i in self.inputs):
            raise ValueError(f"{self.name}: {key} subscribed twice")
        if max_delay_s < 0:
            raise ValueError(f"{self.name}: max_delay_s must not be negative, got {max_delay_s}")
        self.inputs.append(Input(key, type_for_key(key), handler, synced, round(max_delay_s * NS_PER_S)))

    def subscribe_deferred(self, topic: str, pending: Deferred, kind: int = 0,
                           check: Callable[[Any], str] | None = None) -> None:
        """A sporadic input whose messages wait in `pending` until they are due (deferred.py), as
        `kind`; one that `check` finds a problem with (its reason, or '') is rejected instead."""
        key = self.keys.resolve(topic)

        def receive(msg: Any) -> None:
            problem = check(msg) if check is not None else ""
            if problem:
                self.reject(key, MessageError(problem, type_name=type(msg).__name__, key=key))
            else:
                pending.hold(msg, kind)

        self.subscribe(topic, receive, synced=False, max_delay_s=pending.delay_s)

    def publisher(self, topic: str) -> Publisher:
        key = self.keys.resolve(topic)
        if key not in self.outputs:
            self.outputs[key] = Publisher(key, type_for_key(key))
        return self.outputs[key]

    def queryable(self, topic: str, handler: Callable[[dict[str, str]], Any]) -> None:
        self.queryables[self.keys.resolve(topic)] = handler

    def subscriptions(self) -> list[str]:
        """The key expressions this node subscribes to on the bus (its access rights: acl.py)."""
        return [i.key for i in self.inputs]

    def every(self, period_s: float, handler: Callable[[], None]) -> None:
        """Call handler every period_s of sim time (driven by the clock key)."""
        if period_s <= 0:
            raise ValueError(f"{self.name}: timer period must be positive, got {period_s}")
        self._timers.append(_Timer(round(period_s * NS_PER_S), handler))

    # ------------------------------------------------------------ driving (by live.py / replay)

    def process(self, index: int, msg: Any) -> None:
        """Handle one decoded input; drivers call this in merge order."""
        inp = self.inputs[index]
        self.now_ns = max(self.now_ns, msg.header.stamp_ns)
        self.first_seq.setdefault(inp.key, msg.header.seq)
        self.counters[inp.received] += 1
        try:
            inp.handler(msg)
        except Exception as exc:    # the guard: one bad message must not end the service
            self.handler_failed(inp.key, exc)

    def handler_failed(self, key: str, exc: Exception) -> None:
        """A handler raised: counted per key, logged with its traceback once per key and exception
        type; the message is dropped and the node carries on with the next input (so does replay,
        which runs this same code)."""
        self.counters[f"handler_errors/{key}"] += 1
        kind = (key, type(exc).__name__)
        if kind not in self._logged_failures:
            self._logged_failures.add(kind)
            self.log.error("handling a message on %s failed; dropped it and carrying on (further %s on this "
                           "key only counted)", key, kind[1], exc_info=exc)

    def answer(self, key: str, parameters: dict[str, str]) -> Any:
        """The reply to a `get` on one of this node's queryables (raises QueryError)."""
        try:
            return self.queryables[key](parameters)
        except QueryError:
            raise
        except (KeyError, ValueError, TypeError) as exc:
            raise QueryError(f"{key}: bad query parameters {parameters}: {exc}") from None

    def reject(self, key: str, error: MessageError) -> None:
        """A malformed input: logged once per key, counted, and otherwise ignored."""
        self.counters[f"malformed/{key}"] += 1
        if key not in self._logged_bad_keys:
            self._logged_bad_keys.add(key)
            self.log.warning("malformed message ignored (further ones on this key only counted): %s", error)

    def header(self, frame_id: str = "", stamp_ns: int | None = None) -> Header:
        """A header stamped with the current sim time (the stamp of the input being handled)."""
        return Header(stamp_ns=self.now_ns if stamp_ns is None else stamp_ns, frame_id=frame_id)

    def diagnostic(self) -> Diagnostic:
        values: dict[str, float | int | str] = dict(self.counters)
        values.update({f"first_seq/{k}": v for k, v in self.first_seq.items()})
        if self.params_record:
            values[PARAMS_VALUE] = self.params_record
        trouble = sorted(k for k in self.counters if k.startswith(("malformed/", "late/", "sync_timeout", "handler_errors/")))
        return Diagnostic(
            header=self.header(),
            name=self.name,
            level=1 if trouble else 0,
            message=("not exactly replayable or saw bad input: " + ", ".join(trouble)) if trouble else "ok",
            values=values,
        )

    def close(self) -> None:
        """Called once after the last input; finish files and the like."""

    def pace_s(self) -> float | None:
        """Wall-clock period of tick() for sources (the sim); None for services driven by inputs."""
        return None

    def tick(self) -> None:
        """One step of a source; only called when pace_s() is not None."""

    def holds_lockstep(self) -> bool:
        """True once this node wants the simulator to step no further in a lockstep run (a mission
        that is over), so every run of the same command ends at the same step."""
        return False

    # ------------------------------------------------------------ internals

    def _on_clock(self, clock: Clock) -> None:
        now = clock.header.stamp_ns
        for timer in self._timers:
            if timer.next_ns is None:
                timer.next_ns = now
            if timer.next_ns <= now:
                timer.handler()
                missed = (now - timer.next_ns) // timer.period_ns
                timer.next_ns += (missed + 1) * timer.period_ns
