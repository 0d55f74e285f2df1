"""`omninav topics | echo | hz | get`: see what flows on the bus, like `ros2 topic` and `rostopic`.

Rates are measured on wall-clock receipt times (what the bus delivers), not on message stamps.
"""
from __future__ import annotations

import argparse
import json
import queue
import sys
import threading
import time
from collections import Counter, deque
from dataclasses import dataclass
from typing import Callable, Iterator

import numpy as np
import zenoh

from ..schemas import MessageError, decode, peek_type, type_for_key
from ..schemas.attachment import unpack_attachment
from ..schemas.keys import ALL
from ..schemas.readable import to_plain, to_text
from ..services.runtime.selector import join_selector, split_selector
from ..services.runtime.joining import LoginRefused, listening, login_identity, refusal
from ..services.runtime.zenoh_config import open_client, router_endpoint
from ..services.runtime.stop_signals import stop_event

ROUTER_HELP = "router endpoint (default $OMNINAV_ROUTER or tcp/127.0.0.1:7447)"
_NOTICE_S = 2.0      # how long to wait for the router before saying that we are waiting
_TICK_S = 0.1        # how often listening loops look at the clock and the stop flag


class CommandError(Exception):
    """A failure the user should read as one line on stderr, with the exit code to return."""

    def __init__(self, message: str, code: int = 1):
        super().__init__(message)
        self.code = code


def reports_errors(run: Callable[[argparse.Namespace], int]) -> Callable[[argparse.Namespace], int]:
    def wrapped(args: argparse.Namespace) -> int:
        try:
            return run(args)
        except CommandError as exc:
            print(f"omninav {args.command_name}: {exc}", file=sys.stderr, flush=True)
            return exc.code
    return wrapped


# ---------------------------------------------------------------- the bus

def connect(router: str | None, give_up_s: float | None = None) -> zenoh.Session:
    """A client session, logged in as a tool (joining.py: $OMNINAV_CREDENTIALS, else the run's
    entry); says so on stderr when the router is not there yet (clients wait for it)."""
    try:
        endpoint = router_endpoint(router)
    except ValueError as exc:
        raise CommandError(str(exc), 2) from None
    started, told = time.monotonic(), []

    def stopped() -> bool:
        waited = time.monotonic() - started
        if (waited >= _NOTICE_S and not told and (give_up_s is None or give_up_s > _NOTICE_S)
                and not listening(endpoint)):       # a router there that has not let us in yet: not waiting for one
            told.append(True)
            print(f"waiting for the router at {endpoint} (start one with `omninav up` or `omninav router`)",
                  file=sys.stderr, flush=True)
        return give_up_s is not None and waited >= give_up_s

    def warn(text: str) -> None:
        print(text, file=sys.stderr, flush=True)

    try:
        session = open_client(endpoint, stopped=stopped, as_tool=True, warn=warn)
    except LoginRefused as exc:
        raise CommandError(str(exc)) from None
    except Exception as exc:  # zenoh raises its own error types; the user gets the text
        raise CommandError(f"cannot connect to {endpoint}: {exc}") from None
    if session is None:
        if listening(endpoint):     # gave up before the verdict: a router is there, but we are not in
            raise CommandError(str(refusal(endpoint, login_identity(endpoint, as_tool=True))))
        raise CommandError(f"no router listening at {endpoint} (waited {give_up_s:g} s; start one with "
                           f"`omninav up` or `omninav router`)")
    return session


def _reason(exc: zenoh.ZError) -> str:
    """Zenoh's message without the Rust source location it appends."""
    return str(exc).split(" at /")[0]


def key_expression(text: str) -> str:
    """Check a key expression before connecting, so a typo fails at once and not after a wait."""
    try:
        zenoh.KeyExpr(text)
    except zenoh.ZError as exc:
        raise CommandError(f"invalid key expression {text!r}: {_reason(exc)}", 2) from None
    return text


def _stop_on_signals() -> threading.Event:
    """SIGINT/SIGTERM end a listening command normally (it still prints its summary and closes)."""
    return stop_event()


@dataclass(frozen=True)
class Received:
    key: str
    payload: bytes
    attachment: bytes | None
    t: float                    # wall receipt time, time.monotonic()


