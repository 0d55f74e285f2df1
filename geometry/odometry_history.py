"""Recent odometry poses, so a scan stamped between two odometry messages is processed at the pose
the robot had then (the localizer and slam wait for odometry past a scan's stamp, then ask here)."""
from __future__ import annotations

import bisect

import numpy as np

from .se2 import wrap_angle


class OdomHistory:
    """Recent odometry poses, for the pose at any stamp in between (linear, heading wrapped)."""

    def __init__(self, keep_ns: int):
        self.keep_ns = keep_ns
        self.stamps: list[int] = []
        self.poses: list[np.ndarray] = []

    @property
    def latest(self) -> int | None:
        return self.stamps[-1] if self.stamps else None

    def add(self, stamp_ns: int, pose: np.ndarray) -> None:
        self.stamps.append(stamp_ns)
        self.poses.append(pose)
        old = bisect.bisect_left(self.stamps, stamp_ns - self.keep_ns) - 1   # keep one before the window
        if old > 0:
            del self.stamps[:old], self.poses[:old]

    def at(self, stamp_ns: int) -> np.ndarray | None:
        """The odometry pose at stamp_ns, or None outside the history."""
        if not self.stamps or not self.stamps[0] <= stamp_ns <= self.stamps[-1]:
            return None
        i = bisect.bisect_left(self.stamps, stamp_ns)
        if self.stamps[i] == stamp_ns:
            return self.poses[i]
        t0, t1 = self.stamps[i - 1], self.stamps[i]
        a, b = self.poses[i - 1], self.poses[i]
        f = (stamp_ns - t0) / (t1 - t0)
        return np.array([a[0] + f * (b[0] - a[0]), a[1] + f * (b[1] - a[1]),
                         float(wrap_angle(a[2] + f * float(wrap_angle(b[2] - a[2]))))])


class WaitingForOdometry:
    """Inputs (a scan's data) stamped t held until odometry stamped ≥ t has come (rule 2 of the
    determinism rules), then handed out in stamp order with the odometry pose at t (None when t is
    before the history). At most `limit` wait; beyond, the oldest is dropped."""

    def __init__(self, history: OdomHistory, limit: int = 100):
        self.history, self.limit = history, limit
        self.items: list[tuple[int, object]] = []

    @property
    def newest(self) -> int | None:
        return self.items[-1][0] if self.items else None

    def add(self, stamp_ns: int, item) -> bool:
        """Hold an input; False when that dropped the oldest one waiting."""
        self.items.append((stamp_ns, item))
        if len(self.items) > self.limit:
            self.items.pop(0)
            return False
        return True

    def ready(self):
        """(stamp, item, odometry pose at stamp or None) of each input odometry has passed, in order."""
        latest = self.history.latest
        while self.items and latest is not None and self.items[0][0] <= latest:
            stamp, item = self.items.pop(0)
            yield stamp, item, self.history.at(stamp)
