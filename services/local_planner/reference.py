"""The DWA rollout, footprint check and path distances written the slow, obvious way (a Python loop
per trajectory, every outline point looked up, Dijkstra with a heap), the oracle tests/test_dwa.py
and `omninav bench local` hold the batched kernels in dwa.py and footprint_check.py to."""
from __future__ import annotations

import heapq
import math

import numpy as np

from ...schemas.messages import MapMetaData
from ..costmap import layers as costmap_layers
from ...geometry.footprint import transform
from ...geometry.grid import in_grid, world_to_cell
from ...geometry.se2 import integrate
from .dwa import DwaPlanner
from .footprint_check import FootprintCheck, PoseCheck

def reference_pose_cost(footprint_check: FootprintCheck, check: PoseCheck, pose, costs: np.ndarray,
                        info: MapMetaData) -> int:
    """The centre cost of the robot at pose, or -1 where illegal, the slow, obvious way: every point of
    the outline looked at."""
    def cost_at(points):
        rows, cols = world_to_cell(info, points[:, 0], points[:, 1])
        inside = in_grid(info, rows, cols)
        return np.where(inside, costs[np.where(inside, rows, 0), np.where(inside, cols, 0)].astype(int), -1)

    centre = int(cost_at(np.asarray(pose, float)[None, :2])[0])
    if centre < 0 or centre >= check.centre_limit:
        return -1
    row, col = world_to_cell(info, pose[0], pose[1])
    if centre >= footprint_check.check_cost or check.near[int(row), int(col)]:
        edge = cost_at(transform(check.outline, pose))
        if np.any((edge < 0) | (edge >= costmap_layers.LETHAL_OBSTACLE)):
            return -1
    return centre


def reference_rollout(planner: DwaPlanner, twist, n: int, pose, velocity, costs: np.ndarray, info: MapMetaData):
    """One trajectory of n steps the slow, obvious way: (poses up to where it stopped, highest cost, legal)."""
    p = planner.params
    samples = np.asarray(twist, float)[None]
    dt = p.sim_time / n
    check = planner.footprint_check.setup(pose, costs, info)
    current = np.asarray(velocity, float) if not p.dwa else samples[0]
    step_limit = np.array([p.acc_lim_x, p.acc_lim_y, p.acc_lim_theta]) * dt
    poses, worst = [np.asarray(pose, float)], 0
    for _ in range(n):
        if not p.dwa:
            current = current + np.clip(samples[0] - current, -step_limit, step_limit)
        poses.append(integrate(poses[-1], current, dt))
        cost = reference_pose_cost(planner.footprint_check, check, poses[-1], costs, info)
        if cost < 0:
            return np.array(poses), worst, False
        worst = max(worst, cost)
    return np.array(poses), worst, True


def reference_path_distance(on_path: np.ndarray, passable: np.ndarray, resolution: float) -> np.ndarray:
    """Metres from the nearest on_path cell through passable cells, the obvious way: Dijkstra with a
    heap over the 16 moves of a cell (a knight's move only between two passable cells); inf where
    not reached."""
    moves = [(dr, dc) for dr in range(-2, 3) for dc in range(-2, 3)
             if (dr, dc) != (0, 0) and math.gcd(abs(dr), abs(dc)) == 1]
    height, width = passable.shape
    distance = np.full(passable.shape, np.inf)
    heap = [(0.0, int(r), int(c)) for r, c in zip(*np.nonzero(on_path))]
    for _, r, c in heap:
        distance[r, c] = 0.0
    while heap:
        d, r, c = heapq.heappop(heap)
        if d > distance[r, c]:
            continue
        for dr, dc in moves:
            row, col = r + dr, c + dc
            if not (0 <= row < height and 0 <= col < width and passable[row, col]):
                continue
            if abs(dr) == 2 and not (passable[r + dr // 2, c] and passable[r + dr // 2, col]):
                continue
            if abs(dc) == 2 and not (passable[r, c + dc // 2] and passable[row, c + dc // 2]):
                continue
            if d + math.hypot(dr, dc) < distance[row, col]:
                distance[row, col] = d + math.hypot(dr, dc)
                heapq.heappush(heap, (distance[row, col], row, col))
    return distance * resolution
