"""The local_planner service: follows the navigator's path on the local costmap (move_base's
controller loop), with DWA, the elastic band or the path follower, and a precise final approach.

Inputs, in merge order: odom (synced); costmap/local, tf/map_odom, follow_path, tracks (sporadic). A
sporadic message stamped t takes effect at the first control tick stamped after
t + request_delay_s, as in global_planner/node.py: the costmap runs up to a scan period behind the
clock, and deferred, whether a message reached the node before or after the odometry stamped in
(t, t + delay] cannot change the commands — a live run replays byte for byte. The default, 0.5 s,
is above the 0.1–0.3 s by which live costmaps trailed the clock on a loaded 2-core machine (it
is the costmap's age that grows, not the path's, which the controller tracks on fresh odometry).

The tracker's tracks (moving obstacles) are held tracks_delay_s only (0.3 s: they follow the
scan, and are predicted from their stamp to the tick; 0.15 s was exceeded live on a loaded machine): DWA scores each rollout against where the
tracks will be along it (dynamic.py).

Control ticks fall on the odometry stamped at or first after each multiple of
1/controller_frequency of sim time. Each tick publishes a LocalCommand on local_cmd, stamped with
that odometry: idle (no path, or an empty follow_path) → ok, zero twist, goal_id "", reason
"idle"; else the answer for the followed path (its goal_id), and the chosen trajectory on
local_plan (costmap frame).

Frames: the controller works in the local costmap's frame (odom for the rolling window), where the
robot is the latest odometry; the path (map frame) is carried into it by the tf/map_odom in effect
(initial_pose_* until a localizer sends one, frames.py). The final approach runs in the map frame
on the odometry carried into the map the same way, so the goal is reached where the localization
says it is. A localizer's `pose` adds nothing here: it is always older than the odometry of a tick.

Within final_approach_distance of the path's end (straight-line) the FinalApproach (approach.py)
takes over as long as the poses it will pass through are free on the costmap; when they are not,
the controller carries on along the path. It reports ok with a zero twist ("goal_reached") once
within xy_goal_tolerance and yaw_goal_tolerance; the navigator decides success by its own.

Before the controller, the rotation shim (shim.py; on by default with dwa) turns the robot on the
spot towards a new path (a new goal_id, or a start more than START_MOVED from the last path's) that
lies more than angular_dist_threshold off its heading: reason "rotate_to_heading". Its state is
set by follow_path and the ticks alone, so a replay reproduces it.
"""
from __future__ import annotations

import math
import statistics
import time
from collections import deque
from dataclasses import dataclass, field, fields

import numpy as np

from ...schemas.messages import Costmap, Diagnostic, LocalCommand, Odometry, Path, Tracks
from ...geometry.footprint import DEFAULT_FOOTPRINT, STOP_PADDING, make_footprint
from ...geometry.frames import FrameParams
from ..runtime.deferred import Deferred
from ..runtime.node import NS_PER_S, Node, Ticks
from ..runtime.params import ForeignNames, ParamError, load_params, require_nonnegative
from ...geometry.se2 import compose, inverse
from .approach import FinalApproach
from .dwa import DwaPlanner, footprint_check_cost, reachable, warm_up
from .dynamic import Movers, movers_at, tracks_problem
from .path_follower import PathFollower, segments_from_poses
from .params import DwaParams, FollowerParams
from .path_ahead import ahead_of
from .shim import RotationShim, RotationShimParams

CONTROLLERS = ("dwa", "eband", "follower")
TIMES_KEPT = 10_000     # cycle times kept for the diagnostic's median
COSTMAP, MAP_ODOM, PATH = range(3)    # sporadic inputs, in input order (the order of equal stamps)
APPROACH_HYSTERESIS = 0.1             # m beyond final_approach_distance before an approach is given up
START_MOVED = 0.05    # m: a path from the same goal starting farther from the last one's start is a new path

