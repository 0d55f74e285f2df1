"""The local planner's control core: what the robot does on the followed path, tick by tick.

The node (node.py) calls `LocalControl.follow(path, frames)` when a follow_path takes effect and
`LocalControl.step(inputs)` on every control tick; the returned Control is the LocalCommand's twist,
ok and reason and the trajectory for local_plan. Nothing here reads a clock or does I/O, so the same
inputs always give the same commands (a replay reproduces them).

Frames: the controller works in the local costmap's frame (odom for the rolling window), where the
robot is the latest odometry; the path (map frame) is carried into it by the map→odom transform in
effect (`RobotFrames`, kept by the node). The final approach runs in the map frame on the odometry
carried into the map the same way, so the goal is reached where the localization says it is.

One tick, in order:
- no path (none yet, or an empty follow_path): ok, zero twist, reason "idle"; once arrived and as
  long as the robot stays within the tolerances: ok, zero twist, "goal_reached" (GOAL_REACHED); no
  costmap yet: a braking twist, not ok, "no_costmap: …".
- An arrived robot that is no longer within the tolerances (pushed, or its map pose corrected by a
  new map→odom) is approached again (counted arrival_lost): a latched arrival would leave it
  standing off the goal for good, answering goal_reached while the navigator waits for it.
- Within final_approach_distance of the path's end (straight-line) the FinalApproach (approach.py)
  takes over as long as the poses it will pass through are free on the costmap; when they are not,
  the controller carries on along the path (counted approach_blocked). It reports ok with a zero
  twist ("goal_reached") once within xy_goal_tolerance and yaw_goal_tolerance; the navigator
  decides success by its own. It is given up beyond final_approach_distance + APPROACH_HYSTERESIS
  and on a path that ends elsewhere; a replan to the same end pose (the navigator replans every
  planner period) keeps it, with the position it has latched (geometry/goal_latch.py).
- The rotation shim (shim.py; on by default with dwa) turns the robot on the spot towards a new path
  (a new goal_id, or a start more than START_MOVED from the last path's) that lies more than
  angular_dist_threshold off its heading: reason "rotate_to_heading". Its state is set by `follow`
  and the ticks alone. It stays out within final_approach_distance of the goal. DWA failing (backing
  up or braking: no forward rollout legal) arms it again (counted shim/rearmed): a path that turned
  round while the robot crept into a dead end (BARN world 58: a replanned path led back out of a
  pocket behind the robot) is one DWA's forward samples never reach — it crept on and backed up in
  turn until the navigator gave up — while turning on the spot first leaves it facing the way out.
- A maneuver being driven (maneuver.py) goes on: reason "maneuver", until its segments are done,
  its time is up, or the pose its command heads for within MANEUVER_LOOKAHEAD_S lies outside what
  the collision monitor lets through (FootprintCheck.monitor_check); then DWA again.
- Else the controller: DWA (scoring the tracker's tracks predicted to the tick, dynamic.py), the
  elastic band, TEB (teb.py: bands in several homotopy classes, each pose clear of the tracks where
  they will be when it is reached), or the path follower (braking, not ok, "path_blocked: …" when the path ahead is
  illegal on the costmap). When DWA has moved the robot less than maneuver.stall_radius over the
  last maneuver.stall_time (creeping counts: a window that slides, not one anchored where the robot
  stood) with no tracked mover within maneuver.mover_distance (a robot waiting for
  people is not stuck), a maneuver is searched in (x, y, heading) for the footprint and, found,
  driven from this tick on (counted maneuver/planned, else maneuver/none): at the mouth of a BARN
  gap DWA's arcs reach none of the few poses the padded footprint fits in, and the robot crept and
  turned there until a recovery moved it (docs/barn.md). A robot wedged on the costmap is searched
  and driven with the cells it is wedged on forgiven (`_plan_maneuver`).
Every pose is held to one FootprintCheck (footprint_check.py), the one DWA's rollouts use.
"""
from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, field, replace

import numpy as np

