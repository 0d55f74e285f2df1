"""The explore service: explore_lite for omninav. It sends frontiers of the slam map as goals to
the navigator (move_base's part), which plans them on the global costmap (slam's map plus the
live scans) and drives them with the local planner, the velocity smoother and the collision
monitor, until no reachable frontier is left.

Inputs: `map` and `pose` (slam's, synced); `nav_status` (the navigator's, sporadic). Outputs:
`goal` (Goal, map frame, goal_id "explore-<n>": the core's approach cell, heading along the
bearing from the robot to it) and `cancel`. Decisions are made on maps (every map_update_interval of sim time):

- No goal out: the core (explore.py) chooses one on this map from the latest pose, leaving out
  the shadows and the failed frontiers held back (FailedFrontiers); it is sent.
- The goal's status succeeded: this map was made after the robot stopped there, so the frontier
  cells it still holds within approach_distance of the approached cell were seen from close by and
  stay unknown (shadows behind furniture): they are given up for good (the rest of a long
  frontier stays), and the next goal is chosen.
- aborted or canceled (no plan to it, or the robot stuck after the navigator's recoveries), or no
  PROGRESS_M closer within progress_timeout: the frontier failed. explore_lite blacklists it for
  good; here it is held back until the robot has moved or the map has grown, then tried again,
  and dropped for good (logged, with its reasons) after max_failures failures. Closer by either
  measure: the straight line from slam's pose, or the navigator's distance_remaining along its
  plan (a plan that leaves through a door and comes back behind a wall makes progress while the
  straight line grows).
- A goal out whose frontier has gone (no frontier cell within approach_distance of it: seen, or
  grown away): the next goal is chosen, which preempts it in the navigator.
- No reachable frontier: a goal not ended is canceled (the robot stops); on two maps in a row:
  finished.

A nav_status stamped t takes effect at the first map stamped after t + status_delay_s (as the
navigator defers its sporadic inputs): whether it arrives before or after the maps in
(t, t + delay], the goals are the same, and a live run replays exactly.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ...schemas.messages import CancelGoal, Goal, OccupancyGrid, Pose2D, PoseWithCovariance
from ...geometry.grid import cell_to_world
from ..runtime.deferred import Deferred
from ..runtime.node import NS_PER_S, Node
from .frontiers import (ExploreGoal, Explorer, ExploreParams, FailedFrontiers, find_frontiers, frontier_cells, known_area,
                      still_frontier)
from ...parameters.declare import param

PROGRESS_M = 0.1
GOAL_PREFIX = "explore-"
ENDED = ("succeeded", "aborted", "canceled")


class Progress:
    """The shortest distance to the goal seen so far by one measure, and when it last shrank by
    PROGRESS_M."""

    def __init__(self, start_ns: int):
        self.best = math.inf
        self.when_ns = start_ns

    def see(self, distance: float, stamp_ns: int) -> None:
        if distance < self.best - PROGRESS_M:
            self.best, self.when_ns = distance, stamp_ns


@dataclass(frozen=True)
class ExploreNodeParams(ExploreParams):
    status_delay_s: float = param(0.3, ge=0)     # sim s from a nav_status stamp to its effect
    progress_timeout: float = param(30.0, gt=0)  # sim s without getting 0.1 m closer to the goal: give it up (explore_lite's)


class ExploreNode(Node):
    service = "explore"
    Params = ExploreNodeParams

    def setup(self) -> None:
        self.goal_pub = self.publisher("goal")
        self.cancel_pub = self.publisher("cancel")
        self.subscribe("map", self.on_map)
        self.subscribe("pose", self.on_pose)
        self.explorer: Explorer | None = None
        self.goal: ExploreGoal | None = None
        self.goal_id = ""                       # the last goal sent
        self.goal_open = False                  # … and the navigator has not ended it
        self.statuses = Deferred(self.params.status_delay_s)   # statuses not yet in effect
        self.subscribe_deferred("nav_status", self.statuses)
        self.shadows = np.zeros((0, 2))         # world points of frontier cells seen from close by: left out for good
        self.failed = FailedFrontiers(self.params)
        self.pose: tuple[float, float, float] | None = None
        self.empty_maps = 0                     # maps in a row without a reachable frontier
        self.finished = False
        self.straight = Progress(0)             # towards the goal out: along the straight line
        self.along_plan = Progress(0)           # … and along the navigator's plan

    def on_pose(self, msg: PoseWithCovariance) -> None:
        self.pose = (msg.pose.x, msg.pose.y, msg.pose.theta)
        if self.goal is not None:
            self.straight.see(math.dist(self.pose[:2], self.goal.xy), msg.header.stamp_ns)

    def on_map(self, msg: OccupancyGrid) -> None:
        if self.explorer is None:
            self.explorer = Explorer(self.params, msg.info.resolution)
        if self.finished or self.pose is None:
            return
        ended, reason = self._ended_status(msg.header.stamp_ns)
        if self.goal is not None:
            if ended is not None:
                self.counters[f"goals_{ended}"] += 1
                if ended == "succeeded":
                    self._leave_shadows(msg)
                else:
                    self._fail(msg, f"{ended}: {reason}" if reason else ended)
            elif not self._near_a_frontier(msg):
                self.counters["goals_frontier_gone"] += 1
                self.goal = None
            elif (msg.header.stamp_ns - max(self.straight.when_ns, self.along_plan.when_ns)
                  > round(self.params.progress_timeout * NS_PER_S)):
                self.counters["goals_without_progress"] += 1
                self._fail(msg, f"no progress within progress_timeout {self.params.progress_timeout:g} s")
        if self.goal is None:
            self._choose(msg)

    # ------------------------------------------------------------ decisions

    def _ended_status(self, now_ns: int) -> tuple[str | None, str]:
        """Put into effect the statuses stamped before now − status_delay_s (the goal's progress along
        the plan); the last end of the goal out among them and its reason, or None."""
        ended, reason = None, ""
        for _, status in self.statuses.due(now_ns):
            if status.goal_id != self.goal_id:
                continue
            if status.status in ENDED:
                self.goal_open = False
                if self.goal is not None:
                    ended, reason = status.status, status.reason
            elif self.goal is not None and math.isfinite(status.distance_remaining):
                self.along_plan.see(status.distance_remaining, status.header.stamp_ns)
        return ended, reason

    def _near_a_frontier(self, grid: OccupancyGrid) -> bool:
        """Whether a frontier cell lies within approach_distance of the goal, to within half a cell: the
        goal was chosen at up to approach_distance from its frontier's cells, and this map's cells
        may lie differently, or the rounding differ (a frontier at 1.0000000000000002 m was gone)."""
        frontiers = find_frontiers(grid, self.params.min_frontier_size, self.shadows)
        if not frontiers:
            return False
        points = np.vstack([f.xy for f in frontiers])
        reach = self.params.approach_distance + grid.info.resolution / 2
        return float(np.min(np.hypot(*(points - self.goal.xy).T))) <= reach

    def _choose(self, grid: OccupancyGrid) -> None:
        goal = self.explorer.next_goal(grid, self.pose, self.shadows, self.failed)
        if goal is None:
            self.empty_maps += 1
            self.finished = self.empty_maps >= 2
            if self.goal_open:      # gone or failed, and nothing to preempt it with
                self.cancel_pub.publish(CancelGoal(header=self.header("map"), goal_id=self.goal_id))
                self.goal_open = False
            return
        self.empty_maps = 0
        self.goal = goal
        self.counters["goals"] += 1
        self.goal_id, self.goal_open = f"{GOAL_PREFIX}{self.counters['goals']}", True
        self.straight, self.along_plan = Progress(grid.header.stamp_ns), Progress(grid.header.stamp_ns)
        self.goal_pub.publish(Goal(header=self.header("map"), goal_id=self.goal_id,
                                   pose=Pose2D(*goal.xy, self._arrival_heading(goal))))

    def _arrival_heading(self, goal: ExploreGoal) -> float:
        """The bearing from the robot to the goal (the lidar sees all round: any heading will do, and
        this one needs no turning on the spot at the end of a straight drive); the robot's heading
        when the goal is within PROGRESS_M."""
        dx, dy = goal.xy[0] - self.pose[0], goal.xy[1] - self.pose[1]
        return math.atan2(dy, dx) if math.hypot(dx, dy) > PROGRESS_M else self.pose[2]

    def _leave_shadows(self, grid: OccupancyGrid) -> None:
        """Leave out for good the frontier cells within approach_distance of the cell the goal
        approached: seen from close by, they stay unknown (any frontier's: the goal's own may have
        changed shape, and one chosen again at the same place would end there again)."""
        rows, cols = np.nonzero(frontier_cells(grid))
        cells = np.column_stack(cell_to_world(grid.info, rows, cols))
        near = np.hypot(*(cells - self.goal.target_xy).T) <= self.params.approach_distance
        self.shadows = np.vstack([self.shadows, cells[near]])
        self.counters["shadow_cells"] += int(near.sum())
        self.goal = None

    def _fail(self, grid: OccupancyGrid, reason: str) -> None:
        """The goal's frontier failed: held back for now, dropped after max_failures failures."""
        record = self.failed.fail(self._still_frontier_cells(grid), reason, self.pose[:2], known_area(grid))
        self.counters["frontier_failures"] += 1
        if len(record.reasons) >= self.params.max_failures:
            self.counters["frontiers_dropped"] += 1
            centre = record.xy.mean(axis=0)
            self.log.info("frontier near (%.2f, %.2f) dropped after %d failures: %s", *centre, len(record.reasons),
                          "; ".join(record.reasons))
        self.goal = None

    def _still_frontier_cells(self, grid: OccupancyGrid) -> np.ndarray:
        cells = self.goal.frontier.xy
        return cells[still_frontier(grid, cells)]
