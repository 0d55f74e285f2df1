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
