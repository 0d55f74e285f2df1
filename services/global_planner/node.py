"""The global_planner service: plans over the global costmap with the A*/Dijkstra core (astar.py).

Plan as a service: `get` on the plan key with `start=x,y[,yaw];goal=x,y[,yaw]` (metres and radians
in the costmap's frame, the map; yaw 0 when left out) answers a Path planned on the newest global
costmap received; without `start` the plan starts at the robot's pose. A plan that fails answers
an error whose text begins with the status (`no_path`, `goal_in_obstacle`, `off_map`, `unreachable`) and says why;
malformed parameters, or no costmap yet, answer an error saying so. `get` without parameters
answers the plan last published.

Goals: a Goal on goal_topic (`goal`, from users; the navigation compose uses `plan_request`, the
navigator's requests, with planner_frequency 0 since the navigator replans itself) is planned
from the robot's pose when it takes effect (its pose only: waypoints are the navigator's to send
one by one), and again every 1/planner_frequency of sim time while it is active (0: once per
goal, as move_base), until a cancel naming it (or naming no goal). Each plan is published on the
plan key, stamped with the sim time it was made, with the goal's goal_id; a failed one as an
empty Path, as ROS global_planner does, whose error says "<status>: <reason>", counted in the
Diagnostic as plans/<status>. A goal that comes before a costmap or a pose is planned when they
are there.

Inputs, in merge order: odom (synced); costmap/global, tf/map_odom, pose, goal_topic, cancel, map (sporadic).

A plan that fails (no_path, goal_in_obstacle) on a costmap in the map frame is checked against the
latest map (map_reach.py): a goal that no way through the map's free cells joins to the robot fails
as `unreachable: <why> (<the planner's status>: <its reason>)`, which the navigator ends the goal on
at once; otherwise the failure stands, for the navigator's recoveries.
A sporadic message stamped t takes effect at the first odometry or planning tick stamped after
t + request_delay_s, as the localizer defers its requests: the costmap service runs up to a scan
period behind the clock (it waits for the scans), so its costmaps come after the odometry of their
stamp; deferred, whether one reached the node before or after the odometry stamped in
(t, t + delay] cannot change the plans, and a live run replays byte for byte.

The robot's pose: the latest `pose` (a localizer's PoseWithCovariance, map frame) when it is newer
than the odometry, else the odometry carried into the map by tf/map_odom, or by initial_pose_*
until a localizer sends one (frames.py).
"""
from __future__ import annotations

import math
import statistics
import time
from collections import deque
from dataclasses import dataclass

import numpy as np

from ...schemas.keys import KeyLayout, type_for_key
from ...schemas.messages import (PLAN_UNREACHABLE, Costmap, Diagnostic, Goal, Header, OccupancyGrid, Odometry, Path,
                                 PoseWithCovariance)
from ...geometry.frames import FrameParams
from ..runtime.deferred import Deferred
from ..runtime.node import Node, QueryError
from .astar import GOAL_IN_OBSTACLE, NO_PATH, GlobalPlanner, PlanResult, warm_up
from .map_reach import MapReach
from .params import GlobalPlannerParams
from ...parameters.declare import ParamError, Rule, param

TIMES_KEPT = 10_000     # plan times kept for the diagnostic's median
QUERY_PARAMETERS = ("start", "goal")
COSTMAP, MAP_ODOM, POSE, GOAL, CANCEL, MAP = range(6)   # sporadic inputs, in input order (the order of equal stamps)


@dataclass(frozen=True)
class PlannerNodeParams(FrameParams, GlobalPlannerParams):
    """ROS global_planner's parameters (and move_base's planner_frequency) plus the frames."""
    request_delay_s: float = param(0.3, ge=0)  # sim s from a costmap / tf / pose / goal / cancel stamp to its effect
    goal_topic: str = "goal"      # where goals come from: "goal" (users) or "plan_request" (the navigator)
    planner_frequency: float = param(0.0, ge=0)   # Hz (move_base's name): replanning rate; 0 = once per goal

    rules = (Rule("goal_topic", lambda p: _carries_goals(p.goal_topic), "a topic of Goal messages"),)


