"""Cells of an occupancy grid and the world.

`origin` [x, y, yaw] (MapMetaData.origin, ROS map_server's `origin`) is the pose of the outer corner
of cell (row 0, col 0) in the map frame: columns run along the origin's x axis (at angle yaw) and
rows along its y axis. The centre of cell (row, col) is therefore

    origin_xy + R(yaw) · ((col + 0.5)·resolution, (row + 0.5)·resolution)

`cell_to_world` and `world_to_cell` implement this; everyone converts through them. With yaw = π
(the Stata basement map) the grid grows towards −x and −y from the origin.
"""
from __future__ import annotations

import numpy as np

from ..schemas.messages import MapMetaData

GRID_OBSTACLE = 50            # map cells above this occupancy (percent) are obstacles


def grid_coords(info: MapMetaData, x, y) -> tuple[np.ndarray, np.ndarray]:
    """Continuous grid coordinates (u along columns, v along rows, in cells) of world points."""
    c, s = np.cos(info.origin.theta), np.sin(info.origin.theta)
    dx, dy = np.asarray(x, np.float64) - info.origin.x, np.asarray(y, np.float64) - info.origin.y
    return (c * dx + s * dy) / info.resolution, (-s * dx + c * dy) / info.resolution


def world_to_cell(info: MapMetaData, x, y) -> tuple[np.ndarray, np.ndarray]:
    """(row, col) of the cells holding world points; may lie outside the grid (see `in_grid`)."""
    u, v = grid_coords(info, x, y)
    return np.floor(v).astype(np.int64), np.floor(u).astype(np.int64)


def cell_to_world(info: MapMetaData, row, col) -> tuple[np.ndarray, np.ndarray]:
    """World (x, y) of the centres of cells (row, col)."""
    c, s = np.cos(info.origin.theta), np.sin(info.origin.theta)
    lx = (np.asarray(col, np.float64) + 0.5) * info.resolution
    ly = (np.asarray(row, np.float64) + 0.5) * info.resolution
    return info.origin.x + c * lx - s * ly, info.origin.y + s * lx + c * ly


def kernel_costs(costs: np.ndarray) -> np.ndarray:
    """A uint8 cost grid as the numba kernels take it: C-contiguous and read-only (a view: no copy
    where it already is). A grid decoded from a message is read-only, one computed in the process is
    not, and numba compiles a kernel once for each: one variant, one compile (seconds each on the
    cold cache of a fresh checkout)."""
    view = np.ascontiguousarray(costs, np.uint8).view()
    view.flags.writeable = False
    return view


def in_grid(info: MapMetaData, row, col) -> np.ndarray:
    row, col = np.asarray(row), np.asarray(col)
    return (row >= 0) & (row < info.height) & (col >= 0) & (col < info.width)