# ROS local planner sections (move_base loads them under the planner's name) and how their names
# map onto DwaParams; names that mean nothing here are accepted without effect (docs/local_planner.md)
ROS_SECTIONS = {
    "TrajectoryPlannerROS": {"max_rotational_vel": "max_vel_theta", "min_in_place_rotational_vel":
                             "min_in_place_vel_theta", "backup_vel": "escape_vel",
                             "pdist_scale": "path_distance_bias", "gdist_scale": "goal_distance_bias"},
    "DWAPlannerROS": {"vth_samples": "vtheta_samples", "max_rot_vel": "max_vel_theta",
                      "min_rot_vel": "min_in_place_vel_theta", "min_vel_theta": "min_in_place_vel_theta",
                      "acc_lim_th": "acc_lim_theta", "use_dwa": "dwa"},
}
ROS_WITHOUT_EFFECT = {
    "meter_scoring", "heading_lookahead", "heading_scoring", "heading_scoring_timestep", "simple_attractor",
    "angular_sim_granularity", "prune_plan", "publish_cost_grid_pc", "publish_cost_grid", "publish_traj_pc",
    "global_frame_id", "latch_xy_goal_tolerance", "oscillation_reset_dist", "oscillation_reset_angle",
    "escape_reset_dist", "escape_reset_theta", "restore_defaults", "trans_stopped_vel", "theta_stopped_vel",
    "rot_stopped_vel", "stop_time_buffer", "scaling_speed", "max_scaling_factor", "twirling_scale",
    "acc_lim_trans", "max_vel_trans", "min_vel_trans", "max_trans_vel", "min_trans_vel", "use_sim_time",
}

# Nav2's controller_server with DWB (dwb_core::DWBLocalPlanner) as its one controller plugin: DWB's
# names are dwa_local_planner's where it has them; its critics' scales are the biases here
NAV2 = ForeignNames(
    stack="Nav2", node="controller_server", plugin_list="controller_plugins",
    plugin_types=frozenset({"dwb_core::DWBLocalPlanner"}),
    renames={"linear_granularity": "sim_granularity", "PathDist.scale": "path_distance_bias",
             "GoalDist.scale": "goal_distance_bias", "BaseObstacle.scale": "occdist_scale",
             "PathAlign.forward_point_distance": "forward_point_distance",
             "GoalAlign.forward_point_distance": "forward_point_distance"},
    naming_ignored_sections=frozenset({"goal_checker_plugins", "progress_checker_plugin",
                                       "progress_checker_plugins"}),
    # the server's thresholds and checkers (the navigator judges progress and arrival here), DWB's
    # speed norms, deceleration limits and critics without a counterpart in this DWA
    ignored=frozenset({"use_sim_time", "min_x_velocity_threshold", "min_y_velocity_threshold",
                       "min_theta_velocity_threshold", "failure_tolerance", "debug_trajectory_details",
                       "min_speed_xy", "max_speed_xy", "min_speed_theta", "decel_lim_x", "decel_lim_y",
                       "decel_lim_theta", "angular_granularity", "transform_tolerance", "trans_stopped_velocity",
                       "short_circuit_trajectory_evaluation", "stateful", "critics", "prune_plan",
                       "prune_distance", "PathAlign.scale", "GoalAlign.scale", "RotateToGoal.scale",
                       "RotateToGoal.slowing_factor", "RotateToGoal.lookahead_time"}))


