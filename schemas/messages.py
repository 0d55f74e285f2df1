"""Every message that travels on the bus. SI units, radians, ROS field names where ROS has them.

2-D simplifications of ROS types: poses are (x, y, theta); covariances are 3×3 over (x, y, theta);
arrays of poses travel as one (N, 3) float64 array instead of a list of PoseStamped.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .fields import array, real
from .registry import message


@dataclass(slots=True)
class Header:
    stamp_ns: int = 0          # sim time of the data, nanoseconds
    frame_id: str = ""
    seq: int = 0               # set by the publishing node, one counter per key


@dataclass(slots=True)
class Pose2D:
    x: float = 0.0
    y: float = 0.0
    theta: float = 0.0


@dataclass(slots=True)
class MapMetaData:
    resolution: float = 0.05   # m / cell
    width: int = 0             # cells along x
    height: int = 0            # cells along y
    origin: Pose2D = field(default_factory=Pose2D)  # pose of cell (0, 0)'s corner in the map frame


@message("Twist", 1)
@dataclass(slots=True)
class Twist:
    """A velocity in the child (robot) frame, as geometry_msgs/TwistStamped reduced to the plane."""
    header: Header = field(default_factory=Header)
    linear_x: float = 0.0
    linear_y: float = 0.0
    angular_z: float = 0.0


@message("Odometry", 1)
@dataclass(slots=True)
class Odometry:
    header: Header = field(default_factory=Header)     # frame_id: odom
    child_frame_id: str = "base_link"
    pose: Pose2D = field(default_factory=Pose2D)
    twist: Twist = field(default_factory=Twist)
    pose_covariance: np.ndarray = array("<f8", (3, 3))
    twist_covariance: np.ndarray = array("<f8", (3, 3))


@message("WheelCommand", 1)
@dataclass(slots=True)
class WheelCommand:
    header: Header = field(default_factory=Header)
    drive: str = "mecanum"                              # mecanum | omni3 | diff
    velocities: np.ndarray = array("<f8", (None,))      # rad/s, one per wheel


@message("WheelState", 1)
@dataclass(slots=True)
class WheelState:
    header: Header = field(default_factory=Header)
    drive: str = "mecanum"
    positions: np.ndarray = array("<f8", (None,))       # encoder angle, rad, one per wheel
    velocities: np.ndarray = array("<f8", (None,))      # rad/s
    follower_positions: np.ndarray = array("<f8", (None,))  # passive follower-wheel encoders, rad
    gyro_z: float = 0.0                                 # yaw rate, rad/s


@message("LaserScan", 1)
@dataclass(slots=True)
class LaserScan:
    header: Header = field(default_factory=Header)
    angle_min: float = 0.0
    angle_max: float = 0.0
    angle_increment: float = 0.0
    time_increment: float = 0.0
    scan_time: float = 0.0
    range_min: float = 0.0
    range_max: float = 0.0
    # inf means no return within range_max, as in sensor_msgs/LaserScan (REP 117)
    ranges: np.ndarray = array("<f4", (None,), allow_nonfinite=True)
    intensities: np.ndarray = array("<f4", (None,))


@message("OccupancyGrid", 1)
@dataclass(slots=True)
class OccupancyGrid:
    header: Header = field(default_factory=Header)
    info: MapMetaData = field(default_factory=MapMetaData)
    # row-major (height, width); -1 unknown, 0..100 occupancy probability in percent
    data: np.ndarray = array("|i1", (None, None))


@message("Costmap", 1)
@dataclass(slots=True)
class Costmap:
    """A costmap_2d grid with its raw costs (ROS squeezes them into OccupancyGrid's 0..100; planners
    on the other side need the real values): 0 free .. 252 inflated, 253 inscribed, 254 lethal,
    255 unknown (NO_INFORMATION)."""
    header: Header = field(default_factory=Header)
    info: MapMetaData = field(default_factory=MapMetaData)
    data: np.ndarray = array("|u1", (None, None))       # row-major (height, width)


@message("PoseWithCovariance", 1)
@dataclass(slots=True)
class PoseWithCovariance:
    header: Header = field(default_factory=Header)
    pose: Pose2D = field(default_factory=Pose2D)
    covariance: np.ndarray = array("<f8", (3, 3))


@message("ParticleCloud", 1)
@dataclass(slots=True)
class ParticleCloud:
    header: Header = field(default_factory=Header)
    poses: np.ndarray = array("<f8", (None, 3))         # x, y, theta per particle
    weights: np.ndarray = array("<f8", (None,))


@message("Path", 2)
@dataclass(slots=True)
class Path:
    header: Header = field(default_factory=Header)
    poses: np.ndarray = array("<f8", (None, 3))         # x, y, theta per waypoint
    goal_id: str = ""          # the goal or plan request this path answers ("" when none)
    error: str = ""            # why there is no path ("status: reason"); empty when poses is the plan


@message("LocalCommand", 1)
@dataclass(slots=True)
class LocalCommand:
    """The local planner's answer for one control cycle (move_base's computeVelocityCommands)."""
    header: Header = field(default_factory=Header)     # stamp: the odometry it was computed on
    goal_id: str = ""          # goal_id of the followed path
    linear_x: float = 0.0      # body twist, m/s and rad/s
    linear_y: float = 0.0
    angular_z: float = 0.0
    ok: bool = True            # False: no valid command (the twist then brakes)
    reason: str = ""           # why not, or what it did (e.g. "escape")


@message("Transform", 1)
@dataclass(slots=True)
class Transform:
    """The pose of child_frame_id in header.frame_id (parent), as a TransformStamped."""
    header: Header = field(default_factory=Header)
    child_frame_id: str = ""
    transform: Pose2D = field(default_factory=Pose2D)


@message("Obstacles", 1)
@dataclass(slots=True)
class Obstacles:
    """Moving obstacles as circles, published by the sim so the lidar can see them."""
    header: Header = field(default_factory=Header)     # frame_id: world
    circles: np.ndarray = array("<f8", (None, 3))       # x, y, radius
    velocities: np.ndarray = array("<f8", (None, 2))    # vx, vy in the world frame


@message("Tracks", 1)
@dataclass(slots=True)
class Tracks:
    """Moving obstacles tracked from the scan (the tracker service), each a constant-velocity
    Kalman filter's estimate at the header's stamp, in the header's frame (odom)."""
    header: Header = field(default_factory=Header)
    ids: np.ndarray = array("<i8", (None,))             # stable over the track's life
    states: np.ndarray = array("<f8", (None, 4))        # x, y, vx, vy: m, m/s
    covariances: np.ndarray = array("<f8", (None, 4, 4))  # over (x, y, vx, vy)
    radii: np.ndarray = array("<f8", (None,))           # m, estimated from the clusters seen


