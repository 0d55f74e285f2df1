"""Sporadic inputs held back until a margin of sim time after their stamp.

A service that takes a sporadic input (a map, a goal, a plan, a scan for a gate) into effect at
the first tick stamped after stamp + delay gives the same outputs whether the input reached it
before or after the ticks stamped in (stamp, stamp + delay]: live runs then replay byte for byte
(docs/architecture.md, time rules). Held inputs come out in the order replay feeds them — by
stamp, then by the kind the node gives them (its input order), then by sequence number —
whatever order they arrived in.
"""
from __future__ import annotations

import bisect
from typing import Any, Iterator

from .node import NS_PER_S


class Deferred:
    def __init__(self, delay_s: float):
        self.delay_s = delay_s
        self.delay_ns = round(delay_s * NS_PER_S)
        self._held: list[tuple[int, int, int, Any]] = []    # (stamp, kind, seq, message)

    def hold(self, msg: Any, kind: int = 0) -> None:
        bisect.insort(self._held, (msg.header.stamp_ns, kind, msg.header.seq, msg), key=lambda item: item[:3])

    def due(self, now_ns: int) -> Iterator[tuple[int, Any]]:
        """(kind, message) of the inputs stamped before now − delay, in order, each once."""
        while self._held and self._held[0][0] + self.delay_ns < now_ns:
            _, kind, _, msg = self._held.pop(0)
            yield kind, msg

    def latest(self, kind: int = 0) -> Any | None:
        """The held message of this kind stamped last, or None."""
        return next((msg for _, held_kind, _, msg in reversed(self._held) if held_kind == kind), None)

    def __len__(self) -> int:
        return len(self._held)