@dataclass(frozen=True)
class LocalPlannerNodeParams(FrameParams, DwaParams, RotationShimParams):
    """DwaParams (TrajectoryPlannerROS / DWAPlannerROS names), RotationShimParams (Nav2's), the frames
    and the node's own; the tolerances are the final approach's, tighter than ROS's."""
    xy_goal_tolerance: float = 0.02      # m: the controller stops here (the navigator judges success)
    yaw_goal_tolerance: float = 0.02     # rad
    controller: str = "dwa"              # dwa | eband | follower
    final_approach_distance: float = 0.6  # m from the path's end where the final approach takes over
    rotation_shim: bool | None = None    # turn towards a new path first (shim.py); None: with the dwa controller
    path_follower: dict = field(default_factory=dict)   # FollowerParams by name (drive: from holonomic_robot)
    elastic_band: dict = field(default_factory=dict)    # ElasticBandParams by name; limits default to the above
    # the robot, spelled as costmap_2d spells it (the local costmap's values)
    footprint: tuple[tuple[float, float], ...] = tuple(map(tuple, DEFAULT_FOOTPRINT.tolist()))
    robot_radius: float = 0.46           # m, when footprint is empty
    footprint_padding: float = 0.01      # m
    inflation_radius: float = 0.55       # m: with cost_scaling_factor, where the footprint check starts
    cost_scaling_factor: float = 10.0    # 1/m
    request_delay_s: float = 0.5         # sim s from a costmap / tf / path stamp to its effect
    tracks_delay_s: float = 0.3          # sim s from a tracks stamp to its effect (they are predicted to the tick)
    # m: the collision monitor's stop zone (its default), kept free by DWA's rollouts
    stop_padding: float = STOP_PADDING

    def __post_init__(self):
        super().__post_init__()
        require_nonnegative(self, "xy_goal_tolerance", "yaw_goal_tolerance")
        if self.controller not in CONTROLLERS:
            raise ValueError(f"controller must be one of {CONTROLLERS}, got {self.controller!r}")
        require_nonnegative(self, "final_approach_distance", "request_delay_s", "tracks_delay_s", "robot_radius", "footprint_padding",
                            "inflation_radius", "cost_scaling_factor", "stop_padding")
        if self.footprint and len(self.footprint) < 3:
            raise ValueError(f"footprint needs at least 3 points, got {len(self.footprint)}")
        for name in ("path_follower", "elastic_band"):
            if not isinstance(getattr(self, name), dict):
                raise ValueError(f"{name} must be a mapping of parameter names to values, got {getattr(self, name)!r}")
        self.follower_params()
        self.shim_params()

    def shim_params(self) -> RotationShimParams:
        """The shim's parameters, its turn clamped to the controller's max_vel_theta and acc_lim_theta."""
        values = {f.name: getattr(self, f.name) for f in fields(RotationShimParams)}
        values["rotate_to_heading_angular_vel"] = min(self.rotate_to_heading_angular_vel, self.max_vel_theta)
        values["max_angular_accel"] = min(self.max_angular_accel, self.acc_lim_theta)
        return RotationShimParams(**values)

    def follower_params(self) -> FollowerParams:
        drive = "holonomic" if self.holonomic_robot else "diff"
        values = dict(self.path_follower)
        if values.setdefault("drive", drive) != drive:
            raise ValueError(f"path_follower: drive {values['drive']!r} contradicts holonomic_robot "
                             f"{self.holonomic_robot}")
        return load_params(FollowerParams, values, "path_follower")

    @classmethod
    def from_mapping(cls, values: dict | None, source: str = "local_planner") -> LocalPlannerNodeParams:
        """Flat names, plus ROS TrajectoryPlannerROS / DWAPlannerROS sections as move_base reads them, or
        a Nav2 controller_server file with DWB (NAV2)."""
        values = dict(values or {})
        nav2 = NAV2.plugin_list in NAV2.node_section(values)
        if nav2:
            values = NAV2.translate(values, source)
            if "max_vel_theta" in values:
                values.setdefault("min_vel_theta", -values["max_vel_theta"])   # DWB's limit is a magnitude
        for section, aliases in ROS_SECTIONS.items():
            ros = values.pop(section, None)
            if ros is None:
                continue
            if not isinstance(ros, dict):
                raise ParamError(f"{source}: {section} must be a mapping of parameters, got {ros!r}")
            for key, value in ros.items():
                name = aliases.get(key, key)
                if name in ROS_WITHOUT_EFFECT:
                    continue
                if name in values and values[name] != value:
                    raise ParamError(f"{source}: {name} is given twice ({section}: {key}: {value!r}, "
                                     f"and {values[name]!r})")
                values[name] = value
            if section == "DWAPlannerROS" and "max_vel_theta" in values:
                values.setdefault("min_vel_theta", -values["max_vel_theta"])   # DWA's limits are magnitudes
        return load_params(cls, values, source, NAV2.names if nav2 else ())


@dataclass(frozen=True)
class Control:
    """One tick's answer."""
    twist: np.ndarray
    ok: bool
    reason: str
    trajectory: np.ndarray      # (K, 3) in the costmap frame, for local_plan


