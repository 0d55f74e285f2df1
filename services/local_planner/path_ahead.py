"""The part of a path ahead of the robot, shared by the rotation shim and the node's path check."""
from __future__ import annotations

import numpy as np

from ...geometry.polygons import arc_lengths


def ahead_of(path: np.ndarray, pose) -> tuple[np.ndarray, np.ndarray]:
    """(M, 3) the path from its point nearest `pose` on, and (M,) the length along it to each point."""
    nearest = int(np.argmin(np.hypot(path[:, 0] - pose[0], path[:, 1] - pose[1])))
    ahead = path[nearest:]
    return ahead, arc_lengths(ahead)