from ...schemas.messages import GOAL_REACHED, Costmap, Path, Tracks
from ...geometry.footprint import DEFAULT_FOOTPRINT, STOP_PADDING, make_footprint
from ...geometry.frames import RobotFrames
from ...geometry.se2 import compose
from ...parameters.declare import Rule, group, param
from ...parameters.from_mapping import load_params
from .approach import FinalApproach
from .dwa import VALID_DWA_STATUSES, DwaPlanner, path_maps, reachable
from .maneuver import ManeuverDriver, ManeuverParams, plan_maneuver
from ...geometry.movers import Movers, movers_at
from .dynamic import slack
from .footprint_check import FootprintCheck, footprint_check_cost
from .params import DwaParams, FollowerParams
from .path_ahead import ahead_of
from .path_follower import PathFollower, segments_from_poses
from .shim import RotationShim, RotationShimParams

CONTROLLERS = ("dwa", "eband", "teb", "follower")
DEFAULT_CONTROLLER = "dwa"
APPROACH_HYSTERESIS = 0.1             # m beyond final_approach_distance before an approach is given up
START_MOVED = 0.05    # m: a path from the same goal starting farther from the last one's start is a new path
MANEUVER_LOOKAHEAD_S = 0.1   # s of a maneuver's command whose end pose must be legal


@dataclass(frozen=True)
class LocalControlParams(DwaParams, RotationShimParams):
    """DwaParams (TrajectoryPlannerROS / DWAPlannerROS names), RotationShimParams (Nav2's) and the
    core's own; the tolerances are the final approach's, tighter than ROS's."""
    xy_goal_tolerance: float = param(0.02, ge=0)         # m: the controller stops here (the navigator judges success)
    yaw_goal_tolerance: float = param(0.02, ge=0)        # rad
    latch_xy_goal_tolerance: bool = True                 # the position once reached stays so while turning (geometry/goal_latch.py; ROS: false, Nav2: stateful)
    controller: str = param(DEFAULT_CONTROLLER, choices=CONTROLLERS)  # dwa | eband | teb | follower
    final_approach_distance: float = param(0.6, ge=0)    # m from the path's end where the final approach takes over
    rotation_shim: bool | None = None                    # turn towards a new path first (shim.py); None: with the dwa controller
    path_follower: dict = field(default_factory=dict)    # FollowerParams by name (drive: from holonomic_robot)
    maneuver: dict = field(default_factory=dict)         # ManeuverParams by name (maneuver.py; with the dwa controller)
    elastic_band: dict = field(default_factory=dict)     # ElasticBandParams by name; limits default to the above
    teb: dict = field(default_factory=dict)              # TebParams by name (teb.py); limits default to the above
    # the robot, spelled as costmap_2d spells it (the local costmap's values)
    footprint: tuple[tuple[float, float], ...] = param(tuple(map(tuple, DEFAULT_FOOTPRINT.tolist())),
                                                       min_items=3, or_empty=True)
    robot_radius: float = param(0.46, ge=0)              # m, when footprint is empty
    footprint_padding: float = param(0.01, ge=0)         # m
    inflation_radius: float = param(0.55, ge=0)          # m: with cost_scaling_factor, where the footprint check starts
    cost_scaling_factor: float = param(10.0, ge=0)       # 1/m
    # m: the collision monitor's stop zone (its default), kept free by DWA's rollouts
    stop_padding: float = param(STOP_PADDING, ge=0)

    def dwa_params(self) -> DwaParams:
        return group(self, DwaParams)

    def shim_params(self) -> RotationShimParams:
        """The shim's parameters, its turn clamped to the controller's max_vel_theta and acc_lim_theta."""
        return replace(group(self, RotationShimParams),
                       rotate_to_heading_angular_vel=min(self.rotate_to_heading_angular_vel, self.max_vel_theta),
                       max_angular_accel=min(self.max_angular_accel, self.acc_lim_theta))

    def follower_params(self) -> FollowerParams:
        drive = "holonomic" if self.holonomic_robot else "diff"
        values = dict(self.path_follower)
        if values.setdefault("drive", drive) != drive:
            raise ValueError(f"path_follower: drive {values['drive']!r} contradicts holonomic_robot "
                             f"{self.holonomic_robot}")
        return load_params(FollowerParams, values, "path_follower")

    def maneuver_params(self) -> ManeuverParams:
        return load_params(ManeuverParams, dict(self.maneuver), "maneuver")

    rules = (Rule("path_follower", lambda p: bool(p.follower_params()), "FollowerParams by name"),
             Rule("maneuver", lambda p: bool(p.maneuver_params()), "ManeuverParams by name"))


