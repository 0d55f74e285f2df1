"""Stamp-ordered merging of several input streams — the rule that makes replay exact.

Inputs are processed in the order (stamp, stream index, arrival). An item is released only when no
stream that others wait on ("synced") can still deliver something that sorts before it: every
synced stream with a lower index has passed its stamp, every one with a higher index has reached
it. Sporadic streams (goals, initial poses) wait for the synced streams but nobody waits for them.
Replay sorts the same way, so arrival order between keys cannot change a result.
"""
from __future__ import annotations

import heapq
import itertools
from dataclasses import dataclass, field
from typing import Any


def order_key(stamp_ns: int, stream: int, seq: int) -> tuple[int, int, int]:
    """The processing order of an input, shared by live merging and deterministic replay."""
    return (stamp_ns, stream, seq)


@dataclass
class StampMerger:
    synced: list[bool]
    _heap: list = field(default_factory=list)
    _latest: list[int | None] = field(init=False)
    _waited_on: list[int] = field(init=False)       # the synced streams
    _arrival: itertools.count = field(default_factory=itertools.count)
    released_upto: int | None = None   # stamp of the last released item

    def __post_init__(self):
        self._latest = [None] * len(self.synced)
        self._waited_on = [i for i, synced in enumerate(self.synced) if synced]

    def push(self, stream: int, stamp_ns: int, item: Any, enqueued_at: float = 0.0) -> bool:
        """Buffer an item; False if it arrived too late to keep stamp order (it is still buffered)."""
        late = self.released_upto is not None and stamp_ns < self.released_upto
        last = self._latest[stream]
        self._latest[stream] = stamp_ns if last is None else max(last, stamp_ns)
        heapq.heappush(self._heap, (stamp_ns, stream, next(self._arrival), enqueued_at, item))
        return not late

    def _ready(self, stamp_ns: int, stream: int) -> bool:
        latest = self._latest
        for other in self._waited_on:
            last = latest[other]
            if other != stream and (last is None or last < stamp_ns or (last == stamp_ns and other < stream)):
                return False
        return True

    def pop_ready(self) -> list[Any]:
        out = []
        while self._heap and self._ready(self._heap[0][0], self._heap[0][1]):
            out.append(self._release())
        return out

    def pop_oldest(self) -> Any:
        """Release the head regardless of readiness (a wait bound was hit)."""
        return self._release()

    def _release(self) -> Any:
        stamp, _, _, _, item = heapq.heappop(self._heap)
        self.released_upto = stamp if self.released_upto is None else max(self.released_upto, stamp)
        return item

    def head_enqueued_at(self) -> float | None:
        """When the item next in line was buffered (for the wait bound), or None if empty."""
        return self._heap[0][3] if self._heap else None

    def drain(self) -> list[Any]:
        out = []
        while self._heap:
            out.append(self._release())
        return out

    def __len__(self) -> int:
        return len(self._heap)
