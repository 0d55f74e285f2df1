"""The bridge's pure core: ROS 2 topics (CDR, through `rosbags`) to omninav messages and back.

In from the robot: /scan (sensor_msgs/LaserScan) -> scan, /odom (nav_msgs/Odometry) -> odom,
/goal_pose (geometry_msgs/PoseStamped, map frame) -> goal, /initialpose (RViz's "2D Pose Estimate",
geometry_msgs/PoseWithCovarianceStamped) -> initialpose, /tf and /tf_static (tf2_msgs/TFMessage):
the laser's mounting on base_link. Out to the robot: cmd_vel -> /cmd_vel (geometry_msgs/TwistStamped,
Jazzy's diff_drive_controller and Nav2 default, stamped with the bridge's clock in cmd_vel_frame_id; or
geometry_msgs/Twist with cmd_vel_type twist: the type is part of rmw_zenoh's key, so it must be the robot's),
map -> /map (nav_msgs/OccupancyGrid), pose -> /amcl_pose (geometry_msgs/PoseWithCovarianceStamped),
plan -> /plan (nav_msgs/Path), tf/map_odom -> /tf (map -> odom, as amcl broadcasts it: RViz then
places the robot's odom -> base_link in the map). Poses are projected to the plane as the bag importer does (x, y and
the quaternion's heading; the (x, y, yaw) rows and columns of 6 x 6 covariances) and lifted back
with z = 0, roll = pitch = 0.

Time: the robot's stamps are the stack's clock. omninav's services run on sim time from the clock
key, and on a real robot there is no simulator, so the bridge publishes a Clock at each new latest
stamp of the robot's scans and odometry, before the message that carries it (ROS time: wall time on
a robot, the simulator's with use_sim_time).

The laser mounting: the stack's services take it as parameters (laser_x, laser_y, laser_yaw), which
`omninav bridge ros2` finds before it starts them (laser_mounting, on what the robot sent: the chain
of transforms from its scans' frame to base_link) unless given --laser. The bridge is given the same
values and checks them against that chain on /tf and /tf_static as the robot goes on. A scan whose mounting there differs is not passed on (the
collision monitor then stops the robot, as without scans) and the mismatch is reported with the
values found; a scan whose frame /tf does not connect to base_link is passed on, counted.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ...schemas.messages import (Clock, Goal, Header, OccupancyGrid, Path, Pose2D, PoseWithCovariance, Transform,
                                 Twist)
from ..importers.rosbag import laser_scan, odometry, yaw_of
from ...geometry.se2 import compose
from .rmw import BEST_EFFORT, TRANSIENT_LOCAL, Qos
from ...parameters.declare import Parameters, param

NS_PER_S = 1_000_000_000
_PLANAR = (0, 1, 5)         # x, y, yaw among ROS's (x, y, z, roll, pitch, yaw) covariance axes


@dataclass(frozen=True)
class RosTopic:
    """One ROS topic the bridge speaks: its name, type, the omninav topic it maps to and the QoS
    it is offered or asked with (as the usual ROS 2 drivers and Nav2 do)."""
    name: str
    msgtype: str
    omninav: str
    qos: Qos = Qos()
    urgent: bool = False    # sent ahead of everything else the bridge sends (node.publisher_options)


INPUTS = (
    RosTopic("/scan", "sensor_msgs/msg/LaserScan", "scan", Qos(reliability=BEST_EFFORT, depth=5)),
    RosTopic("/odom", "nav_msgs/msg/Odometry", "odom"),
    RosTopic("/tf", "tf2_msgs/msg/TFMessage", "", Qos(depth=100)),
    RosTopic("/tf_static", "tf2_msgs/msg/TFMessage", "", Qos(durability=TRANSIENT_LOCAL, depth=1)),
    RosTopic("/goal_pose", "geometry_msgs/msg/PoseStamped", "goal"),
    RosTopic("/initialpose", "geometry_msgs/msg/PoseWithCovarianceStamped", "initialpose"),
)
# --cmd-vel-type: the /cmd_vel message; TwistStamped is what Jazzy's diff_drive_controller and Nav2 take
CMD_VEL_TYPES = {"twist_stamped": "geometry_msgs/msg/TwistStamped", "twist": "geometry_msgs/msg/Twist"}
DEFAULT_CMD_VEL_TYPE = "twist_stamped"


def ros_outputs(cmd_vel_type: str = DEFAULT_CMD_VEL_TYPE) -> tuple[RosTopic, ...]:
    """What the bridge publishes, with the QoS Nav2's publishers of those topics use (depth 1 for
    cmd_vel, map and amcl_pose; /map and /amcl_pose transient local, so a late RViz gets them)."""
    latched = Qos(durability=TRANSIENT_LOCAL, depth=1)
    return (
        RosTopic("/cmd_vel", CMD_VEL_TYPES[cmd_vel_type], "cmd_vel", Qos(depth=1), urgent=True),
        RosTopic("/map", "nav_msgs/msg/OccupancyGrid", "map", latched),
        RosTopic("/amcl_pose", "geometry_msgs/msg/PoseWithCovarianceStamped", "pose", latched),
        RosTopic("/plan", "nav_msgs/msg/Path", "plan"),
        RosTopic("/tf", "tf2_msgs/msg/TFMessage", "tf/map_odom", Qos(depth=100)),
    )


OUTPUTS = ros_outputs()


def typestore():
    """ROS 2 Jazzy's message definitions (rosbags: the optional [rosbag] extra)."""
    try:
        from rosbags.typesys import Stores, get_typestore
    except ImportError:
        raise RuntimeError("the ROS 2 bridge needs the rosbags package: pip install 'omninav[rosbag]'") from None
    return get_typestore(Stores.ROS2_JAZZY)


