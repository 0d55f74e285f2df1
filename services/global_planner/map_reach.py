"""Whether a goal can be reached on the map itself: the quick answer for a plan that failed.

A plan fails on the global costmap for one of two kinds of reason: obstacles the sensors marked (a
person in a door, a cart, a stale mark), which clearing the costmaps or waiting may remove, or the
map itself (a goal inside a wall, in a room without a door, outside the building), which no
recovery changes. After a failed plan the planner asks the map (`MapReach.why_unreachable`): its
free cells (below OCCUPIED, unknown ones too when the planner may plan through unknown space)
joined 8-connected into regions; a goal that lies in no free cell within default_tolerance, or in
no region the start's cell is in, cannot be reached, and the navigator aborts at once with the
reason instead of running its recoveries first. The robot's size is not looked at: a goal behind a
door narrower than the robot passes here and is left to the recoveries (the costmap's inflation
says so, not the map).

Pure: numpy and scipy.ndimage; poses in the map's frame.
"""
from __future__ import annotations

import numpy as np
from scipy import ndimage

from ...schemas.messages import OccupancyGrid
from ...geometry.grid import in_grid, world_to_cell

OCCUPIED = 65           # % occupancy from which a map cell is a wall (map_server's occupied_thresh 0.65)
EIGHT_CONNECTED = np.ones((3, 3), bool)


class MapReach:
    def __init__(self, grid: OccupancyGrid, allow_unknown: bool):
        self.info = grid.info
        self.allow_unknown = allow_unknown
        data = np.asarray(grid.data).reshape(grid.info.height, grid.info.width)
        free = (data >= 0) & (data < OCCUPIED)
        if allow_unknown:
            free |= data < 0
        self.regions, _ = ndimage.label(free, structure=EIGHT_CONNECTED)

    def why_unreachable(self, start, goal, tolerance: float = 0.0) -> str:
        """Why no way on the map's free cells joins start to goal (x, y[, yaw]); "" when one may."""
        start_region = self._region(start)
        if start_region is None:
            return ""   # the robot stands off the map or on a wall cell: the map cannot judge
        where = f"the goal ({goal[0]:.2f}, {goal[1]:.2f})"
        if self.allow_unknown and not in_grid(self.info, *world_to_cell(self.info, goal[0], goal[1])):
            return ""   # beyond the map lies unknown space, which the planner may cross
        regions = self._regions_near(goal, tolerance)
        if not len(regions):
            near = f" or within default_tolerance {tolerance:g} m of it" if tolerance > 0 else ""
            return f"{where} lies on no free cell of the map{near}"
        if start_region not in regions:
            return (f"{where} lies in a part of the map no way through free cells joins to the robot's "
                    f"({start[0]:.2f}, {start[1]:.2f})")
        return ""

    def _region(self, pose) -> int | None:
        row, col = (int(v) for v in world_to_cell(self.info, pose[0], pose[1]))
        if not in_grid(self.info, row, col) or not self.regions[row, col]:
            return None
        return int(self.regions[row, col])

    def _regions_near(self, pose, tolerance: float) -> np.ndarray:
        """The free regions of the cells within tolerance of pose (its own cell at least)."""
        row, col = (int(v) for v in world_to_cell(self.info, pose[0], pose[1]))
        reach = int(np.ceil(tolerance / self.info.resolution))
        rows = np.arange(row - reach, row + reach + 1)[:, None]
        cols = np.arange(col - reach, col + reach + 1)[None, :]
        near = ((rows - row) ** 2 + (cols - col) ** 2) * self.info.resolution ** 2 <= tolerance ** 2
        inside = in_grid(self.info, rows, cols) & near
        found = self.regions[np.clip(rows, 0, self.info.height - 1), np.clip(cols, 0, self.info.width - 1)][inside]
        return np.unique(found[found > 0])
