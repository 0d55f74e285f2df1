"""Where the robot is in the odom and map frames, for the costmap and planner nodes (there is no tf
tree: odometry gives odom→base_link, tf/map_odom gives map→odom).

Until a localizer publishes map→odom, it is `start`: the pose in the map of the odom frame's
origin, i.e. where the robot stood when odometry started (the chassis starts odometry at zero),
as if odometry were exact. In the sim that is the world's robot start; a localizer replaces it.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..schemas.messages import Header, LaserScan, Odometry, Pose2D, PoseWithCovariance, Transform, Twist
from .se2 import compose, inverse
from ..parameters.declare import Parameters, param


# (x, y, yaw) of the laser in base_link (m, m, rad): the simulated lidar's mount, and the default of
# every node that places scan points on the robot
LASER_MOUNT = (0.0, 0.0, 0.0)
INF_EPSILON = 0.0001     # m: ROS replaces +inf by range_max − this when inf_is_valid


class RobotFrames:
    def __init__(self, map_frame: str, odom_frame: str, start=(0.0, 0.0, 0.0)):
        self.map_frame, self.odom_frame = map_frame, odom_frame
        self.map_odom = np.asarray(start, np.float64)
        self.odom: np.ndarray | None = None       # the robot in the odom frame, latest odometry
        self.odom_stamp_ns: int | None = None

    def check_frame(self, frame: str, owner: str) -> None:
        if frame not in (self.map_frame, self.odom_frame):
            raise ValueError(f"{owner}: frame {frame!r} is neither the map frame {self.map_frame!r} nor the "
                             f"odom frame {self.odom_frame!r}")

    def set_odom(self, msg: Odometry) -> None:
        self.odom = np.array([msg.pose.x, msg.pose.y, msg.pose.theta])
        self.odom_stamp_ns = msg.header.stamp_ns

    def transform_problem(self, msg: Transform) -> str:
        """Why a map→odom transform cannot be used, or ''."""
        frames = (msg.header.frame_id, msg.child_frame_id)
        if frames != (self.map_frame, self.odom_frame):
            return f"transform from {frames[0]!r} to {frames[1]!r}, expected {self.map_frame!r} to {self.odom_frame!r}"
        return ""

    def set_map_odom(self, msg: Transform) -> None:
        self.map_odom = np.array([msg.transform.x, msg.transform.y, msg.transform.theta])

    def in_frame(self, frame: str, pose_in_odom) -> np.ndarray:
        """A pose given in the odom frame, expressed in `frame` (the map or the odom frame)."""
        if frame == self.odom_frame:
            return np.asarray(pose_in_odom, np.float64)
        return compose(self.map_odom, pose_in_odom)

    def carry(self, poses, source: str, target: str) -> np.ndarray:
        """Poses (N, 3) given in the map or odom frame, in the other one (or the same, unchanged)."""
        poses = np.asarray(poses, np.float64).reshape(-1, 3)
        if source == target:
            return poses
        return compose(self.map_odom, poses) if target == self.map_frame else compose(inverse(self.map_odom), poses)

    def robot(self, frame: str) -> np.ndarray | None:
        """The robot's latest pose in `frame`, or None before any odometry."""
        return None if self.odom is None else self.in_frame(frame, self.odom)

    def robot_with_pose(self, frame: str, pose: PoseWithCovariance | None) -> np.ndarray | None:
        """The robot in `frame`: a localizer's pose (map frame) when it is newer than the odometry,
        else the odometry carried into `frame`; None before either."""
        if pose is not None and frame == self.map_frame and (
                self.odom_stamp_ns is None or pose.header.stamp_ns > self.odom_stamp_ns):
            return np.array([pose.pose.x, pose.pose.y, pose.pose.theta])
        return self.robot(frame)

    def frame_in_map(self, frame: str) -> Pose2D | None:
        """The pose of `frame` in the map frame (None: it is the map frame)."""
        if frame == self.map_frame:
            return None
        x, y, theta = (float(v) for v in self.map_odom)
        return Pose2D(x, y, theta)


@dataclass(frozen=True)
class FrameParams(Parameters):
    """The frame parameters of a node that places the robot with RobotFrames (a mixin of its Params)."""
    initial_pose_x: float = param(0.0, finite=True)  # the odom frame's pose in the map (where odometry started) until tf/map_odom
    initial_pose_y: float = param(0.0, finite=True)
    initial_pose_a: float = param(0.0, finite=True)
    map_frame: str = "map"
    odom_frame: str = "odom"

    def robot_frames(self) -> RobotFrames:
        return RobotFrames(self.map_frame, self.odom_frame, (self.initial_pose_x, self.initial_pose_y,
                                                             self.initial_pose_a))


def twist_vector(msg: Twist) -> np.ndarray:
    """A Twist as (vx, vy, wz), base_link."""
    return np.array([msg.linear_x, msg.linear_y, msg.angular_z])


def twist_message(twist: np.ndarray, stamp_ns: int) -> Twist:
    """(vx, vy, wz) as a Twist in base_link."""
    vx, vy, wz = (float(v) for v in twist)
    return Twist(header=Header(stamp_ns=stamp_ns, frame_id="base_link"), linear_x=vx, linear_y=vy, angular_z=wz)


def scan_points(scan: LaserScan, sensor_pose, inf_is_valid: bool) -> np.ndarray:
    """A scan's endpoints in the global frame, as laser_geometry projects them: readings within
    [range_min, range_max) (with inf_is_valid, +inf counts as range_max − 0.0001)."""
    ranges = np.asarray(scan.ranges, np.float64)
    if inf_is_valid:
        ranges = np.where(np.isposinf(ranges), scan.range_max - INF_EPSILON, ranges)
    angles = scan.angle_min + np.arange(ranges.shape[0]) * scan.angle_increment
    with np.errstate(invalid="ignore"):
        keep = np.isfinite(ranges) & (ranges >= scan.range_min) & (ranges < scan.range_max)
    x, y, yaw = (float(v) for v in sensor_pose)
    r, a = ranges[keep], angles[keep] + yaw
    return np.stack([x + r * np.cos(a), y + r * np.sin(a)], axis=1)