def stamp_ns(time) -> int:
    return int(time.sec) * NS_PER_S + int(time.nanosec)


def planar_pose(pose) -> Pose2D:
    p, q = pose.position, pose.orientation
    return Pose2D(float(p.x), float(p.y), yaw_of(q.x, q.y, q.z, q.w))


@dataclass
class Mounting:
    """The transforms seen on /tf and /tf_static, 2-D: child frame -> (parent frame, x, y, yaw), and the
    topic each came on."""
    edges: dict[str, tuple[str, tuple[float, float, float]]] = field(default_factory=dict)
    topics: dict[str, str] = field(default_factory=dict)

    def update(self, tf_message, topic: str = "/tf") -> None:
        for t in tf_message.transforms:
            v, q = t.transform.translation, t.transform.rotation
            child = t.child_frame_id.lstrip("/")
            self.edges[child] = (t.header.frame_id.lstrip("/"), (float(v.x), float(v.y), yaw_of(q.x, q.y, q.z, q.w)))
            self.topics[child] = topic

    def frames(self) -> list[str]:
        return sorted({*self.edges, *(parent for parent, _ in self.edges.values())})

    def chain(self, frame: str, base: str) -> list[str] | None:
        """The frames from `frame` up its parents to `base`, or None if they do not get there."""
        frames = [frame.lstrip("/")]
        while frames[-1] != base:
            if frames[-1] not in self.edges or len(frames) > len(self.edges):    # a gap, or a cycle
                return None
            frames.append(self.edges[frames[-1]][0])
        return frames

    def in_frame(self, frame: str, base: str) -> tuple[float, float, float] | None:
        """The pose of `frame` in `base` by the chain of transforms, or None if it does not connect."""
        frames = self.chain(frame, base)
        if frames is None:
            return None
        pose = np.zeros(3)
        for child in frames[:-1]:
            pose = compose(np.asarray(self.edges[child][1]), pose)
        return float(pose[0]), float(pose[1]), float(pose[2])


def laser_mounting(scan_frame: str | None, mounting: Mounting, base: str) -> tuple[tuple[float, float, float], str]:
    """The laser's pose on `base` from what the robot has sent so far (the frame of its scans, None before
    the first, and its transforms), with how it was found ("/tf_static: base_link -> laser");
    LookupError naming what is still missing."""
    if scan_frame is None:
        raise LookupError("no /scan seen (its frame_id names the laser's frame)")
    frames = mounting.chain(scan_frame, base)
    if frames is None:
        seen = ", ".join(mounting.frames()) or "none"
        raise LookupError(f"no chain of transforms from frame {scan_frame!r} to {base!r} on /tf or /tf_static "
                          f"(frames seen: {seen})")
    topics = " and ".join(sorted({mounting.topics[child] for child in frames[:-1]})) or "/scan"
    return mounting.in_frame(scan_frame, base), f"{topics}: {' -> '.join(reversed(frames))}"