def _receive(session: zenoh.Session, keyexpr: str, stop: threading.Event,
             duration_s: float | None = None) -> Iterator[Received | None]:
    """Messages on keyexpr as they arrive, and None every tick without one, until stop or duration."""
    inbox: queue.SimpleQueue = queue.SimpleQueue()

    def on_sample(sample: zenoh.Sample) -> None:  # on a Zenoh thread: only copy out and enqueue
        attachment = sample.attachment
        inbox.put(Received(str(sample.key_expr), sample.payload.to_bytes(),
                           None if attachment is None else attachment.to_bytes(), time.monotonic()))

    sub = session.declare_subscriber(keyexpr, on_sample)
    deadline = None if duration_s is None else time.monotonic() + duration_s
    try:
        while not stop.is_set():
            wait = _TICK_S if deadline is None else min(_TICK_S, deadline - time.monotonic())
            if wait <= 0:
                return
            try:
                yield inbox.get(timeout=wait)
            except queue.Empty:
                yield None
    finally:
        sub.undeclare()


def _decode(key: str, payload: bytes):
    """Decode, checking the type the key layout expects when it knows the key (raises MessageError)."""
    return decode(payload, type_for_key(key), key=key)


def _type_name(item: Received) -> str:
    envelope = unpack_attachment(item.attachment)
    if envelope is not None:
        return envelope.type_name
    try:
        return peek_type(item.payload)
    except MessageError:
        return "(malformed)"


def _print_message(key: str, msg, as_json: bool, full: bool) -> None:
    if as_json:
        print(json.dumps({"key": key, "message": to_plain(msg, full=full)}), flush=True)
    else:
        print(f"--- {key} ({type(msg).__name__})\n{to_text(msg, full=full)}", flush=True)


# ---------------------------------------------------------------- rates (pure)

@dataclass(frozen=True)
class RateStats:
    rate_hz: float
    min_s: float
    max_s: float
    std_s: float
    periods: int                # how many periods the figures are over


class RateWindow:
    """Receipt times of one key; statistics over the last `window` periods, as `rostopic hz` does."""

    def __init__(self, window: int | None = None):
        self.times: deque[float] = deque(maxlen=None if window is None else window + 1)
        self.count = 0

    def add(self, t: float) -> None:
        self.times.append(t)
        self.count += 1

    def stats(self) -> RateStats | None:
        if len(self.times) < 2:
            return None
        periods = np.diff(np.fromiter(self.times, float))
        mean = float(periods.mean())
        return RateStats(1.0 / mean if mean > 0 else float("inf"), float(periods.min()),
                         float(periods.max()), float(periods.std()), len(periods))


# ---------------------------------------------------------------- omninav topics

def add_topics_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--duration", type=float, default=2.0, metavar="S", help="listen this long (default 2 s)")
    parser.add_argument("--json", action="store_true", help="print one JSON object")
    parser.add_argument("--router", help=ROUTER_HELP)
    parser.set_defaults(command_name="topics")


@reports_errors
def main_topics(args: argparse.Namespace) -> int:
    session = connect(args.router)
    windows: dict[str, RateWindow] = {}
    types: dict[str, Counter[str]] = {}
    try:
        for item in _receive(session, ALL, _stop_on_signals(), args.duration):
            if item is not None:
                windows.setdefault(item.key, RateWindow()).add(item.t)
                types.setdefault(item.key, Counter())[_type_name(item)] += 1
    finally:
        session.close()
    rows = []
    for key in sorted(windows):
        stats = windows[key].stats()
        rows.append({"key": key, "type": "|".join(sorted(types[key])), "count": windows[key].count,
                     "rate_hz": None if stats is None else round(stats.rate_hz, 3)})
    if args.json:
        print(json.dumps({"duration_s": args.duration, "topics": rows}))
    elif not rows:
        print(f"no messages on {ALL} within {args.duration:g} s")
    else:
        width = max(len(r["key"]) for r in rows)
        print(f"{'KEY':{width}s}  {'TYPE':18s} {'COUNT':>7s} {'RATE (Hz)':>10s}")
        for r in rows:
            rate = "-" if r["rate_hz"] is None else f"{r['rate_hz']:.2f}"
            print(f"{r['key']:{width}s}  {r['type']:18s} {r['count']:7d} {rate:>10s}")
    return 0


# ---------------------------------------------------------------- omninav echo

def add_echo_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("key", help="key or key expression (wildcards * and ** allowed)")
    parser.add_argument("--count", type=int, metavar="N", help="stop after N messages")
    parser.add_argument("--full", action="store_true", help="print whole arrays, not a summary")
    parser.add_argument("--json", action="store_true", help="one JSON object per message")
    parser.add_argument("--router", help=ROUTER_HELP)
    parser.set_defaults(command_name="echo")


