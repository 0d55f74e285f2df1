"""Is a generated world fair to the robot? Checked before it is written; a world that fails is
drawn again from the next sub-seed.

- the start and the goal are free for the footprint grown by CLEARANCE_M, and the goal can be
  reached from the start on the world rasterised at RESOLUTION (experiments/reachability.py: the global
  planner core, a disk of the footprint's inscribed radius);
- every path mover's loop, and every walker's route (people: docs/people.md; a group as wide as it
  walks abreast), keeps its radius plus CLEARANCE_M from the static obstacles (people do not walk
  through furniture), and keeps off the robot standing at its start or its goal (the robot must be
  able to wait there without being run over);
- a flow's people (who walk from anywhere in its source area to anywhere in its goal area) keep
  off the robot standing at its start or its goal: the region between the two areas keeps the
  robot's reach plus a person plus CLEARANCE_M from both (the generator keeps furniture out of it);
- a building's robot (building_problems) gets from its start to its goal as its whole shape, not
  a disk, keeping CSPACE_MARGIN_M a side (experiments/configuration_space.py);
- a mover on keyframes (DynaBARN's obstacles) may cross walls, the start and the goal, as
  DynaBARN's do; it only must not overlap the robot's footprint at its start when the run begins.
"""
from __future__ import annotations

import numpy as np
from scipy.spatial import ConvexHull, QhullError

from ..configuration_space import reach
from ..mission_score import movers_clearance
from ..reachability import ReachabilityParams, mission_problems
from ...geometry.polygons import arc_lengths, point_segment_distance, points_in_polygons
from ...sim.people.plans import ROW_GAP
from ...sim.world import World

RESOLUTION = 0.05       # m, as `navigate` rasterises a world into its map
CLEARANCE_M = 0.1       # m, as the shipped worlds keep the footprint from everything at the start
SAMPLE_M = 0.05         # m between the points checked along a mover's loop
CSPACE_MARGIN_M = 0.05  # m a building's robot keeps from everything on some way to its goal


def _loop_points(loop: np.ndarray) -> np.ndarray:
    arcs = arc_lengths(loop)
    samples = np.arange(0.0, arcs[-1], SAMPLE_M)
    return np.column_stack([np.interp(samples, arcs, loop[:, 0]), np.interp(samples, arcs, loop[:, 1])])


def _swept_region(flow) -> np.ndarray:
    """The convex region (V, 2), counter-clockwise, between a flow's source and goal areas and
    through its via points."""
    corners = [np.asarray(area.center) + np.array([sx, sy]) * np.asarray(area.size) / 2
               for area in (flow.source, flow.goal) for sx in (-1, 1) for sy in (-1, 1)]
    points = np.unique(np.vstack([corners, flow.via.reshape(-1, 2)]), axis=0)
    try:
        return points[ConvexHull(points).vertices]
    except QhullError:                    # all on a line: the line's ends
        order = np.argsort(points @ (points[-1] - points[0]))
        return points[order[[0, -1]]]


def world_problems(world: World) -> list[str]:
    """One line per reason the world is unfair; empty when it is fine."""
    problems = mission_problems(world.rasterize(RESOLUTION), world.robot.footprint, world.robot.start, world.goals,
                                ReachabilityParams(clearance_m=CLEARANCE_M))
    footprint = world.robot.footprint
    reach = float(np.hypot(*footprint.T).max())
    ends = np.vstack([world.robot.start[:2], world.goals[:, :2]])
    on_keyframes = world.movers.on_keyframes
    at_start = movers_clearance(footprint, world.robot.start[None], world.movers.circles_at(0.0)[None, on_keyframes])
    if at_start[0] <= 0.0:
        problems.append("a mover on keyframes stands on the robot's start at t = 0")
    routes = [(f"mover {k}", loop, radius) for k, (loop, radius) in enumerate(zip(world.movers.loops, world.movers.radius))
              if not on_keyframes[k]]
    for k, w in enumerate(world.people.walkers):
        half_width = w.radius[1] + (w.group - 1) * (w.radius[1] + ROW_GAP / 2)
        routes.append((f"walker {k}", np.vstack([w.path, w.path[:1]]) if w.loop else w.path, half_width))
    for k, flow in enumerate(world.people.flows):
        region = _swept_region(flow)
        inside = points_in_polygons(ends, region[None])[:, 0].any()
        gap = point_segment_distance(ends[:, None], region[None], np.roll(region, -1, axis=0)[None]).min()
        if inside or gap < reach + flow.radius[1] + CLEARANCE_M:
            problems.append(f"flow {k} walks over the robot's start or goal")
    for name, loop, radius in routes:
        if world.distance(_loop_points(loop)).min() < radius + CLEARANCE_M:
            problems.append(f"{name} walks into a static obstacle")
        if point_segment_distance(ends[:, None], loop[None, :-1], loop[None, 1:]).min() < reach + radius + CLEARANCE_M:
            problems.append(f"{name} walks over the robot's start or goal")
    return problems



def building_problems(world: World) -> list[str]:
    """Why the robot's own shape (its footprint, not a disk) cannot drive from its start to its
    goal keeping CSPACE_MARGIN_M from everything, turning where it must; empty when it can."""
    grid = world.rasterize(RESOLUTION)
    way = reach(grid.data > 0, grid.info, world.robot.footprint, world.robot.start, world.goals[0], CSPACE_MARGIN_M)
    if way.reachable:
        return []
    return [f"the robot's shape cannot reach the goal with {CSPACE_MARGIN_M} m to spare a side"]
