"""Navigator parameters with move_base's names and defaults (ROS 1 noetic move_base.cpp).

min_pose_beam_fit and recovery_by_cause are not move_base's: move_base trusts any pose; this one
waits at the goal while the localizer's scans do not fit the map (docs/navigator.md); move_base runs
its recovery behaviours in one order, this one in the order that suits what blocked the robot
(core.py). xy_goal_tolerance, yaw_goal_tolerance,
latch_xy_goal_tolerance and escape_vel are base_local_planner's (in ROS the local
planner decides arrival; here the navigator does, so both see the same numbers). The recovery
behaviours' own settings (rotate_angle, max_rotational_vel, backup_dist, wait_duration) carry the
names of rotate_recovery and Nav2's BackUp/Wait behaviours.

ROS move_base files load unchanged (from_mapping; flat or under `move_base:`): `recovery_behaviors`
may be move_base's list of `{name, type}` plugin entries, whose types map onto the behaviours here
(ROS_RECOVERY_TYPES); the namespaces those entries name (e.g. `conservative_reset:
{reset_distance: 3.0}`) and the plugin and make_plan settings in ROS_IGNORED are accepted without
effect (each behaviour takes its settings from the names above). Anything else unknown is an
error naming the key.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

from ..runtime.params import unwrap_ros
from ...parameters.declare import ParamError
from ...parameters.from_mapping import load_params
from ...parameters.declare import Parameters, Rule, param

RECOVERY_NAMES = ("clear_costmaps", "rotate", "back_up", "wait")
# move_base recovery plugin types -> the behaviour here
ROS_RECOVERY_TYPES = {"clear_costmap_recovery/ClearCostmapRecovery": "clear_costmaps",
                      "rotate_recovery/RotateRecovery": "rotate"}
# move_base settings of plugins and services that have no meaning here
ROS_IGNORED = frozenset({"base_global_planner", "base_local_planner", "make_plan_clear_costmap",
                         "make_plan_add_unreachable_goal", "restore_defaults", "use_sim_time"})


@dataclass(frozen=True)
class NavigatorParams(Parameters):
    planner_frequency: float = param(0.0, ge=0)            # Hz: replanning while controlling; 0 = only on a new goal or a failure
    controller_frequency: float = param(20.0, gt=0)        # Hz: the rate step() is called at; sets the recovery command period
    planner_patience: float = param(5.0, ge=0)             # s without a valid plan → recovery
    controller_patience: float = param(15.0, ge=0)         # s without a valid command → recovery
    max_planning_retries: int = param(-1, ge=-1)           # failed plans tolerated before recovery; -1 = unlimited (patience only)
    oscillation_timeout: float = param(0.0, ge=0)          # s without moving oscillation_distance → recovery; 0 = off
    oscillation_distance: float = param(0.5, ge=0)         # m
    conservative_reset_dist: float = param(3.0, ge=0)      # m: clear_costmaps keeps obstacles within this square around the robot
    recovery_behavior_enabled: bool = True
    clearing_rotation_allowed: bool = True                 # false drops "rotate" from the recovery order
    shutdown_costmaps: bool = False                        # accepted for ROS files; costmaps here run independently
    recovery_behaviors: tuple[str, ...] = param(RECOVERY_NAMES, choices=RECOVERY_NAMES)
    recovery_by_cause: bool = True                         # run them in the order that suits what blocked the robot (core.py); false: as listed, as move_base
    xy_goal_tolerance: float = param(0.10, ge=0)           # m
    yaw_goal_tolerance: float = param(0.05, ge=0)          # rad (final pose only; waypoints check xy only)
    latch_xy_goal_tolerance: bool = True                   # the final position once reached stays so while turning, within a slack (geometry/goal_latch.py; ROS: false, Nav2: stateful)
    trans_stopped_vel: float = param(0.1, ge=0)            # m/s: at the final pose, success only below this (dwa_local_planner)
    rot_stopped_vel: float = param(0.1, ge=0)              # rad/s: likewise
    min_pose_beam_fit: float = param(0.5, ge=0)            # success only while the localizer's latest beam fit is at least this; 0 = off
    # success only while the odometry fusion trusts its odometry (odom_doubt): for a pose from odometry
    # alone; a localizer on a map judges its own pose (min_pose_beam_fit) and puts a push right
    use_odometry_doubt: bool = True
    escape_vel: float = param(-0.1, finite=True)           # m/s along x while backing up (negative: backwards)
    rotate_angle: float = param(2 * math.pi, finite=True)  # rad: rotate_recovery turns a full circle
    max_rotational_vel: float = param(1.0, gt=0)           # rad/s for rotate
    backup_dist: float = param(0.15, ge=0)                 # m for back_up
    wait_duration: float = param(1.0, ge=0)                # s for wait

    @property
    def recovery_order(self) -> tuple[str, ...]:
        """The behaviours actually run, in order (rotate only when clearing_rotation_allowed)."""
        if not self.recovery_behavior_enabled:
            return ()
        return tuple(n for n in self.recovery_behaviors if n != "rotate" or self.clearing_rotation_allowed)

    @classmethod
    def from_mapping(cls, values: dict | None, source: str = "navigator") -> NavigatorParams:
        """From our names or a ROS move_base parameter mapping (see the module's docstring)."""
        values = {k: v for k, v in unwrap_ros(values or {}, "move_base").items() if k not in ROS_IGNORED}
        entries = values.get("recovery_behaviors")
        if isinstance(entries, (list, tuple)) and any(isinstance(e, dict) for e in entries):
            values["recovery_behaviors"] = [_ros_recovery(e, source) for e in entries]
            for entry in entries:
                if isinstance(entry, dict) and isinstance(values.get(entry.get("name")), dict):
                    del values[entry["name"]]
        return load_params(cls, values, source)

    rules = (Rule("escape_vel", lambda p: p.escape_vel != 0 or p.backup_dist <= 0 or "back_up" not in p.recovery_behaviors,
                  "non-zero when back_up is a recovery behaviour"),)


def _ros_recovery(entry, source: str) -> str:
    """One move_base recovery_behaviors entry ({name, type}, or one of our names) as our name."""
    if not isinstance(entry, dict):
        return entry
    kind = entry.get("type")
    if kind not in ROS_RECOVERY_TYPES:
        raise ParamError(f"{source}: recovery_behaviors entry {entry!r}: type {kind!r} has no equivalent here; "
                         f"known: {sorted(ROS_RECOVERY_TYPES)} or the names {list(RECOVERY_NAMES)}")
    return ROS_RECOVERY_TYPES[kind]
