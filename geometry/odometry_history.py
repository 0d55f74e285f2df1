"""Recent odometry poses, so a scan stamped between two odometry messages is processed at the pose
the robot had then (the localizer and slam wait for odometry past a scan's stamp, then ask here);
recent commanded twists, for how far the robot has moved since a scan when no odometry that fresh
has arrived (the collision monitor)."""
from __future__ import annotations

import bisect

import numpy as np

from .se2 import integrate, wrap_angle


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


class TwistHistory:
    """Recent commanded twists, each in effect from its stamp until the next one's: the motion they
    carry the robot through between two stamps (dead reckoning, exact for piecewise-constant twists)."""

    def __init__(self, keep_ns: int):
        self.keep_ns = keep_ns
        self.stamps: list[int] = []
        self.twists: list[np.ndarray] = []

    def add(self, stamp_ns: int, twist: np.ndarray) -> None:
        self.stamps.append(stamp_ns)
        self.twists.append(np.asarray(twist, float))
        old = bisect.bisect_right(self.stamps, stamp_ns - self.keep_ns) - 1   # keep the one in effect then
        if old > 0:
            del self.stamps[:old], self.twists[:old]

    def motion(self, since_ns: int, until_ns: int) -> np.ndarray:
        """The robot's pose at until_ns in its own frame at since_ns; no motion before the first
        twist in the history."""
        pose = np.zeros(3)
        first = max(bisect.bisect_right(self.stamps, since_ns) - 1, 0)
        for i in range(first, len(self.stamps)):
            start = max(self.stamps[i], since_ns)
            end = min(self.stamps[i + 1], until_ns) if i + 1 < len(self.stamps) else until_ns
            if end > start:
                pose = integrate(pose, self.twists[i], (end - start) / 1e9)
        return pose