@reports_errors
def main_echo(args: argparse.Namespace) -> int:
    if args.count is not None and args.count < 1:
        raise CommandError("--count must be at least 1", 2)
    key = key_expression(args.key)
    session = connect(args.router)
    seen = 0
    try:
        for item in _receive(session, key, _stop_on_signals()):
            if item is None:
                continue
            seen += 1
            try:
                _print_message(item.key, _decode(item.key, item.payload), args.json, args.full)
            except MessageError as exc:  # report this one and keep echoing
                print(f"malformed message: {exc}", file=sys.stderr, flush=True)
            if args.count is not None and seen >= args.count:
                break
    finally:
        session.close()
    return 0


# ---------------------------------------------------------------- omninav hz

def add_hz_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("key", help="key or key expression (each matching key gets its own rate)")
    parser.add_argument("--window", type=int, default=10000, metavar="N",
                        help="statistics over the last N periods (default 10000, as ros2 topic hz)")
    parser.add_argument("--duration", type=float, metavar="S", help="stop after S seconds")
    parser.add_argument("--router", help=ROUTER_HELP)
    parser.set_defaults(command_name="hz")


def format_rate(key: str, stats: RateStats) -> str:
    return (f"{key}: average rate: {stats.rate_hz:.3f}\n"
            f"\tmin: {stats.min_s:.3f}s max: {stats.max_s:.3f}s std dev: {stats.std_s:.5f}s "
            f"window: {stats.periods}")


@reports_errors
def main_hz(args: argparse.Namespace) -> int:
    if args.window < 1:
        raise CommandError("--window must be at least 1", 2)
    key = key_expression(args.key)
    session = connect(args.router)
    windows: dict[str, RateWindow] = {}
    fresh: set[str] = set()
    next_print = time.monotonic() + 1.0

    def report() -> None:
        for key in sorted(fresh):
            stats = windows[key].stats()
            if stats is not None:
                print(format_rate(key, stats), flush=True)
        if not fresh:
            print("no new messages", flush=True)
        fresh.clear()

    try:
        for item in _receive(session, key, _stop_on_signals(), args.duration):
            if item is not None:
                windows.setdefault(item.key, RateWindow(args.window)).add(item.t)
                fresh.add(item.key)
            if time.monotonic() >= next_print:
                report()
                next_print += 1.0
    finally:
        session.close()
    if fresh:
        report()
    if not any(w.stats() for w in windows.values()):
        span = f" within {args.duration:g} s" if args.duration is not None else ""
        raise CommandError(f"not enough messages on {key}{span} to measure a rate")
    return 0


# ---------------------------------------------------------------- omninav get

def add_get_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("selector", help="KEY, KEY;a=1;b=2 or KEY?a=1;b=2 (quote it in the shell)")
    parser.add_argument("--timeout", type=float, default=5.0, metavar="S", help="wait this long (default 5 s)")
    parser.add_argument("--full", action="store_true", help="print whole arrays, not a summary")
    parser.add_argument("--json", action="store_true", help="one JSON object per reply")
    parser.add_argument("--router", help=ROUTER_HELP)
    parser.set_defaults(command_name="get")


@reports_errors
def main_get(args: argparse.Namespace) -> int:
    if args.timeout <= 0:
        raise CommandError("--timeout must be positive", 2)
    key, params = split_selector(args.selector)
    key_expression(key)
    started = time.monotonic()
    session = connect(args.router, give_up_s=args.timeout)
    failed = answered = 0
    try:
        remaining = max(0.1, args.timeout - (time.monotonic() - started))
        for reply in session.get(join_selector(key, params), timeout=remaining):
            answered += 1
            if reply.ok is None:
                text = reply.err.payload.to_bytes().decode(errors="replace")
                print(f"omninav get: error reply: {text}", file=sys.stderr, flush=True)
                failed += 1
                continue
            reply_key = str(reply.ok.key_expr)
            try:
                _print_message(reply_key, _decode(reply_key, reply.ok.payload.to_bytes()), args.json, args.full)
            except MessageError as exc:
                print(f"omninav get: malformed reply: {exc}", file=sys.stderr, flush=True)
                failed += 1
    finally:
        session.close()
    if not answered:
        raise CommandError(f"no reply on {key} within {args.timeout:g} s (is a service answering that key?)")
    return 1 if failed else 0