@dataclass(frozen=True)
class ControlInputs:
    """What one tick decides on."""
    velocity: np.ndarray        # (3,) the robot's body twist (vx, vy, wz), from the tick's odometry
    frames: RobotFrames         # the robot's latest odometry and the map→odom transform in effect
    costmap: Costmap | None     # the local costmap in effect; None: none yet
    tracks: Tracks | None       # the tracker's tracks in effect (moving obstacles); None: none
    now_s: float                # the tick's time, to which the tracks are predicted


@dataclass(frozen=True)
class Control:
    """One tick's answer."""
    twist: np.ndarray
    ok: bool
    reason: str
    trajectory: np.ndarray      # (K, 3) in the costmap frame, for local_plan
    counted: tuple[str, ...] = ()   # what happened on the way, for the node's Diagnostic counters


class LocalControl:
    """The followed path (`follow`) and the answer of each control tick `dt` seconds apart (`step`)."""

    def __init__(self, params: LocalControlParams, dt: float):
        p = self.params = params
        self.dt = dt
        fp = make_footprint(p.footprint, p.robot_radius, p.footprint_padding)
        self.footprint_check = FootprintCheck(
            fp.points, footprint_check_cost(fp.inscribed_radius, fp.circumscribed_radius, p.inflation_radius,
                                            p.cost_scaling_factor), p.stop_padding, p.footprint_padding)
        self.dwa_params = p.dwa_params()
        self.follower_params = p.follower_params()
        self.controller = self._make_controller()
        shimmed = p.rotation_shim if p.rotation_shim is not None else p.controller == "dwa"
        self.shim = RotationShim(p.shim_params(), dt) if shimmed else None
        self.shim_key: tuple[str, np.ndarray] | None = None   # goal_id and start of the last path the shim saw
        self.path: Path | None = None            # followed; None: idle
        self.path_follower: PathFollower | None = None      # controller "follower", on the path in the map frame
        self.approach: FinalApproach | None = None
        self.arrived = False
        self.maneuver_params = p.maneuver_params()
        self.maneuver: ManeuverDriver | None = None
        self._maneuver_from: tuple[np.ndarray, bool] | None = None   # where the maneuver was planned, and wedged there
        self._stall: deque[np.ndarray] = deque()   # the robot's poses over the last stall_time under DWA
        self._counted: list[str] = []

    def _make_controller(self):
        p = self.params
        if p.controller == "dwa":
            return DwaPlanner(self.dwa_params, self.footprint_check)
        if p.controller in ("eband", "teb"):
            # numba-compiled: loaded only when chosen
            from .eband import ElasticBandPlanner
            from .params import ElasticBandParams
            from .teb import TebParams, TebPlanner
            # one set of robot limits: the band's default to the node's (TEB spells them alike)
            shared = ["holonomic_robot", "controller_frequency", "max_vel_x", "max_vel_theta", "acc_lim_x",
                      "acc_lim_theta", *(["max_vel_y", "acc_lim_y"] if p.holonomic_robot else [])]
            defaults = {name: getattr(p, name) for name in shared}
            if p.controller == "eband":
                params = load_params(ElasticBandParams, {**defaults, **p.elastic_band}, "elastic_band")
                return ElasticBandPlanner(params, self.footprint_check)
            return TebPlanner(load_params(TebParams, {**defaults, **p.teb}, "teb"), self.footprint_check)
        return None     # follower: built per path

    def follow(self, path: Path, frames: RobotFrames) -> None:
        """Follow `path` (map or odom frame) from now on; an empty path stops."""
        same_goal = self.path is not None and len(path.poses) and path.goal_id == self.path.goal_id
        if not same_goal:
            self.maneuver = None
            self._stall.clear()
        if not (same_goal and _same_end(path, self.path)):
            self.approach, self.arrived = None, False
        self.path = path if len(path.poses) else None
        self.path_follower = None
        if self.shim is not None and self.path is not None:
            start = np.asarray(path.poses, np.float64).reshape(-1, 3)[0, :2]
            if (self.shim_key is None or self.shim_key[0] != path.goal_id
                    or math.hypot(*(start - self.shim_key[1])) > START_MOVED):
                self.shim.new_path()
            self.shim_key = (path.goal_id, start)
        if self.path is not None and self.params.controller == "follower":
            segments = segments_from_poses(frames.carry(path.poses, path.header.frame_id, frames.map_frame))
            self.path_follower = PathFollower(self.follower_params, segments) if segments else None

    def step(self, inputs: ControlInputs) -> Control:
        self._counted = []
        return replace(self._control(inputs), counted=tuple(self._counted))

    def _brake(self, velocity: np.ndarray) -> np.ndarray:
        low, high = reachable(self.dwa_params, velocity)
        return np.clip(0.0, low, high)

    def _legal(self, poses: np.ndarray, costmap: Costmap) -> np.ndarray:
        return self.footprint_check.legal_poses(poses, costmap.data, costmap.info)

    def _control(self, inputs: ControlInputs) -> Control:
        none = np.zeros((0, 3))
        if self.path is None:
            return Control(np.zeros(3), True, "idle", none)
        velocity, frames, costmap = inputs.velocity, inputs.frames, inputs.costmap
        if self.arrived:
            if self.approach.reached(frames.robot(frames.map_frame)):
                return Control(np.zeros(3), True, GOAL_REACHED, none)
            self.arrived, self.approach = False, None
            self._counted.append("arrival_lost")
        if costmap is None:
            return Control(self._brake(velocity), False, "no_costmap: no local costmap yet", none)
        frame = costmap.header.frame_id
        path = frames.carry(self.path.poses, self.path.header.frame_id, frame)
        robot = frames.robot(frame)
        approach = self._approach(velocity, frames, costmap)
        if approach is not None:
            self.maneuver = None
            self._stall.clear()
            return approach
        movers = self._movers(inputs, frame)
        maneuver = self._maneuver(robot, costmap)
        if maneuver is not None:
            return maneuver
        rotation = self._rotate(velocity, path, robot, costmap, movers)
        if rotation is not None:
            self._stall.clear()   # turning onto the path is no stall
            return rotation
        if self.params.controller == "follower":
            return self._follow_path(velocity, path, robot, frames, costmap)
        if self.params.controller == "dwa":
            maps = path_maps(path, robot, costmap.info, costmap.data, self.controller.distances)
            result = self.controller.compute(robot, velocity, costmap.data, costmap.info, path, maps, movers)
            if result.status in ("escape", "no_valid_trajectory") and self.shim is not None:
                self.shim.new_path()
                self._counted.append("shim/rearmed")
            if maps is not None and self._stalled(robot, movers):
                maneuver = self._plan_maneuver(robot, costmap, maps)
                if maneuver is not None:
                    return maneuver
        else:
            result = self.controller.compute(robot, velocity, costmap.data, costmap.info, path, movers)
        valid = result.status in VALID_DWA_STATUSES
        reason = result.status if valid else f"{result.status}: {result.message}"
        return Control(result.cmd, valid, "" if result.status == "ok" else reason,
                       result.trajectory)

    def _stalled(self, robot: np.ndarray, movers: Movers | None) -> bool:
        """Whether DWA has moved the robot less than stall_radius over the last stall_time, with no
        tracked mover within mover_distance (a robot waiting for people to pass is not stuck)."""
        m = self.maneuver_params
        if not m.enabled:
            return False
        self._stall.append(robot.copy())
        if (len(self._stall) - 1) * self.dt < m.stall_time:
            return False
        then = self._stall.popleft()
        if math.hypot(*(robot[:2] - then[:2])) > m.stall_radius:
            return False
        self._stall.clear()
        if movers is not None and movers.nearest_edge(robot) < m.mover_distance:
            return False
        return True

    def _plan_maneuver(self, robot: np.ndarray, costmap: Costmap, maps) -> Control | None:
        """A maneuver (maneuver.py) out of a stall, its first command; None when none is found.

        A robot wedged on the costmap (its own outline on lethal cells where it stands: a door post
        rasterised a cell into it, the scan's noise) is planned and driven with those cells forgiven
        (FootprintCheck.escape_check): from a start every neighbour of which is illegal the search
        found nothing (building-diff-3: the mecanum robot as a diff drive, diagonal in a 1.1 m door,
        stood 40 s). The collision monitor, on the scan's points, still stops any motion into the
        door post. Where the padded footprint finds no way, the search is run again with the padding
        given up for the monitor's stop zone (FootprintCheck.turn_check)."""
        fc, data, info = self.footprint_check, costmap.data, costmap.info
        check = fc.setup(robot, data, info)
        wedged = check.wedged
        if wedged:
            check = fc.escape_check(check, robot, data, info)
        segments = plan_maneuver(robot, fc, check, data, info, maps.goal_dist, self.maneuver_params)
        zone = None if segments or wedged else fc.turn_check(check, data, info)
        if zone is not None and fc.check_poses(zone, robot[None], data, info)[0]:
            # the padding given up before the maneuver: the robot's own outline grown by the
            # monitor's stop zone, which it is driven within anyway (BARN world 58: with the
            # Jackal's wheels in its footprint, no way out of a pocket kept the padding)
            segments = plan_maneuver(robot, fc, zone, data, info, maps.goal_dist, self.maneuver_params)
            self._counted.append("maneuver/unpadded")
        self._counted.append("maneuver/planned" if segments else "maneuver/none")
        if not segments:
            return None
        dwa = self.dwa_params
        self.maneuver = ManeuverDriver(segments, robot, self.maneuver_params, (dwa.max_vel_x, dwa.max_vel_theta),
                                       (dwa.acc_lim_x, dwa.acc_lim_theta))
        self._maneuver_from = robot.copy(), wedged
        return self._maneuver(robot, costmap)

    def _maneuver(self, robot: np.ndarray, costmap: Costmap) -> Control | None:
        """The maneuver's command while one is driven and the poses it heads for are legal; None (and
        the maneuver dropped) once it is done or blocked."""
        if self.maneuver is None:
            return None
        twist = self.maneuver.step(robot, self.dt)
        if twist is not None:
            ahead = compose(robot, tuple(v * MANEUVER_LOOKAHEAD_S for v in twist))
            poses = np.array([robot, ahead])
            fc, (anchor, wedged) = self.footprint_check, self._maneuver_from
            data, info = costmap.data, costmap.info
            if wedged:   # as planned: the robot's own outline, the cells it was wedged on forgiven
                check = fc.escape_check(fc.setup(anchor, data, info), anchor, data, info)
            else:
                check = fc.monitor_check(data, info)
                if not fc.check_poses(check, anchor[None], data, info)[0]:
                    # the monitor's zone reached a wall where it was planned: as planned, by the
                    # padding that pose allows (mecanum-20: six maneuvers dropped at their first step)
                    check = fc.setup(anchor, data, info)
            if fc.check_poses(check, poses, data, info).all():
                return Control(twist, True, "maneuver", poses)
            self._counted.append("maneuver/blocked")
        else:
            self._counted.append("maneuver/done" if self.maneuver.finished else "maneuver/timeout")
        self.maneuver = None
        self._stall.clear()
        return None

    def _movers(self, inputs: ControlInputs, frame: str) -> Movers | None:
        """The tracks in effect, predicted to this tick, in the costmap's frame."""
        if inputs.tracks is None:
            return None
        source = inputs.tracks.header.frame_id
        frame_pose = (0.0, 0.0, 0.0) if source == frame else inputs.frames.carry(np.zeros((1, 3)), source, frame)[0]
        return movers_at(inputs.tracks, inputs.now_s, frame_pose, self.params.dynamic_min_speed)

    def _approach(self, velocity: np.ndarray, frames: RobotFrames, costmap: Costmap) -> Control | None:
        """The final approach's answer, or None when the robot is not close to the goal or the
        approach is blocked."""
        p = self.params
        robot = frames.robot(frames.map_frame)
        goal = frames.carry(self.path.poses[-1:], self.path.header.frame_id, frames.map_frame)[0]
        distance = math.hypot(*(goal[:2] - robot[:2]))
        if self.approach is not None and distance > p.final_approach_distance + APPROACH_HYSTERESIS:
            self.approach = None
        if self.approach is None:
            if distance > p.final_approach_distance:
                return None
            moving = compose((0.0, 0.0, robot[2]), (*velocity[:2], 0.0))[:2]    # the robot's velocity, map axes
            along = float(np.dot(moving, goal[:2] - robot[:2]) / max(distance, 1e-9))
            self.approach = FinalApproach(self.follower_params, goal, robot, along, p.xy_goal_tolerance,
                                          p.yaw_goal_tolerance, p.latch_xy_goal_tolerance)
        poses = frames.carry(self.approach.planned_poses(robot, costmap.info.resolution / 2), frames.map_frame,
                             costmap.header.frame_id)
        if not self._legal(poses, costmap).all():
            self.approach = None
            self._counted.append("approach_blocked")
            return None
        command = self.approach.step(robot, self.dt)
        if command.phase == "arrived":
            self.arrived = True
            return Control(np.zeros(3), True, GOAL_REACHED, poses[-1:])
        return Control(command.twist, True, "final_approach", poses)

    def _rotate(self, velocity: np.ndarray, path: np.ndarray, robot: np.ndarray, costmap: Costmap,
                movers: Movers | None) -> Control | None:
        """The rotation shim's turn towards a new path, or None when it is off or has handed over;
        it stays out within final_approach_distance of the goal, where the final approach turns."""
        if self.shim is None or not self.shim.armed \
                or math.hypot(*(path[-1, :2] - robot[:2])) <= self.params.final_approach_distance:
            return None
        command = self.shim.step(robot, velocity, path,
                                 lambda poses: self._legal(poses, costmap) & self._clear_of_movers(poses, movers))
        if command.phase != "rotate":
            self._counted.append(f"shim/{command.phase}")
            return None
        return Control(command.twist, True, "rotate_to_heading", command.poses)

    def _clear_of_movers(self, poses: np.ndarray, movers: Movers | None) -> np.ndarray:
        """(K,) whether the footprint at each pose of a turn on the spot stays dynamic_obstacle_margin
        clear of every mover predicted over the shim's simulate_ahead_time. A turn is slow to leave a
        person's way and swings the corners: with one coming (a person catching up from behind while
        a replanned path turned the robot aside: generated head-on world, seed 2) the turn is not
        commanded and DWA, which scores its rollouts against the movers, drives instead."""
        if movers is None or not len(movers):
            return np.ones(len(poses), bool)
        steps = math.ceil(self.shim.params.simulate_ahead_time / self.dt) + 1
        held = np.repeat(np.asarray(poses, np.float64)[:, None, :], steps, axis=1)   # each pose held over the time
        hard, _ = slack(held, self.dt, self.footprint_check.footprint, movers, self.params.dynamic_obstacle_margin, 0.0)
        return (hard >= 0).all(axis=1)

    def _follow_path(self, velocity: np.ndarray, path: np.ndarray, robot: np.ndarray, frames: RobotFrames,
                     costmap: Costmap) -> Control:
        """The path follower's command, unless the path ahead (as far as the robot gets in sim_time)
        is blocked on the costmap."""
        if self.path_follower is None:
            return Control(self._brake(velocity), False, "no_path: the path has no length", np.zeros((0, 3)))
        command = self.path_follower.step(frames.robot(frames.map_frame), self.dt)
        ahead, along = ahead_of(path, robot)
        ahead = ahead[along <= self.follower_params.cruise_speed * self.params.sim_time]
        if not self._legal(ahead, costmap).all():
            return Control(self._brake(velocity), False, "path_blocked: the path ahead collides on the local costmap",
                           ahead)
        return Control(command.twist, True, "", ahead)


def _same_end(path: Path, other: Path) -> bool:
    """Whether two paths end on the same pose: a replan towards the same goal keeps the final
    approach (and its latched position) going instead of starting it afresh every planner period."""
    return (path.header.frame_id == other.header.frame_id
            and np.allclose(np.asarray(path.poses)[-1], np.asarray(other.poses)[-1], atol=1e-6))
