"""Every message that travels on the bus. SI units, radians, ROS field names where ROS has them.

2-D simplifications of ROS types: poses are (x, y, theta); covariances are 3×3 over (x, y, theta);
arrays of poses travel as one (N, 3) float64 array instead of a list of PoseStamped.

A type whose fields must agree with each other (a grid's size and its data, a scan's angles and its
ranges, a covariance's symmetry) has a `problem()` method: the codec calls it after decoding the
fields and refuses the payload with the (field, reason) it returns, so no consumer sees such a
message; None means the message is sound.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from .fields import array, real, sign_bytes
from .registry import message

Problem = tuple[str, str] | None        # (field, reason) of the first inconsistency, or None
WHEEL_COUNTS = {"mecanum": 4, "omni3": 3, "diff": 2}     # the drives and their driven wheels
SCAN_BEAM_SLACK = 1     # beams: drivers differ on whether angle_max is the last beam's angle or its end


def covariance_problem(name: str, cov: np.ndarray) -> Problem:
    # in Python: these matrices are 3 × 3 or 4 × 4 and checked on every decode, where numpy's
    # per-call overhead (np.allclose ~100 µs) was a fifth of a whole in-process mission
    rows = cov.tolist()
    if rows != cov.T.tolist():      # exactly symmetric, as most are, in one comparison of lists
        for i, row in enumerate(rows):
            for j in range(i + 1, len(rows)):
                a, b = row[j], rows[j][i]
                if a != b and abs(a - b) > 1e-12 + 1e-9 * abs(b):
                    return name, "is not symmetric"
    diagonal = [row[i] for i, row in enumerate(rows)]
    if any([variance < 0 for variance in diagonal]):
        return name, f"has a negative variance on its diagonal {diagonal}"
    return None


def same_length(names: tuple[str, ...], arrays: tuple[np.ndarray, ...]) -> Problem:
    """Arrays that describe the same items, one row each, must have as many rows."""
    for name, arr in zip(names[1:], arrays[1:]):
        if len(arr) != len(arrays[0]):
            return name, f"has {len(arr)} entries but {names[0]} has {len(arrays[0])}"
    return None


def wheels_problem(drive: str, velocities: np.ndarray) -> Problem:
    if drive not in WHEEL_COUNTS:
        return "drive", f"{drive!r} is not one of {list(WHEEL_COUNTS)}"
    if len(velocities) != WHEEL_COUNTS[drive]:
        return "velocities", f"{len(velocities)} wheel velocities for a {drive} drive of {WHEEL_COUNTS[drive]} wheels"
    return None


def grid_problem(info: "MapMetaData", data: np.ndarray) -> Problem:
    if not (math.isfinite(info.resolution) and info.resolution > 0):
        return "info.resolution", f"{info.resolution} is not a positive number of metres per cell"
    if data.shape != (info.height, info.width):
        return "data", f"shape {data.shape} does not match height × width = ({info.height}, {info.width})"
    return None


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

    def problem(self) -> Problem:
        return covariance_problem("pose_covariance", self.pose_covariance) or \
            covariance_problem("twist_covariance", self.twist_covariance)


@message("WheelCommand", 1)
@dataclass(slots=True)
class WheelCommand:
    header: Header = field(default_factory=Header)
    drive: str = "mecanum"                              # mecanum | omni3 | diff
    velocities: np.ndarray = array("<f8", (None,))      # rad/s, one per wheel

    def problem(self) -> Problem:
        return wheels_problem(self.drive, self.velocities)


@message("WheelState", 1)
@dataclass(slots=True)
class WheelState:
    header: Header = field(default_factory=Header)
    drive: str = "mecanum"
    positions: np.ndarray = array("<f8", (None,))       # encoder angle, rad, one per wheel
    velocities: np.ndarray = array("<f8", (None,))      # rad/s
    follower_positions: np.ndarray = array("<f8", (None,))  # passive follower-wheel encoders, rad
    gyro_z: float = 0.0                                 # yaw rate, rad/s

    def problem(self) -> Problem:
        return wheels_problem(self.drive, self.velocities) or \
            same_length(("velocities", "positions"), (self.velocities, self.positions))


@message("Imu", 1)
@dataclass(slots=True)
class Imu:
    """sensor_msgs/Imu as a planar robot needs it: the yaw rate and the acceleration in the plane,
    in the IMU's frame (header.frame_id). No orientation: a 2-D IMU integrates none (ROS says so
    with orientation_covariance[0] = -1). Gravity is not included: on a level floor it lies along
    z, which the plane drops, so x and y hold the body's own acceleration (REP 145's x and y).
    The variances are the diagonals of ROS's covariances: the white noise of one reading, never
    its bias."""
    header: Header = field(default_factory=Header)
    angular_velocity_z: float = 0.0                     # rad/s
    linear_acceleration_x: float = 0.0                  # m/s^2, forward
    linear_acceleration_y: float = 0.0                  # m/s^2, left
    angular_velocity_z_variance: float = 0.0            # (rad/s)^2: angular_velocity_covariance[8]
    linear_acceleration_x_variance: float = 0.0         # (m/s^2)^2: linear_acceleration_covariance[0]
    linear_acceleration_y_variance: float = 0.0         # (m/s^2)^2: linear_acceleration_covariance[4]

    def problem(self) -> Problem:
        for name in ("angular_velocity_z_variance", "linear_acceleration_x_variance", "linear_acceleration_y_variance"):
            if getattr(self, name) < 0:
                return name, f"{getattr(self, name)} is a negative variance"
        return None


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

    def problem(self) -> Problem:
        """REP 117: a range is a distance (≥ 0), +inf (no return) or NaN / −inf (no valid reading)."""
        if not (math.isfinite(self.angle_increment) and self.angle_increment != 0.0):
            return "angle_increment", f"{self.angle_increment} is not a non-zero finite angle"
        if not (math.isfinite(self.angle_min) and math.isfinite(self.angle_max)):
            return "angle_min", "the angles are not finite"
        beams = round((self.angle_max - self.angle_min) / self.angle_increment) + 1
        if beams < 0:
            return "angle_increment", (f"{self.angle_increment} runs away from angle_max "
                                       f"({self.angle_min} → {self.angle_max})")
        if abs(len(self.ranges) - beams) > SCAN_BEAM_SLACK:
            return "ranges", (f"{len(self.ranges)} ranges, but angle_min..angle_max in steps of angle_increment "
                              f"make {beams} beams")
        # no sign bit set: nothing below zero; else fmin, which skips NaN, is below zero only with a
        # negative number or -inf
        if len(self.ranges) and not sign_bytes(self.ranges).isascii() and np.fmin.reduce(self.ranges) < 0:
            negative = self.ranges[(self.ranges < 0) & np.isfinite(self.ranges)]
            if negative.size:
                return "ranges", f"{negative.size} negative range(s), e.g. {float(negative[0])}"
        if len(self.intensities) not in (0, len(self.ranges)):
            return "intensities", f"{len(self.intensities)} intensities for {len(self.ranges)} ranges"
        if not (self.range_min >= 0 and self.range_max >= self.range_min):
            return "range_max", f"range_min {self.range_min} .. range_max {self.range_max} is not a range"
        return None


@message("OccupancyGrid", 1)
@dataclass(slots=True)
class OccupancyGrid:
    header: Header = field(default_factory=Header)
    info: MapMetaData = field(default_factory=MapMetaData)
    # row-major (height, width); -1 unknown, 0..100 occupancy probability in percent
    data: np.ndarray = array("|i1", (None, None))

    def problem(self) -> Problem:
        if self.data.size and ((self.data < -1) | (self.data > 100)).any():
            return "data", "holds values outside -1 (unknown) and 0..100 (percent)"
        return grid_problem(self.info, self.data)


@message("Costmap", 1)
@dataclass(slots=True)
class Costmap:
    """A costmap_2d grid with its raw costs (ROS squeezes them into OccupancyGrid's 0..100; planners
    on the other side need the real values): 0 free .. 252 inflated, 253 inscribed, 254 lethal,
    255 unknown (NO_INFORMATION)."""
    header: Header = field(default_factory=Header)
    info: MapMetaData = field(default_factory=MapMetaData)
    data: np.ndarray = array("|u1", (None, None))       # row-major (height, width)

    def problem(self) -> Problem:
        return grid_problem(self.info, self.data)


@message("PoseWithCovariance", 1)
@dataclass(slots=True)
class PoseWithCovariance:
    header: Header = field(default_factory=Header)
    pose: Pose2D = field(default_factory=Pose2D)
    covariance: np.ndarray = array("<f8", (3, 3))

    def problem(self) -> Problem:
        return covariance_problem("covariance", self.covariance)


@message("PoseFit", 1)
@dataclass(slots=True)
class PoseFit:
    """How well a scan agrees with the map at the localizer's pose (no ROS equivalent): a pose the
    scans do not fit is one the localizer doubts, whatever its covariance says."""
    header: Header = field(default_factory=Header)   # the scan's stamp, the map frame
    beam_fit: float = 0.0      # share of the scan's used returns within beam_fit_distance of a mapped obstacle
    beams: int = 0             # returns counted

    def problem(self) -> Problem:
        if not 0.0 <= self.beam_fit <= 1.0:
            return "beam_fit", f"{self.beam_fit} is not a share between 0 and 1"
        return None if self.beams >= 0 else ("beams", f"{self.beams} returns is negative")


@message("OdometryDoubt", 1)
@dataclass(slots=True)
class OdometryDoubt:
    """The odometry fusion's verdict on its own estimate (no ROS equivalent: robot_localization only
    rejects a measurement): doubtful while the wheels, the gyro and the scans disagree beyond their
    noise (a slip, a push, a wheel off the ground). A navigator declares no goal reached on a pose
    built on doubtful odometry."""
    header: Header = field(default_factory=Header)   # the newest measurement judged, the odom frame
    doubtful: bool = False
    reason: str = ""           # which sources disagree and by how much; "" while not doubtful
    mahalanobis: float = 0.0   # the squared Mahalanobis distance of the worst recent innovation

    def problem(self) -> Problem:
        return None if self.mahalanobis >= 0 else ("mahalanobis", f"{self.mahalanobis} is negative")


@message("ParticleCloud", 1)
@dataclass(slots=True)
class ParticleCloud:
    header: Header = field(default_factory=Header)
    poses: np.ndarray = array("<f8", (None, 3))         # x, y, theta per particle
    weights: np.ndarray = array("<f8", (None,))

    def problem(self) -> Problem:
        if (self.weights < 0).any():
            return "weights", "holds a negative weight"
        return same_length(("poses", "weights"), (self.poses, self.weights))


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
    reason: str = ""           # why not, or what it did (e.g. "escape", GOAL_REACHED)


# LocalCommand.reason while the robot stands at the followed path's end within the local planner's
# tolerances; the navigator, which decides success, checks it against its own view of the robot
GOAL_REACHED = "goal_reached"
# the status that begins a failed Path's error when the goal cannot be reached on the map itself
# (global_planner/map_reach.py): no recovery can help, and the navigator aborts at once
PLAN_UNREACHABLE = "unreachable"


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

    def problem(self) -> Problem:
        if (self.circles[:, 2] < 0).any():
            return "circles", "holds a negative radius"
        return same_length(("circles", "velocities"), (self.circles, self.velocities))


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
    rate: float = 1.0                                   # sim seconds per wall second; 0: as fast as it may

    def problem(self) -> Problem:
        return None if self.rate >= 0 else ("rate", f"{self.rate} is not a rate (positive, or 0: unpaced)")


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

    def problem(self) -> Problem:
        return None if self.reset_distance >= 0 else ("reset_distance", f"{self.reset_distance} m is negative")


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