def _grid_problem(grid: Costmap | OccupancyGrid) -> str:
    if grid.data.shape != (grid.info.height, grid.info.width) or grid.data.size == 0:
        return f"data of shape {grid.data.shape} for a grid of {grid.info.height} x {grid.info.width} cells"
    return ""


def _carries_goals(topic: str) -> bool:
    try:
        return type_for_key(KeyLayout().resolve(topic)) is Goal
    except KeyError as exc:
        raise ParamError(f"parameter goal_topic must be a robot topic: {topic!r}: {exc.args[0]}") from None


def parse_pose(name: str, text: str) -> np.ndarray:
    """'x,y' or 'x,y,yaw' -> (x, y, yaw); QueryError naming the parameter otherwise."""
    try:
        values = [float(v) for v in text.split(",")]
    except ValueError:
        values = []
    if len(values) not in (2, 3) or not all(math.isfinite(v) for v in values):
        raise QueryError(f"{name}={text!r}: expected x,y or x,y,yaw (metres, radians, in the map frame)")
    return np.array(values + [0.0] * (3 - len(values)))


class PlannerNode(Node):
    service = "global_planner"
    Params = PlannerNodeParams

    def setup(self) -> None:
        p = self.params
        warm_up()   # compile (or load) the search and smoothing kernels now, never inside a cycle
        self.planner = GlobalPlanner(p)
        self.frames = p.robot_frames()
        self.pending = Deferred(p.request_delay_s)   # sporadic inputs not yet in effect
        self.costmap: Costmap | None = None          # in effect
        self.pose: PoseWithCovariance | None = None
        self.map: OccupancyGrid | None = None         # in effect
        self._map_reach: tuple[OccupancyGrid, MapReach] | None = None   # a map's free regions, found when a plan first fails on it
        self.goal: Goal | None = None
        self.waiting = False               # the active goal is not planned yet: no costmap or pose
        self.plan: Path | None = None      # last published
        self.plan_ms: deque[float] = deque(maxlen=TIMES_KEPT)
        self.plan_pub = self.publisher("plan")
        self.plan_key = self.plan_pub.key
        self.subscribe("odom", self.on_odom)
        for kind, topic, check in ((COSTMAP, "costmap/global", self._check_costmap),
                                   (MAP_ODOM, "tf/map_odom", self.frames.transform_problem),
                                   (POSE, "pose", self._check_pose), (GOAL, p.goal_topic, self._check_goal),
                                   (CANCEL, "cancel", None), (MAP, "map", self._check_map)):
            self.subscribe_deferred(topic, self.pending, kind, check)
        self.queryable("plan", self.answer_plan)
        if p.planner_frequency > 0:
            self.every(1.0 / p.planner_frequency, self.on_timer)

    # ------------------------------------------------------------ inputs

    @property
    def newest_costmap(self) -> Costmap | None:
        """The newest costmap received, in effect or not (queries are answered now, not replayed)."""
        held = self.pending.latest(COSTMAP)
        return held if held is not None else self.costmap

    def _check_costmap(self, msg: Costmap) -> str:
        problem = _grid_problem(msg)
        if not problem and msg.header.frame_id not in (self.frames.map_frame, self.frames.odom_frame):
            problem = f"frame {msg.header.frame_id!r} is neither {self.frames.map_frame!r} nor {self.frames.odom_frame!r}"
        return problem

    def _check_map(self, msg: OccupancyGrid) -> str:
        return _grid_problem(msg) or self._check_goal(msg)

    def _check_pose(self, msg: PoseWithCovariance) -> str:
        if msg.header.frame_id != self.frames.map_frame:
            return f"frame {msg.header.frame_id!r}, expected the map frame {self.frames.map_frame!r}"
        return ""

    def _check_goal(self, msg: Goal | OccupancyGrid) -> str:
        """A frame of the map's (or none, taken as the map's)."""
        if msg.header.frame_id not in ("", self.frames.map_frame):
            return f"frame {msg.header.frame_id!r}, expected the map frame {self.frames.map_frame!r}"
        return ""

    def _apply_due(self, now_ns: int) -> None:
        """Put into effect the sporadic inputs stamped before now − request_delay_s, in stamp order."""
        for kind, msg in self.pending.due(now_ns):
            if kind == COSTMAP:
                self.costmap = msg
            elif kind == MAP_ODOM:
                self.frames.set_map_odom(msg)
            elif kind == POSE:
                self.pose = msg
            elif kind == MAP:
                self.map = msg
            elif kind == GOAL:
                self.goal, self.waiting = msg, True
                self.counters["goals"] += 1
            elif self.goal is not None and msg.goal_id in ("", self.goal.goal_id):
                self.goal, self.waiting = None, False
                self.counters["goals_canceled"] += 1

    def on_odom(self, msg: Odometry) -> None:
        self.frames.set_odom(msg)
        self._apply_due(msg.header.stamp_ns)
        if self.waiting:
            self.replan()

    def on_timer(self) -> None:
        self._apply_due(self.now_ns)
        self.replan()

    # ------------------------------------------------------------ planning

    def _plan(self, costmap: Costmap, start, goal, grid: OccupancyGrid | None) -> PlanResult:
        """A plan on the costmap; a failed one checked against the map `grid` (map_reach.py)."""
        began = time.perf_counter()   # instrumentation only
        result = self.planner.plan(costmap.data, costmap.info, start, goal)
        if result.status in (NO_PATH, GOAL_IN_OBSTACLE) and grid is not None \
                and costmap.header.frame_id == self.frames.map_frame:
            if self._map_reach is None or self._map_reach[0] is not grid:
                self._map_reach = grid, MapReach(grid, self.params.allow_unknown)
            why = self._map_reach[1].why_unreachable(start, goal, self.params.default_tolerance)
            if why:
                result = PlanResult(PLAN_UNREACHABLE, f"{why} ({result.status}: {result.message})")
        self.plan_ms.append((time.perf_counter() - began) * 1e3)
        return result

    def replan(self) -> None:
        """Plan the active goal from the robot's pose and publish it."""
        if self.goal is None:
            return
        start = None if self.costmap is None else self.frames.robot_with_pose(self.costmap.header.frame_id,
                                                                               self.pose)
        self.waiting = start is None
        if self.waiting:
            return
        g = self.goal.pose
        result = self._plan(self.costmap, start, (g.x, g.y, g.theta), self.map)
        self.counters[f"plans/{result.status}"] += 1
        self.plan = Path(header=self.header(self.costmap.header.frame_id), poses=result.poses,
                         goal_id=self.goal.goal_id, error="" if result.ok else f"{result.status}: {result.message}")
        self.plan_pub.publish(self.plan)

    def answer_plan(self, parameters: dict[str, str]) -> Path | None:
        if not parameters:
            return self.plan
        unknown = sorted(set(parameters) - set(QUERY_PARAMETERS))
        if unknown:
            raise QueryError(f"{self.plan_key}: unknown parameter(s) {unknown}; use start=x,y[,yaw];goal=x,y[,yaw]")
        if "goal" not in parameters:
            raise QueryError(f"{self.plan_key}: goal=x,y[,yaw] is required (start defaults to the robot's pose)")
        goal = parse_pose("goal", parameters["goal"])
        start = parse_pose("start", parameters["start"]) if "start" in parameters else None
        costmap = self.newest_costmap
        if costmap is None:
            raise QueryError(f"{self.plan_key}: no global costmap yet (on {self.keys.resolve('costmap/global')})")
        if start is None:
            start = self.frames.robot_with_pose(costmap.header.frame_id, self.pose)
            if start is None:
                raise QueryError(f"{self.plan_key}: no start= given and the robot's pose is not known yet")
        held = self.pending.latest(MAP)
        result = self._plan(costmap, start, goal, held if held is not None else self.map)
        self.counters[f"queries/{result.status}"] += 1
        if not result.ok:
            raise QueryError(f"{result.status}: {result.message}")
        return Path(header=Header(stamp_ns=costmap.header.stamp_ns, frame_id=costmap.header.frame_id),
                    poses=result.poses)

    def diagnostic(self) -> Diagnostic:
        diag = super().diagnostic()
        if self.plan_ms:
            diag.values["plan_ms"] = statistics.median(self.plan_ms)
        return diag