@dataclass(frozen=True)
class Ros2BridgeParams(Parameters):
    """The robot's ROS 2 side (domain, router, who the bridge is on its graph), its frames and the laser
    mounting the stack's services are configured with."""
    domain: int = 0                     # the robot's ROS_DOMAIN_ID
    ros_router: str = "tcp/127.0.0.1:7447"  # the robot's rmw_zenoh router, reached on loopback
    # how the bridge logs in to the robot's router, as rmw_zenoh's security does (zenoh_config.checked_login_config)
    ros_zenoh_config: str = ""          # a Zenoh JSON5 config file (usrpwd, TLS; its connect/endpoints over ros_router)
    ros_user: str = ""                  # usrpwd user, with ros_password_file (a file holding the password alone)
    ros_password_file: str = ""
    node_name: str = "omninav_bridge"
    namespace: str = "/"
    base_frame: str = "base_link"
    map_frame: str = "map"
    cmd_vel_type: str = param(DEFAULT_CMD_VEL_TYPE, choices=tuple(CMD_VEL_TYPES))  # the robot's /cmd_vel type
    cmd_vel_frame_id: str = "base_link"     # a TwistStamped's header.frame_id
    laser_x: float = 0.0
    laser_y: float = 0.0
    laser_yaw: float = 0.0
    mount_tolerance: float = 0.01       # m and rad: /tf's mounting may differ this much from laser_*