@message("Clock", 1)
@dataclass(slots=True)
class Clock:
    header: Header = field(default_factory=Header)     # stamp_ns is the sim time
    rate: float = 1.0                                   # sim seconds per wall second


@message("Goal", 1)
@dataclass(slots=True)
class Goal:
    header: Header = field(default_factory=Header)     # frame_id: map
    goal_id: str = ""
    pose: Pose2D = field(default_factory=Pose2D)
    waypoints: np.ndarray = array("<f8", (None, 3))     # visited in order before `pose`


@message("CancelGoal", 1)
@dataclass(slots=True)
class CancelGoal:
    header: Header = field(default_factory=Header)
    goal_id: str = ""                                   # empty: cancel whatever is active


@message("ClearCostmaps", 1)
@dataclass(slots=True)
class ClearCostmaps:
    """A recovery's request: forget obstacles farther than reset_distance from the robot."""
    header: Header = field(default_factory=Header)
    reset_distance: float = 3.0    # m: the side of the square around the robot that is kept


@message("NavStatus", 1)
@dataclass(slots=True)
class NavStatus:
    header: Header = field(default_factory=Header)
    goal_id: str = ""
    status: str = "pending"    # pending | active | succeeded | aborted | canceled
    reason: str = ""           # why, when aborted or canceled
    distance_remaining: float = real(0.0, allow_nonfinite=True)


@message("Diagnostic", 1)
@dataclass(slots=True)
class Diagnostic:
    header: Header = field(default_factory=Header)
    name: str = ""             # the service
    level: int = 0             # 0 ok, 1 warn, 2 error (diagnostic_msgs/DiagnosticStatus)
    message: str = ""
    values: dict[str, float | int | str] = field(default_factory=dict)


@message("Chatter", 1)
@dataclass(slots=True)
class Chatter:
    """Demo traffic for the bus itself (talker/listener services)."""
    header: Header = field(default_factory=Header)
    text: str = ""
    value: float = 0.0