class LocalPlannerNode(Node):
    service = "local_planner"
    Params = LocalPlannerNodeParams

    def setup(self) -> None:
        p = self.params
        warm_up()   # compile (or load) the rollout kernels now, never inside a cycle
        self.frames = p.robot_frames()
        fp = make_footprint(p.footprint, p.robot_radius, p.footprint_padding)
        check_cost = footprint_check_cost(fp.inscribed_radius, fp.circumscribed_radius, p.inflation_radius,
                                          p.cost_scaling_factor)
        self.dwa = DwaPlanner(DwaParams(**{f.name: getattr(p, f.name) for f in fields(DwaParams)}), fp.points,
                              check_cost, p.stop_padding, p.footprint_padding)
        self.follower_params = p.follower_params()
        self.controller = self._make_controller(fp.points, check_cost)
        self.ticks = Ticks(p.controller_frequency)
        self.dt = self.ticks.period_ns / NS_PER_S
        shimmed = p.rotation_shim if p.rotation_shim is not None else p.controller == "dwa"
        self.shim = RotationShim(p.shim_params(), self.dt) if shimmed else None
        self.shim_key: tuple[str, np.ndarray] | None = None   # goal_id and start of the last path the shim saw
        self.pending = Deferred(p.request_delay_s)   # sporadic inputs not yet in effect
        self.pending_tracks = Deferred(p.tracks_delay_s)
        self.tracks: Tracks | None = None        # the moving obstacles in effect
        self.costmap: Costmap | None = None
        self.path: Path | None = None            # followed; None: idle
        self.path_follower: PathFollower | None = None      # controller "follower", on the path in the map frame
        self.approach: FinalApproach | None = None
        self.arrived = False
        self.cycle_ms: deque[float] = deque(maxlen=TIMES_KEPT)
        self.cmd_pub = self.publisher("local_cmd")
        self.plan_pub = self.publisher("local_plan")
        self.subscribe("odom", self.on_odom)
        for kind, topic, check in ((COSTMAP, "costmap/local", self._check_costmap),
                                   (MAP_ODOM, "tf/map_odom", self.frames.transform_problem),
                                   (PATH, "follow_path", self._check_path)):
            self.subscribe_deferred(topic, self.pending, kind, check)
        self.subscribe_deferred("tracks", self.pending_tracks, check=self._check_tracks)

    def _make_controller(self, footprint: np.ndarray, check_cost: int):
        p = self.params
        if p.controller == "dwa":
            return self.dwa
        if p.controller == "eband":
            from .eband import ElasticBandPlanner    # numba-compiled: loaded only when chosen
            from .params import ElasticBandParams
            # one set of robot limits: the band's default to the node's (TEB spells them alike)
            shared = ["holonomic_robot", "controller_frequency", "max_vel_x", "max_vel_theta", "acc_lim_x",
                      "acc_lim_theta", *(["max_vel_y", "acc_lim_y"] if p.holonomic_robot else [])]
            values = {**{name: getattr(p, name) for name in shared}, **p.elastic_band}
            return ElasticBandPlanner(load_params(ElasticBandParams, values, "elastic_band"), footprint, check_cost)
        return None     # follower: built per path

    # ------------------------------------------------------------ inputs

    def _frame_problem(self, frame: str) -> str:
        if frame not in (self.frames.map_frame, self.frames.odom_frame):
            return f"frame {frame!r} is neither {self.frames.map_frame!r} nor {self.frames.odom_frame!r}"
        return ""

    def _check_costmap(self, msg: Costmap) -> str:
        if msg.data.shape != (msg.info.height, msg.info.width) or msg.data.size == 0:
            return f"data of shape {msg.data.shape} for a grid of {msg.info.height} x {msg.info.width} cells"
        return self._frame_problem(msg.header.frame_id)

    def _check_tracks(self, msg: Tracks) -> str:
        return tracks_problem(msg) or self._frame_problem(msg.header.frame_id)

    def _check_path(self, msg: Path) -> str:
        return self._frame_problem(msg.header.frame_id) if len(msg.poses) else ""

    def _apply_due(self, now_ns: int) -> None:
        """Put into effect the sporadic inputs stamped before now − request_delay_s, in stamp order."""
        for kind, msg in self.pending.due(now_ns):
            if kind == COSTMAP:
                self.costmap = msg
            elif kind == MAP_ODOM:
                self.frames.set_map_odom(msg)
            else:
                self._follow(msg)
        for _, msg in self.pending_tracks.due(now_ns):
            self.tracks = msg

    def _follow(self, msg: Path) -> None:
        self.path = msg if len(msg.poses) else None
        self.approach, self.arrived, self.path_follower = None, False, None
        self.counters["paths" if self.path is not None else "stops"] += 1
        if self.shim is not None and self.path is not None:
            start = np.asarray(msg.poses, np.float64).reshape(-1, 3)[0, :2]
            if (self.shim_key is None or self.shim_key[0] != msg.goal_id
                    or math.hypot(*(start - self.shim_key[1])) > START_MOVED):
                self.shim.new_path()
            self.shim_key = (msg.goal_id, start)
        if self.path is not None and self.params.controller == "follower":
            segments = segments_from_poses(self._in_frame(msg.poses, msg.header.frame_id, self.frames.map_frame))
            self.path_follower = PathFollower(self.follower_params, segments) if segments else None

    # ------------------------------------------------------------ control

    def on_odom(self, msg: Odometry) -> None:
        self.frames.set_odom(msg)
        t = msg.header.stamp_ns
        if not self.ticks.due(t):
            return
        self._apply_due(t)
        velocity = np.array([msg.twist.linear_x, msg.twist.linear_y, msg.twist.angular_z])
        began = time.perf_counter()     # instrumentation only
        control = self._control(velocity)
        self.cycle_ms.append((time.perf_counter() - began) * 1e3)
        goal_id = "" if self.path is None else self.path.goal_id
        status = control.reason.split(":")[0] if control.reason else "ok"
        self.counters[f"status/{status}"] += 1
        vx, vy, wz = (float(v) for v in control.twist)
        self.cmd_pub.publish(LocalCommand(header=self.header("base_link", t), goal_id=goal_id, linear_x=vx, linear_y=vy,
                                          angular_z=wz, ok=control.ok, reason=control.reason))
        if self.path is not None and self.costmap is not None:
            self.plan_pub.publish(Path(header=self.header(self.costmap.header.frame_id, t),
                                       poses=np.ascontiguousarray(control.trajectory, np.float64).reshape(-1, 3),
                                       goal_id=goal_id))

    def _in_frame(self, poses: np.ndarray, source: str, target: str) -> np.ndarray:
        """Poses (N, 3) given in the map or odom frame, in the other one (or the same)."""
        poses = np.asarray(poses, np.float64).reshape(-1, 3)
        if source == target:
            return poses
        map_odom = self.frames.map_odom
        return compose(map_odom, poses) if target == self.frames.map_frame else compose(inverse(map_odom), poses)

    def _brake(self, velocity: np.ndarray) -> np.ndarray:
        low, high = reachable(self.dwa.params, velocity)
        return np.clip(0.0, low, high)

    def _control(self, velocity: np.ndarray) -> Control:
        none = np.zeros((0, 3))
        if self.path is None:
            return Control(np.zeros(3), True, "idle", none)
        if self.arrived:
            return Control(np.zeros(3), True, "goal_reached", none)
        if self.costmap is None:
            return Control(self._brake(velocity), False, "no_costmap: no local costmap yet", none)
        frame = self.costmap.header.frame_id
        path = self._in_frame(self.path.poses, self.path.header.frame_id, frame)
        robot = self.frames.robot(frame)
        approach = self._approach(velocity)
        if approach is not None:
            return approach
        rotation = self._rotate(velocity, path, robot)
        if rotation is not None:
            return rotation
        if self.params.controller == "follower":
            return self._follow_path(velocity, path, robot)
        if self.controller is self.dwa:
            result = self.dwa.compute(robot, velocity, self.costmap.data, self.costmap.info, path,
                                      movers=self._movers(frame))
        else:
            result = self.controller.compute(robot, velocity, self.costmap.data, self.costmap.info, path)
        reason = result.status if result.status in ("ok", "escape") else f"{result.status}: {result.message}"
        return Control(result.cmd, result.status in ("ok", "escape"), "" if result.status == "ok" else reason,
                       result.trajectory)

    def _movers(self, frame: str) -> Movers | None:
        """The tracks in effect, predicted to this tick, in the costmap's frame."""
        if self.tracks is None:
            return None
        source = self.tracks.header.frame_id
        frame_pose = (0.0, 0.0, 0.0) if source == frame else self._in_frame(np.zeros((1, 3)), source, frame)[0]
        return movers_at(self.tracks, self.now_ns / NS_PER_S, frame_pose, self.params.dynamic_min_speed)

    def _approach(self, velocity: np.ndarray) -> Control | None:
        """The final approach's answer, or None when the robot is not close to the goal or the
        approach is blocked."""
        p = self.params
        robot = self.frames.robot(self.frames.map_frame)
        goal = self._in_frame(self.path.poses[-1:], self.path.header.frame_id, self.frames.map_frame)[0]
        distance = math.hypot(*(goal[:2] - robot[:2]))
        if self.approach is not None and distance > p.final_approach_distance + APPROACH_HYSTERESIS:
            self.approach = None
        if self.approach is None:
            if distance > p.final_approach_distance:
                return None
            moving = compose((0.0, 0.0, robot[2]), (*velocity[:2], 0.0))[:2]    # the robot's velocity, map axes
            along = float(np.dot(moving, goal[:2] - robot[:2]) / max(distance, 1e-9))
            self.approach = FinalApproach(self.follower_params, goal, robot, along, p.xy_goal_tolerance,
                                          p.yaw_goal_tolerance)
        frame = self.costmap.header.frame_id
        poses = self._in_frame(self.approach.planned_poses(robot, self.costmap.info.resolution / 2),
                               self.frames.map_frame, frame)
        if not self.dwa.legal_poses(poses, self.costmap.data, self.costmap.info).all():
            self.approach = None
            self.counters["approach_blocked"] += 1
            return None
        command = self.approach.step(robot, self.dt)
        if command.phase == "arrived":
            self.arrived = True
            return Control(np.zeros(3), True, "goal_reached", poses[-1:])
        return Control(command.twist, True, "final_approach", poses)

    def _rotate(self, velocity: np.ndarray, path: np.ndarray, robot: np.ndarray) -> Control | None:
        """The rotation shim's turn towards a new path, or None when it is off or has handed over;
        it stays out within final_approach_distance of the goal, where the final approach turns."""
        if self.shim is None or not self.shim.armed \
                or math.hypot(*(path[-1, :2] - robot[:2])) <= self.params.final_approach_distance:
            return None
        command = self.shim.step(robot, velocity, path,
                                 lambda poses: self.dwa.legal_poses(poses, self.costmap.data, self.costmap.info))
        if command.phase != "rotate":
            self.counters[f"shim/{command.phase}"] += 1
            return None
        return Control(command.twist, True, "rotate_to_heading", command.poses)

    def _follow_path(self, velocity: np.ndarray, path: np.ndarray, robot: np.ndarray) -> Control:
        """The path follower's command, unless the path ahead (as far as the robot gets in sim_time)
        is blocked on the costmap."""
        if self.path_follower is None:
            return Control(self._brake(velocity), False, "no_path: the path has no length", np.zeros((0, 3)))
        command = self.path_follower.step(self.frames.robot(self.frames.map_frame), self.dt)
        ahead, along = ahead_of(path, robot)
        ahead = ahead[along <= self.follower_params.cruise_speed * self.params.sim_time]
        if not self.dwa.legal_poses(ahead, self.costmap.data, self.costmap.info).all():
            return Control(self._brake(velocity), False, "path_blocked: the path ahead collides on the local costmap",
                           ahead)
        return Control(command.twist, True, "", ahead)

    def diagnostic(self) -> Diagnostic:
        diag = super().diagnostic()
        if self.cycle_ms:
            diag.values["cycle_ms"] = statistics.median(self.cycle_ms)
        return diag
