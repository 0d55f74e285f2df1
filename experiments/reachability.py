"""Can the robot drive from its start to each goal on a map? Asked before a mission starts
(`omninav navigate`) and before a generated world is written (experiments/scenarios), so that an
impossible goal is a one-line error in seconds rather than a mission that recovers until it times out.

Blocked cells are those above `occupied_threshold` and, unless `unknown_is_free`, unknown ones.
- A pose is free when no blocked cell's centre lies inside the footprint there, grown by
  `clearance_m` (plus half a cell, so a cell the footprint's edge cuts counts).
- A goal is reachable when the global planner core (services/global_planner/astar.py) finds a path
  from the start's cell to the goal's through the cells where a disk of the footprint's inscribed
  radius fits. That is necessary for the robot to get there, not sufficient for a long footprint
  in a tight turn — the same test the shipped worlds pass (tests/test_world.py).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..schemas.messages import OccupancyGrid
from ..geometry.distance import distances_to
from ..geometry.footprint import cells_inside, pad, radii, transform
from ..services.global_planner.astar import GlobalPlanner
from ..services.global_planner.params import GlobalPlannerParams
from ..geometry.grid import in_grid, world_to_cell
from ..parameters.declare import Parameters, param

LETHAL = 254
PATH_SEARCH = GlobalPlannerParams(use_dijkstra=False, use_grid_path=True, allow_unknown=False,
                                  default_tolerance=0.0, outline_map=False)


@dataclass(frozen=True)
class ReachabilityParams(Parameters):
    # the footprint grown by this keeps off every blocked cell; a rasterised obstacle may already
    # reach up to a cell beyond the real one, so 0 still keeps the footprint off the obstacle
    clearance_m: float = param(0.0, ge=0)
    occupied_threshold: int = param(50, ge=0, le=100)  # cells above are obstacles (map_server's trinary occupied: 100)
    unknown_is_free: bool = False                      # unknown cells (-1) block, as the static costmap treats them


def blocked_cells(grid: OccupancyGrid, params: ReachabilityParams) -> np.ndarray:
    data = grid.data
    return (data > params.occupied_threshold) | ((data < 0) & (not params.unknown_is_free))


def _describe(what: str, pose) -> str:
    return f"{what} ({pose[0]:.2f}, {pose[1]:.2f})"


def pose_problem(grid: OccupancyGrid, blocked: np.ndarray, footprint: np.ndarray, what: str, pose,
                 params: ReachabilityParams) -> str | None:
    """Why the footprint cannot stand at pose (off the map, or on blocked cells), or None."""
    info = grid.info
    if not in_grid(info, *world_to_cell(info, pose[0], pose[1])):
        return f"{_describe(what, pose)} lies off the map"
    grown = pad(footprint, params.clearance_m + info.resolution / 2)
    rows, cols = cells_inside(info, transform(grown, pose))
    if blocked[rows, cols].any():
        grown_by = f", grown by {params.clearance_m:g} m" if params.clearance_m else ""
        return (f"{_describe(what, pose)} is in an obstacle: the robot's footprint there (yaw "
                f"{math.degrees(pose[2]):.0f} deg{grown_by}) covers occupied cells")
    return None


def mission_problems(grid: OccupancyGrid, footprint, start, goals,
                     params: ReachabilityParams = ReachabilityParams()) -> list[str]:
    """One line per problem with the start or a goal (goals numbered from 1); empty when the robot
    can stand at each and reach every goal from the start."""
    footprint = np.asarray(footprint, np.float64)
    blocked = blocked_cells(grid, params)
    problems = [p for p in [pose_problem(grid, blocked, footprint, "the start", start, params)] if p]
    named = [(f"goal {k + 1}", goal) for k, goal in enumerate(np.asarray(goals, np.float64).reshape(-1, 3))]
    standing = []
    for what, goal in named:
        problem = pose_problem(grid, blocked, footprint, what, goal, params)
        problems += [problem] if problem else []
        standing += [] if problem else [(what, goal)]
    if problems[:1] and problems[0].startswith("the start"):
        return problems
    inscribed = radii(footprint)[0]
    resolution = grid.info.resolution
    # a cell is lethal when the disk around its centre reaches a blocked cell (whose centre is half
    # a cell inside its edge)
    room = distances_to(blocked) * resolution
    costs = np.where(room < inscribed + resolution / 2, LETHAL, 0).astype(np.uint8)
    planner = GlobalPlanner(PATH_SEARCH)
    for what, goal in standing:
        if not planner.plan(costs, grid.info, start, goal).ok:
            problems.append(f"{_describe(what, goal)} cannot be reached from {_describe('the start', start)}: "
                            f"no way on the map wide enough for the robot (inscribed radius {inscribed:.2f} m)")
    return problems