class Bridge:
    """Converts one sample at a time; keeps the clock, the goal counter and the transforms."""

    def __init__(self, params: Ros2BridgeParams):
        self.params = params
        self.outputs = ros_outputs(params.cmd_vel_type)
        self.store = typestore()
        self.types = self.store.types
        self.mounting = Mounting()
        self.clock_ns: int | None = None
        self.goals = 0
        self.problems: list[str] = []       # what went wrong with the last input (the node logs and counts it)
        self.counts: dict[str, int] = {}

    # ------------------------------------------------------------ from the robot

    def from_ros(self, topic: RosTopic, payload: bytes) -> list[tuple[str, object]]:
        """The omninav (topic, message) pairs one ROS sample becomes, a clock first where time advanced."""
        self.problems = []
        msg = self.store.deserialize_cdr(payload, topic.msgtype)
        if topic.msgtype == "tf2_msgs/msg/TFMessage":
            self.mounting.update(msg, topic.name)
            return []
        if topic.omninav == "goal":
            return self._goal(msg)
        if topic.omninav == "initialpose":
            return self._initial_pose(msg)
        stamp = stamp_ns(msg.header.stamp)
        if topic.omninav == "scan":
            if not self._mount_agrees(msg.header.frame_id):
                return []
            out = laser_scan(msg, stamp)
        else:
            out = odometry(msg, stamp)
        return [*self._tick(stamp), (topic.omninav, out)]

    def _tick(self, stamp: int) -> list[tuple[str, object]]:
        if self.clock_ns is not None and stamp <= self.clock_ns:
            return []
        self.clock_ns = stamp
        return [("sim/clock", Clock(header=Header(stamp_ns=stamp)))]

    def _mount_agrees(self, frame: str) -> bool:
        p = self.params
        found = self.mounting.in_frame(frame, p.base_frame)
        if found is None:
            self._count("scans_without_tf_mounting")
            return True
        x, y, yaw = found
        off = max(abs(x - p.laser_x), abs(y - p.laser_y), abs(math.remainder(yaw - p.laser_yaw, math.tau)))
        if off <= p.mount_tolerance:
            self._count("scans_mounting_checked")
            return True
        self._count("scans_dropped_mounting")
        self.problems.append(f"/tf mounts {frame!r} on {p.base_frame!r} at x={x:.4f} y={y:.4f} yaw={yaw:.4f}, but "
                             f"the stack is configured with laser_x={p.laser_x} laser_y={p.laser_y} "
                             f"laser_yaw={p.laser_yaw}: set those in the compose file; scans are held back")
        return False

    def _request_header(self, msg, topic: str) -> Header | None:
        """A request's header in the map frame, stamped now at the earliest (a goal stamped 0, as
        `ros2 topic pub` sends it, or in the past takes effect now); None when in another frame."""
        frame = msg.header.frame_id.lstrip("/") or self.params.map_frame
        if frame != self.params.map_frame:
            self.problems.append(f"{topic} in frame {frame!r}: only poses in {self.params.map_frame!r} are taken")
            return None
        return Header(stamp_ns=max(stamp_ns(msg.header.stamp), self.clock_ns or 0), frame_id=frame)

    def _goal(self, msg) -> list[tuple[str, object]]:
        header = self._request_header(msg, "/goal_pose")
        if header is None:
            return []
        self.goals += 1
        return [("goal", Goal(header=header, goal_id=f"ros2-{self.goals}", pose=planar_pose(msg.pose)))]

    def _initial_pose(self, msg) -> list[tuple[str, object]]:
        header = self._request_header(msg, "/initialpose")
        if header is None:
            return []
        covariance = np.asarray(msg.pose.covariance, np.float64).reshape(6, 6)[np.ix_(_PLANAR, _PLANAR)]
        return [("initialpose", PoseWithCovariance(header=header, pose=planar_pose(msg.pose.pose),
                                                   covariance=np.ascontiguousarray(covariance)))]

    def _count(self, what: str) -> None:
        self.counts[what] = self.counts.get(what, 0) + 1

    # ------------------------------------------------------------ to the robot

    def to_ros(self, topic: RosTopic, msg) -> bytes:
        build = {"cmd_vel": self._twist, "map": self._grid, "pose": self._pose, "plan": self._path,
                 "tf/map_odom": self._transform}[topic.omninav]
        return bytes(self.store.serialize_cdr(build(msg), topic.msgtype))

    def _header(self, header: Header, frame: str | None = None):
        t = self.types
        sec, nanosec = divmod(header.stamp_ns, NS_PER_S)
        return t["std_msgs/msg/Header"](stamp=t["builtin_interfaces/msg/Time"](sec=sec, nanosec=nanosec),
                                        frame_id=frame if frame is not None else header.frame_id)

    def _pose3d(self, x: float, y: float, theta: float):
        t = self.types
        return t["geometry_msgs/msg/Pose"](
            position=t["geometry_msgs/msg/Point"](x=float(x), y=float(y), z=0.0),
            orientation=t["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=math.sin(theta / 2), w=math.cos(theta / 2)))

    def _twist(self, msg: Twist):
        t = self.types
        vector = t["geometry_msgs/msg/Vector3"]
        twist = t["geometry_msgs/msg/Twist"](linear=vector(x=msg.linear_x, y=msg.linear_y, z=0.0),
                                             angular=vector(x=0.0, y=0.0, z=msg.angular_z))
        if self.params.cmd_vel_type == "twist":
            return twist
        # stamped now by the robot's clock, not by the scan the command came from: diff_drive_controller
        # drops a command older than its cmd_vel_timeout (0.5 s) by that stamp
        now = Header(stamp_ns=self.command_stamp_ns(msg))
        return t["geometry_msgs/msg/TwistStamped"](header=self._header(now, self.params.cmd_vel_frame_id), twist=twist)

    def command_stamp_ns(self, msg: Twist) -> int:
        """A command's stamp on the robot: the latest of its own and the bridge's clock."""
        return max(msg.header.stamp_ns, self.clock_ns or 0)

    def _grid(self, msg: OccupancyGrid):
        t, info = self.types, msg.info
        meta = t["nav_msgs/msg/MapMetaData"](
            map_load_time=self._header(msg.header).stamp, resolution=float(info.resolution), width=int(info.width),
            height=int(info.height), origin=self._pose3d(info.origin.x, info.origin.y, info.origin.theta))
        return t["nav_msgs/msg/OccupancyGrid"](header=self._header(msg.header, msg.header.frame_id or "map"),
                                               info=meta, data=np.ascontiguousarray(msg.data, np.int8).ravel())

    def _pose(self, msg: PoseWithCovariance):
        t = self.types
        covariance = np.zeros((6, 6))
        covariance[np.ix_(_PLANAR, _PLANAR)] = msg.covariance
        with_cov = t["geometry_msgs/msg/PoseWithCovariance"](pose=self._pose3d(msg.pose.x, msg.pose.y, msg.pose.theta),
                                                             covariance=covariance.ravel())
        return t["geometry_msgs/msg/PoseWithCovarianceStamped"](header=self._header(msg.header), pose=with_cov)

    def _transform(self, msg: Transform):
        t, pose = self.types, msg.transform
        stamped = t["geometry_msgs/msg/TransformStamped"](
            header=self._header(msg.header), child_frame_id=msg.child_frame_id,
            transform=t["geometry_msgs/msg/Transform"](
                translation=t["geometry_msgs/msg/Vector3"](x=float(pose.x), y=float(pose.y), z=0.0),
                rotation=self._pose3d(0.0, 0.0, pose.theta).orientation))
        return t["tf2_msgs/msg/TFMessage"](transforms=[stamped])

    def _path(self, msg: Path):
        t = self.types
        header = self._header(msg.header, msg.header.frame_id or self.params.map_frame)
        poses = [t["geometry_msgs/msg/PoseStamped"](header=header, pose=self._pose3d(*pose)) for pose in msg.poses]
        return t["nav_msgs/msg/Path"](header=header, poses=poses)

