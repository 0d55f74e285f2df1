"""`omninav replay FILE [--rate R] [--loop] [--keys K…] [--start-offset S] [--clock]`: a recording back onto the bus.

Like `ros2 bag play`: every recorded payload goes out on its key, in recorded order, with the
attachment its publisher sent (seq, stamp, type), paced by log_time (the time it was recorded)
divided by --rate. Publishers use congestion control BLOCK, so a slow subscriber slows the replay
down instead of losing messages.
"""
from __future__ import annotations

import argparse
import contextlib
import logging
import threading
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import zenoh
from mcap.exceptions import McapError

from ...schemas.attachment import pack_attachment
from ...schemas.codec import encode
from ...schemas.keys import KeyLayout
from ...schemas.messages import Clock, Header
from ...schemas.registry import type_info
from ..recorder.mcap_io import Record, read_records, recording_summary
from ..runtime.node import NS_PER_S
from ..runtime.run import configure_logging
from ..runtime.acl import publishers_of
from ..runtime.zenoh_config import open_client, router_endpoint
from ..runtime.stop_signals import stop_event

log = logging.getLogger("omninav.replay")

CLOCK_PERIOD_NS = NS_PER_S // 100     # --clock: at most one Clock per 10 ms of sim time, like the talker


class ReplayError(Exception):
    """A user error: bad file, bad option; the text says which."""


@dataclass(frozen=True)
class LivePlan:
    """What to replay, decided from the options and the recording's summary."""
    keys: frozenset[str]          # recorded keys that pass --keys
    start_ns: int                 # log time that maps to the replay's start (first message + offset)
    clock: bool                   # publish Clock from stamps


def make_plan(args: argparse.Namespace, summary) -> LivePlan:
    recorded = {ch.topic for ch in summary.channels.values()}
    if args.keys:
        try:
            filters = [zenoh.KeyExpr(k) for k in args.keys]
        except zenoh.ZError as exc:
            raise ReplayError(f"--keys: {str(exc).split(' at ')[0]}") from None
        keys = {k for k in recorded if any(f.intersects(zenoh.KeyExpr(k)) for f in filters)}
        if not keys:
            raise ReplayError(f"--keys {' '.join(args.keys)} match none of the recorded keys: {', '.join(sorted(recorded))}")
    else:
        keys = recorded
    clock = args.clock
    clock_key = KeyLayout.sim("clock")
    if clock and clock_key in keys:
        log.info("the recording has its own clock on %s: replaying it, --clock adds none", clock_key)
        clock = False
    stats = summary.statistics
    start_ns = stats.message_start_time + round(args.start_offset * NS_PER_S)
    if stats.message_count == 0 or start_ns > stats.message_end_time:
        length = (stats.message_end_time - stats.message_start_time) / NS_PER_S if stats.message_count else 0.0
        raise ReplayError(f"nothing to replay: the recording has {stats.message_count} messages over {length:.1f} s"
                          f" and --start-offset is {args.start_offset} s")
    return LivePlan(frozenset(keys), start_ns, clock)


class LivePlayer:
    """Publishes Records at their recorded pace; stop_event stops it between two messages."""

    def __init__(self, session_for: Callable[[str], zenoh.Session], plan: LivePlan, rate: float,
                 stop_event: threading.Event):
        """session_for(key): the session that puts key (under an ACL, that of the key's publisher)."""
        self.session_for, self.plan, self.rate, self.stop_event = session_for, plan, rate, stop_event
        self._publishers: dict[str, zenoh.Publisher] = {}
        self.published = 0
        self._clock_key = KeyLayout.sim("clock")
        self._clock_type = type_info(Clock)[0]
        self._clock_seq = 0
        self._clock_ns = -1

    def _publisher(self, key: str) -> zenoh.Publisher:
        pub = self._publishers.get(key)
        if pub is None:
            pub = self._publishers[key] = self.session_for(key).declare_publisher(
                key, congestion_control=zenoh.CongestionControl.BLOCK, reliability=zenoh.Reliability.RELIABLE)
        return pub

    def _tick_clock(self, stamp_ns: int) -> None:
        if stamp_ns >= self._clock_ns + CLOCK_PERIOD_NS:
            self._clock_seq += 1
            self._clock_ns = stamp_ns
            msg = Clock(header=Header(stamp_ns=stamp_ns, seq=self._clock_seq), rate=self.rate)
            self._publisher(self._clock_key).put(
                encode(msg), attachment=pack_attachment(self._clock_seq, stamp_ns, self._clock_type))

    def play(self, records) -> bool:
        """One pass over the records; False if stopped before the end or if nothing was due."""
        before = self.published
        wall_start = time.monotonic()
        self._clock_ns = -1     # a new pass starts the clock over
        for rec in records:
            if rec.log_time_ns < self.plan.start_ns or rec.key not in self.plan.keys:
                continue
            delay = wall_start + (rec.log_time_ns - self.plan.start_ns) / NS_PER_S / self.rate - time.monotonic()
            if (delay > 0 and self.stop_event.wait(delay)) or self.stop_event.is_set():
                return False
            self._send(rec)
        return self.published > before

    def _send(self, rec: Record) -> None:
        if self.plan.clock:
            self._tick_clock(rec.stamp_ns)
        self._publisher(rec.key).put(rec.payload, attachment=pack_attachment(rec.seq, rec.stamp_ns, rec.type_name))
        self.published += 1

    def close(self) -> None:
        for pub in self._publishers.values():
            pub.undeclare()


def _sessions(router: str, files: dict[str, Path] | None, stack: contextlib.ExitStack):
    """One session, or given each key's identity (publishers_of) one session per identity: each key
    goes out as the service that published it, which the router's ACL allows."""
    if files is None:
        session = stack.enter_context(open_client(router))
        return lambda _key: session
    by_file = {file: stack.enter_context(open_client(router, str(file))) for file in set(files.values())}
    return lambda key: by_file[files[key]]


def main_live(args: argparse.Namespace) -> int:
    configure_logging("replay")
    try:
        if not args.rate > 0:
            raise ReplayError(f"--rate must be positive, got {args.rate}")
        if args.start_offset < 0:
            raise ReplayError(f"--start-offset must be >= 0, got {args.start_offset}")
        router = router_endpoint(args.router)
        what = make_plan(args, recording_summary(args.file))
        files = None
        if args.credentials is not None:    # every key's publisher, before anything is sent
            files = publishers_of(Path(args.credentials),
                                  set(what.keys) | ({KeyLayout.sim("clock")} if what.clock else set()))
    except (ReplayError, FileNotFoundError, McapError, ValueError) as exc:
        log.error("%s", exc)
        return 2
    stop = stop_event()
    passes = 0
    started = time.monotonic()
    with contextlib.ExitStack() as sessions:
        session_for = _sessions(router, files, sessions)
        player = LivePlayer(session_for, what, args.rate, stop)
        try:
            while player.play(read_records(args.file)):
                passes += 1
                if not args.loop:
                    break
        except McapError as exc:
            log.error("%s: damaged after %d messages: %s", args.file, player.published, exc)
            return 2
        finally:
            player.close()
    print(f"replayed {player.published} messages on {len(what.keys)} keys in {time.monotonic() - started:.1f} s"
          f" ({passes} full pass{'' if passes == 1 else 'es'}){'; stopped' if stop.is_set() else ''}", flush=True)
    return 0
