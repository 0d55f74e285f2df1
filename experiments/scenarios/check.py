"""Is a generated world fair to the robot? Checked before it is written; a world that fails is
drawn again from the next sub-seed.

- the start and the goal are free for the footprint grown by CLEARANCE_M, and the goal can be
  reached from the start on the world rasterised at RESOLUTION (experiments/reachability.py: the global
  planner core, a disk of the footprint's inscribed radius);
- every path mover's loop keeps its radius plus CLEARANCE_M from the static obstacles (people do
  not walk through furniture), and keeps off the robot standing at its start or its goal (the robot
  must be able to wait there without being run over);
- a mover on keyframes (DynaBARN's obstacles) may cross walls, the start and the goal, as
  DynaBARN's do; it only must not overlap the robot's footprint at its start when the run begins.
"""
from __future__ import annotations

import numpy as np

from ..mission_score import movers_clearance
from ..reachability import ReachabilityParams, mission_problems
from ...sim.world import World
from ...geometry.polygons import point_segment_distance
from .route import polyline_length

RESOLUTION = 0.05       # m, as `navigate` rasterises a world into its map
CLEARANCE_M = 0.1       # m, as the shipped worlds keep the footprint from everything at the start
SAMPLE_M = 0.05         # m between the points checked along a mover's loop


def _loop_points(loop: np.ndarray) -> np.ndarray:
    arcs = polyline_length(loop)
    samples = np.arange(0.0, arcs[-1], SAMPLE_M)
    return np.column_stack([np.interp(samples, arcs, loop[:, 0]), np.interp(samples, arcs, loop[:, 1])])


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
    for k, (loop, radius) in enumerate(zip(world.movers.loops, world.movers.radius)):
        if on_keyframes[k]:
            continue
        points = _loop_points(loop)
        if world.distance(points).min() < radius + CLEARANCE_M:
            problems.append(f"mover {k} walks into a static obstacle")
        if point_segment_distance(ends[:, None], loop[None, :-1], loop[None, 1:]).min() < reach + radius + CLEARANCE_M:
            problems.append(f"mover {k} walks over the robot's start or goal")
    return problems
