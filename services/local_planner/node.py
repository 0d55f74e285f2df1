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

The decisions — final approach, rotation shim or controller, and the command's ok and reason —
are the core's (control.py: LocalControl); this node keeps the inputs in effect and the frames
(odometry, tf/map_odom: frames.py), hands each tick to the core and publishes its answer. A
localizer's `pose` adds nothing here: it is always older than the odometry of a tick.
"""
from __future__ import annotations

import statistics
import time
from collections import deque
from dataclasses import dataclass

import numpy as np

from ...schemas.messages import Costmap, Diagnostic, LocalCommand, Odometry, Path, Tracks
from ...geometry.frames import FrameParams
from ..runtime.deferred import Deferred
from ..runtime.node import NS_PER_S, Node, Ticks
from ..runtime.params import ForeignNames
from ...parameters.declare import ParamError, param
from ...parameters.from_mapping import load_params
from .control import ControlInputs, LocalControl, LocalControlParams
from .dwa import warm_up
from ...geometry.movers import tracks_problem

TIMES_KEPT = 10_000     # cycle times kept for the diagnostic's median
COSTMAP, MAP_ODOM, PATH = range(3)    # sporadic inputs, in input order (the order of equal stamps)

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
    "global_frame_id", "oscillation_reset_dist", "oscillation_reset_angle",
    "restore_defaults", "trans_stopped_vel", "theta_stopped_vel",
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
class LocalPlannerNodeParams(FrameParams, LocalControlParams):
    """The core's parameters (LocalControlParams: DwaParams, RotationShimParams and its own), the
    frames and the node's input delays."""
    request_delay_s: float = param(0.5, ge=0)         # sim s from a costmap / tf / path stamp to its effect
    tracks_delay_s: float = param(0.3, ge=0)          # sim s from a tracks stamp to its effect (they are predicted to the tick)

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


class LocalPlannerNode(Node):
    service = "local_planner"
    Params = LocalPlannerNodeParams

    def setup(self) -> None:
        p = self.params
        warm_up()   # compile (or load) the rollout kernels now, never inside a cycle
        self.frames = p.robot_frames()
        self.ticks = Ticks(p.controller_frequency)
        self.core = LocalControl(p, self.ticks.period_ns / NS_PER_S)
        self.pending = Deferred(p.request_delay_s)   # sporadic inputs not yet in effect
        self.pending_tracks = Deferred(p.tracks_delay_s)
        self.tracks: Tracks | None = None        # the moving obstacles in effect
        self.costmap: Costmap | None = None
        self.cycle_ms: deque[float] = deque(maxlen=TIMES_KEPT)
        self.cmd_pub = self.publisher("local_cmd")
        self.plan_pub = self.publisher("local_plan")
        self.subscribe("odom", self.on_odom)
        for kind, topic, check in ((COSTMAP, "costmap/local", self._check_costmap),
                                   (MAP_ODOM, "tf/map_odom", self.frames.transform_problem),
                                   (PATH, "follow_path", self._check_path)):
            self.subscribe_deferred(topic, self.pending, kind, check)
        self.subscribe_deferred("tracks", self.pending_tracks, check=self._check_tracks)

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
                self.counters["paths" if len(msg.poses) else "stops"] += 1
                self.core.follow(msg, self.frames)
        for _, msg in self.pending_tracks.due(now_ns):
            self.tracks = msg

    # ------------------------------------------------------------ control

    def on_odom(self, msg: Odometry) -> None:
        self.frames.set_odom(msg)
        t = msg.header.stamp_ns
        if not self.ticks.due(t):
            return
        self._apply_due(t)
        velocity = np.array([msg.twist.linear_x, msg.twist.linear_y, msg.twist.angular_z])
        began = time.perf_counter()     # instrumentation only
        control = self.core.step(ControlInputs(velocity, self.frames, self.costmap, self.tracks, self.now_ns / NS_PER_S))
        self.cycle_ms.append((time.perf_counter() - began) * 1e3)
        for counted in control.counted:
            self.counters[counted] += 1
        path = self.core.path
        goal_id = "" if path is None else path.goal_id
        status = control.reason.split(":")[0] if control.reason else "ok"
        self.counters[f"status/{status}"] += 1
        vx, vy, wz = (float(v) for v in control.twist)
        self.cmd_pub.publish(LocalCommand(header=self.header("base_link", t), goal_id=goal_id, linear_x=vx, linear_y=vy,
                                          angular_z=wz, ok=control.ok, reason=control.reason))
        if path is not None and self.costmap is not None:
            self.plan_pub.publish(Path(header=self.header(self.costmap.header.frame_id, t),
                                       poses=np.ascontiguousarray(control.trajectory, np.float64).reshape(-1, 3),
                                       goal_id=goal_id))

    def diagnostic(self) -> Diagnostic:
        diag = super().diagnostic()
        if self.cycle_ms:
            diag.values["cycle_ms"] = statistics.median(self.cycle_ms)
        return diag
