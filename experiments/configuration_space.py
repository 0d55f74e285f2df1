"""Can a footprint — not just its inscribed disk — get from a start pose to a goal pose on a
grid, turning where it must? And how long is the shortest way it can take?

experiments/reachability.py answers for a disk of the footprint's inscribed radius: necessary, not
sufficient for a long robot that must turn through a door beside a corner. Here the robot's
configuration space (x, y, heading) is built on the grid's cells at HEADINGS headings: a pose is
free when no blocked cell's centre lies inside the footprint grown by `margin_m` (plus half a cell,
as reachability's poses); neighbouring free poses join — a cell's step at the same heading, or a
turn in place to the next heading. The goal is reachable when its pose lies in the start's region.
A holonomic robot can drive every such way; a differential one can too wherever it has room to
turn towards the way it goes, which doors 10 cm wider than the robot give it (docs/buildings.md).

The shortest way is measured on the cells some pose of the start's region covers (the robot can
stand there at some heading), pulled taut: a lower bound for the robot, which also turns.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import ndimage, signal, sparse
from scipy.sparse import csgraph

from ..geometry.footprint import pad
from ..geometry.grid import cell_to_world, in_grid, world_to_cell
from ..geometry.polygons import points_in_polygons, transform_points
from ..schemas.messages import MapMetaData
from ..services.global_planner.astar import GlobalPlanner
from .reachability import LETHAL, PATH_SEARCH

HEADINGS = 72               # 5° apart: a turn between two sweeps a 0.53 m corner 2.3 cm off either


@dataclass(frozen=True)
class Reach:
    reachable: bool
    shortest_m: float | None        # the taut way through the start's region, None if unreachable
    region_cells: int               # cells some pose of the start's region covers
    way: np.ndarray | None = None   # (N, 2) x, y of that way's corners, start to goal


def _kernel(footprint: np.ndarray, yaw: float, grown_m: float, resolution: float) -> np.ndarray:
    """(2k+1, 2k+1) bool: the cells (rows = y, cols = x) the grown footprint at yaw covers when
    the robot stands on the centre cell."""
    polygon = transform_points(pad(footprint, grown_m), np.array([[0.0, 0.0, yaw]]))[0]
    k = int(math.ceil(np.hypot(*polygon.T).max() / resolution)) + 1
    offsets = np.arange(-k, k + 1) * resolution
    ys, xs = np.meshgrid(offsets, offsets, indexing="ij")
    inside = points_in_polygons(np.column_stack([xs.ravel(), ys.ravel()]), polygon[None])[:, 0]
    return inside.reshape(xs.shape)


def free_poses(blocked: np.ndarray, footprint: np.ndarray, margin_m: float, resolution: float) -> np.ndarray:
    """(HEADINGS, H, W) bool: where the footprint, grown by margin_m, stands on no blocked cell."""
    grown = margin_m + resolution / 2
    occupied = blocked.astype(np.float32)
    free = np.empty((HEADINGS, *blocked.shape), bool)
    for h in range(HEADINGS):
        kernel = _kernel(footprint, 2 * math.pi * h / HEADINGS, grown, resolution)
        # the pose on cell p is blocked when a blocked cell lies at p + offset for an offset the kernel holds
        overlap = signal.fftconvolve(occupied, kernel[::-1, ::-1].astype(np.float32), mode="same")
        free[h] = overlap < 0.5
    return free


def _regions(free: np.ndarray) -> np.ndarray:
    """Labels (HEADINGS, H, W) of the joined free poses, 0 where blocked; heading 0 joins the last
    heading too (the labelling alone does not wrap round)."""
    labels, count = ndimage.label(free, structure=ndimage.generate_binary_structure(3, 1))
    wrap = free[0] & free[-1]
    joined = sparse.coo_matrix((np.ones(int(wrap.sum())), (labels[0][wrap], labels[-1][wrap])),
                               shape=(count + 1, count + 1))
    _, region = csgraph.connected_components(joined, directed=False)
    return np.where(labels > 0, region[labels] + 1, 0)


def _heading(yaw: float) -> int:
    return int(round(yaw / (2 * math.pi / HEADINGS))) % HEADINGS


def _taut_corners(cells: np.ndarray, room: np.ndarray) -> np.ndarray:
    """The corners (M, 2) of the cell path (N, 2) of (row, col) pulled taut inside `room`: from
    each point, straight to the farthest later point it sees."""
    def sees(a, b) -> bool:
        n = int(np.hypot(*(b - a)) * 2) + 2
        points = np.rint(a + np.linspace(0.0, 1.0, n)[:, None] * (b - a)).astype(int)
        return bool(room[points[:, 0], points[:, 1]].all())

    corners, i = [0], 0
    while i < len(cells) - 1:
        j = len(cells) - 1
        while j > i + 1 and not sees(cells[i], cells[j]):
            j -= 1
        corners.append(j)
        i = j
    return cells[corners]


def reach(blocked: np.ndarray, info: MapMetaData, footprint: np.ndarray, start, goal, margin_m: float) -> Reach:
    """Whether the footprint grown by margin_m can go from start (x, y, yaw) to goal on the grid
    `blocked` (rows = y; `info` places it), and the taut length of the shortest way."""
    free = free_poses(blocked, np.asarray(footprint, np.float64), margin_m, info.resolution)
    labels = _regions(free)

    def pose_label(pose) -> int:
        row, col = (int(v) for v in world_to_cell(info, pose[0], pose[1]))
        return int(labels[_heading(pose[2]), row, col]) if in_grid(info, row, col) else 0

    start_label, goal_label = pose_label(start), pose_label(goal)
    room = (labels == start_label).any(axis=0) if start_label else np.zeros(blocked.shape, bool)
    if not start_label or goal_label != start_label:
        return Reach(False, None, int(room.sum()))
    plan = GlobalPlanner(PATH_SEARCH).plan(np.where(room, 0, LETHAL).astype(np.uint8), info, start, goal)
    corners = _taut_corners(np.asarray(plan.cells), room)
    length = float(np.hypot(*np.diff(corners, axis=0).T).sum()) * info.resolution
    way = np.column_stack(cell_to_world(info, corners[:, 0], corners[:, 1]))
    return Reach(True, length, int(room.sum()), way)
