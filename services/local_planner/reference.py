"""The DWA rollout and footprint check written the slow, obvious way (a Python loop per trajectory,
every outline point looked up), the oracle tests/test_dwa.py and `omninav bench local` hold the
batched kernels in dwa.py and footprint_check.py to."""
from __future__ import annotations

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
