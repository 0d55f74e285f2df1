"""The key layout: the only place that spells a key.

Robot keys are omninav/<robot>/<topic>; sim-wide keys are omninav/sim/<topic>; each service's
diagnostics go to omninav/<robot>/diagnostics/<service>. Every topic has exactly one message type.
"""
from __future__ import annotations

import re

from . import messages as m

ROOT = "omninav"
DEFAULT_ROBOT = "r1"
LOCKSTEP = "lockstep"
ALL = f"{ROOT}/**"

# topic -> message type, for keys under omninav/<robot>/
ROBOT_TOPICS: dict[str, type] = {
    "cmd_vel": m.Twist,                 # collision monitor -> chassis (the only one allowed to put it)
    "cmd_vel_nav": m.Twist,             # the navigator's command, into the command mux
    "cmd_vel_teleop": m.Twist,          # teleop's command, into the command mux (it wins over navigation)
    "cmd_vel_mux": m.Twist,             # command mux -> velocity smoother
    "cmd_vel_smoothed": m.Twist,        # velocity smoother -> collision monitor (which sends cmd_vel)
    "wheel_cmd": m.WheelCommand,        # chassis -> sim
    "wheel_state": m.WheelState,        # sim -> chassis
    "imu": m.Imu,                       # sim -> whoever fuses odometry: yaw rate, planar acceleration
    "odom": m.Odometry,
    "odom_follower": m.Odometry,        # follower-wheel + gyro odometry
    "odom_wheel": m.Odometry,           # the chassis's odometry when a fusion publishes odom (fused_odometry)
    "odom_laser": m.Odometry,           # laser odometry: scans matched to a local map, with covariance
    "odom_doubt": m.OdometryDoubt,      # the odometry fusion: do wheels, gyro and scans agree?
    "scan": m.LaserScan,
    "map": m.OccupancyGrid,
    "pose": m.PoseWithCovariance,       # amcl_pose / slam pose in the map frame
    "initialpose": m.PoseWithCovariance,
    "global_localization": m.PoseWithCovariance,  # request: particles over all free space (only the stamp counts)
    "particlecloud": m.ParticleCloud,
    "pose_fit": m.PoseFit,              # localizer: how well each scan fits the map at its pose
    "tf/map_odom": m.Transform,
    "tf/odom_base": m.Transform,
    "costmap/global": m.Costmap,
    "costmap/local": m.Costmap,
    "costmap/clear": m.ClearCostmaps,   # navigator recovery -> costmap
    "plan": m.Path,
    "plan_request": m.Goal,             # navigator -> global planner (goal_id "<goal>#<request>")
    "follow_path": m.Path,              # navigator -> local planner: the plan to follow (empty: stop)
    "local_cmd": m.LocalCommand,        # local planner -> navigator
    "local_plan": m.Path,
    "tracks": m.Tracks,                 # tracker -> local planner, collision monitor: moving obstacles (odom frame)
    "goal": m.Goal,
    "cancel": m.CancelGoal,
    "nav_status": m.NavStatus,
    "chatter": m.Chatter,
    "echo": m.Chatter,
}

# topic -> message type, for keys under omninav/sim/
SIM_TOPICS: dict[str, type] = {
    "clock": m.Clock,
    "movers": m.Obstacles,              # moving obstacles, for the simulated lidar
}
SIM_ROBOT_TOPICS: dict[str, type] = {
    "truth": m.Odometry,                # ground truth, for evaluation only: omninav/sim/<robot>/truth
}

_SEGMENT = re.compile(r"^[A-Za-z0-9_\-]+$")


def _check_segment(what: str, value: str) -> str:
    if not _SEGMENT.match(value):
        raise ValueError(f"{what} {value!r} must be letters, digits, '_' or '-'")
    return value


class KeyLayout:
    """Keys for one robot namespace."""

    def __init__(self, robot: str = DEFAULT_ROBOT):
        self.robot_name = _check_segment("robot namespace", robot)

    def robot(self, topic: str) -> str:
        if topic not in ROBOT_TOPICS:
            raise KeyError(f"unknown robot topic {topic!r}; known: {sorted(ROBOT_TOPICS)}")
        return f"{ROOT}/{self.robot_name}/{topic}"

    @staticmethod
    def sim(topic: str) -> str:
        if topic not in SIM_TOPICS:
            raise KeyError(f"unknown sim topic {topic!r}; known: {sorted(SIM_TOPICS)}")
        return f"{ROOT}/sim/{topic}"

    def sim_robot(self, topic: str) -> str:
        if topic not in SIM_ROBOT_TOPICS:
            raise KeyError(f"unknown sim robot topic {topic!r}; known: {sorted(SIM_ROBOT_TOPICS)}")
        return f"{ROOT}/sim/{self.robot_name}/{topic}"

    def diagnostics(self, service: str) -> str:
        return f"{ROOT}/{self.robot_name}/diagnostics/{_check_segment('service name', service)}"

    def diagnostics_of_all(self) -> str:
        """The key expression of every service's diagnostics (for a viewer of them all)."""
        return f"{ROOT}/{self.robot_name}/diagnostics/*"

    def lockstep(self, service: str) -> str:
        """Where a service reports its progress in a lockstep run (services/runtime/lockstep.py)."""
        return f"{ROOT}/{self.robot_name}/{LOCKSTEP}/{_check_segment('service name', service)}"

    def lockstep_of_all(self) -> str:
        return f"{ROOT}/{self.robot_name}/{LOCKSTEP}/*"

    def alive(self, service: str) -> str:
        """The liveliness token a running service declares once its inputs and outputs are in place."""
        return f"{ROOT}/{self.robot_name}/alive/{_check_segment('service name', service)}"

    def alive_of_all(self) -> str:
        """The key expression of every service's liveliness token (one query sees who is ready)."""
        return f"{ROOT}/{self.robot_name}/alive/*"

    @staticmethod
    def service_of_alive(key: str) -> str:
        """The service whose liveliness token (alive) this key is."""
        return key.rpartition("/")[2]

    def resolve(self, name: str) -> str:
        """A topic as services name it: 'scan', 'sim/clock', 'sim/truth' or a full key."""
        if name.startswith(f"{ROOT}/"):
            return name
        if name.startswith("sim/"):
            topic = name[4:]
            return self.sim_robot(topic) if topic in SIM_ROBOT_TOPICS else self.sim(topic)
        return self.robot(name)


def is_lockstep_key(key: str) -> bool:
    """A lockstep progress report: flow control between services, not data (the recorder skips it)."""
    parts = key.split("/")
    return len(parts) == 4 and parts[0] == ROOT and parts[2] == LOCKSTEP


def type_for_key(key: str) -> type | None:
    """The message type that a concrete key carries, or None if the layout does not know it."""
    parts = key.split("/")
    if len(parts) < 3 or parts[0] != ROOT:
        return None
    if parts[1] == "sim":
        rest = "/".join(parts[2:])
        if rest in SIM_TOPICS:
            return SIM_TOPICS[rest]
        return SIM_ROBOT_TOPICS.get("/".join(parts[3:])) if len(parts) >= 4 else None
    rest = "/".join(parts[2:])
    if parts[2] in ("diagnostics", LOCKSTEP) and len(parts) == 4:
        return m.Diagnostic
    return ROBOT_TOPICS.get(rest)
