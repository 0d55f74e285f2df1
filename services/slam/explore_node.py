"""The explore service: drives the robot to frontiers of the slam map until none is left.

Inputs, synced: `map` (slam's, every map_update_interval) and `pose` (slam's pose in the map
frame, at every scan). Output: `cmd_vel`. It is explore_lite with its own simple path following
(the core, explore.py, chooses the frontier and plans the path on the map):

- On a map: its costs are made; the path being followed is kept while it is clear of the
  robot's reach of every occupied cell on the new map and its goal still lies within
  approach_distance of a frontier; otherwise a new goal is chosen.
- On a pose: steer at the path point `lookahead` ahead of the robot's nearest one (localize-eval's
  route_command: holonomic robots move straight at it and turn to face their way, a differential
  drive turns on the spot first when far off). Within goal_tolerance of the goal the robot stops
  and waits for a map made after it stopped; the frontier cells that map still holds were seen
  from close by and stay unknown (shadows), so they are given up. A goal not 0.1 m closer after
  progress_timeout is given up the same way.
- With no reachable frontier on two maps in a row (the second made while the robot stood still),
  the exploration is finished: the robot stands, `finished` is set.

Every decision depends only on the inputs' contents and stamps, so a replay reproduces it.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ...schemas.messages import OccupancyGrid, PoseWithCovariance, Twist
from ..localizer.evaluate import route_command
from ..runtime.node import NS_PER_S, Node
from .explore import ExploreGoal, Explorer, ExploreParams, find_frontiers, still_frontier

PROGRESS_M = 0.1


@dataclass(frozen=True)
class ExploreNodeParams(ExploreParams):
    holonomic: bool = True      # false: a differential drive (turns on the spot, never strafes)


class ExploreNode(Node):
    service = "explore"
    Params = ExploreNodeParams

    def setup(self) -> None:
        self.cmd_pub = self.publisher("cmd_vel")
        self.subscribe("map", self.on_map)
        self.subscribe("pose", self.on_pose)
        self.explorer: Explorer | None = None
        self.grid: OccupancyGrid | None = None
        self.costs: np.ndarray | None = None
        self.goal: ExploreGoal | None = None
        self.given_up = np.zeros((0, 2))        # world points of frontier cells given up
        self.pose: tuple[float, float, float] | None = None
        self.stopped_at_ns: int | None = None   # reached a goal; waiting for a map made since
        self.empty_maps = 0                     # maps in a row without a reachable frontier
        self.finished = False
        self._along = 0                         # index of the path point nearest the robot
        self._progress: tuple[float, int] = (math.inf, 0)   # (best distance to the goal, when)

    # ------------------------------------------------------------ inputs

    def on_map(self, msg: OccupancyGrid) -> None:
        if self.explorer is None:
            self.explorer = Explorer(self.params, msg.info.resolution)
        self.grid, self.costs = msg, self.explorer.costs(msg)
        if self.finished or self.pose is None:
            return
        if self.stopped_at_ns is not None:
            if msg.header.stamp_ns <= self.stopped_at_ns:
                return
            self._give_up()
            self.stopped_at_ns = None
        if self.goal is None or not self._goal_still_good():
            self._choose()

    def on_pose(self, msg: PoseWithCovariance) -> None:
        self.pose = (msg.pose.x, msg.pose.y, msg.pose.theta)
        goal = self.goal
        if goal is None or self.finished or self.stopped_at_ns is not None:
            self._command(0.0, 0.0, 0.0)
            return
        now = msg.header.stamp_ns
        distance = math.dist(self.pose[:2], goal.xy)
        if distance < self.params.goal_tolerance:
            self.counters["goals_reached"] += 1
            self.stopped_at_ns = now
            self._command(0.0, 0.0, 0.0)
            return
        best, since = self._progress
        if distance < best - PROGRESS_M:
            self._progress = (distance, now)
        elif now - since > round(self.params.progress_timeout * NS_PER_S):
            self.counters["goals_without_progress"] += 1
            self._give_up()
            self._choose()
            self._command(0.0, 0.0, 0.0)
            return
        p = self.params
        self._command(*route_command(self.pose, self._lookahead_point(), p.holonomic, p.speed, p.turn))

    # ------------------------------------------------------------ decisions

    def _goal_still_good(self) -> bool:
        goal, grid = self.goal, self.grid
        remaining = np.vstack([np.asarray(self.pose[:2])[None], goal.path[self._along + 1:]])
        if self.explorer.path_blocked(grid, self.costs, remaining):
            self.counters["paths_blocked"] += 1
            return False
        frontiers = find_frontiers(grid, self.params.min_frontier_size, self.given_up)
        if not frontiers:
            return False
        points = np.vstack([f.xy for f in frontiers])
        return float(np.min(np.hypot(*(points - goal.xy).T))) <= self.params.approach_distance

    def _choose(self) -> None:
        self.goal = self.explorer.choose(self.grid, self.costs, self.pose, self.given_up)
        self._along = 0
        self._progress = (math.inf, self.now_ns)
        if self.goal is None:
            self.empty_maps += 1
            self.finished = self.empty_maps >= 2
            return
        self.empty_maps = 0
        self.counters["goals"] += 1

    def _give_up(self) -> None:
        """Give up the cells of the goal's frontier that the current map still holds as frontier."""
        goal, grid = self.goal, self.grid
        if goal is None:
            return
        cells = goal.frontier.xy
        self.given_up = np.vstack([self.given_up, cells[still_frontier(grid, cells)]])
        self.counters["frontiers_given_up"] += 1
        self.goal = None

    def _lookahead_point(self) -> tuple[float, float]:
        """The path point lookahead ahead of the nearest one; the next point instead when the straight
        line to it would cut a corner into the robot's reach of an obstacle on the current map."""
        path, here = self.goal.path, np.asarray(self.pose[:2])
        window = path[self._along:]
        self._along += int(np.argmin(np.hypot(*(window - here).T)))
        ahead = np.flatnonzero(np.hypot(*(path[self._along:] - here).T) >= self.params.lookahead)
        target = path[self._along + ahead[0]] if len(ahead) else path[-1]
        if self.explorer.path_blocked(self.grid, self.costs, np.vstack([here, target])):
            self.counters["corners_not_cut"] += 1
            target = path[min(self._along + 1, len(path) - 1)]
        return tuple(target)

    def _command(self, vx: float, vy: float, wz: float) -> None:
        self.cmd_pub.publish(Twist(header=self.header("base_link"), linear_x=vx, linear_y=vy, angular_z=wz))

