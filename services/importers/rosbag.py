"""ROS 1 and ROS 2 bags as omninav messages: sensor_msgs/LaserScan and nav_msgs/Odometry.

Bags are read with the `rosbags` package (an optional extra: pip install 'omninav[rosbag]'), whose
AnyReader opens ROS 1 .bag files and ROS 2 bag folders (.db3 or .mcap) alike and needs no ROS.

Stamps come from the message headers (a message whose header stamp is zero takes the time the bag
recorded it at, and is counted). Odometry is projected to 2-D: x, y of the position, the yaw of the
orientation quaternion (the rotation about z that the quaternion's heading makes, for any
normalisation), the body twist's linear x, y and angular z, and the (x, y, yaw) rows and columns
of the 6×6 covariances. LaserScan fields map one to one; ranges stay as recorded (ROS drivers
already write +inf for no return, REP 117).
"""
from __future__ import annotations

import math
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ...schemas.messages import Header, LaserScan, Odometry, Pose2D, Twist

SCAN_TYPE = "sensor_msgs/msg/LaserScan"
ODOM_TYPE = "nav_msgs/msg/Odometry"
_PLANAR = [0, 1, 5]         # x, y, yaw among ROS's (x, y, z, roll, pitch, yaw) covariance axes


class RosbagError(ValueError):
    """A bag that cannot be converted (missing, unreadable, without the topics asked for)."""


@dataclass
class BagContents:
    scans: list[LaserScan] = field(default_factory=list)
    odometry: list[Odometry] = field(default_factory=list)
    topics: dict[str, tuple[str, int]] = field(default_factory=dict)    # every topic: (type, messages)
    unstamped: Counter = field(default_factory=Counter)                 # topic -> header stamps of zero


def yaw_of(x: float, y: float, z: float, w: float) -> float:
    """The heading (rotation about z) of a quaternion; exact for a planar one, any norm."""
    return math.atan2(2.0 * (w * z + x * y), w * w + x * x - y * y - z * z)


def _stamp(header, record_ns: int, topic: str, contents: BagContents) -> int:
    stamp = int(header.stamp.sec) * 1_000_000_000 + int(header.stamp.nanosec)
    if stamp == 0:
        contents.unstamped[topic] += 1
        return int(record_ns)
    return stamp


def _planar(covariance) -> np.ndarray:
    full = np.asarray(covariance, np.float64).reshape(6, 6)
    return np.ascontiguousarray(full[np.ix_(_PLANAR, _PLANAR)])


def laser_scan(msg, stamp_ns: int) -> LaserScan:
    return LaserScan(header=Header(stamp_ns=stamp_ns, frame_id=msg.header.frame_id),
                     angle_min=float(msg.angle_min), angle_max=float(msg.angle_max),
                     angle_increment=float(msg.angle_increment), time_increment=float(msg.time_increment),
                     scan_time=float(msg.scan_time), range_min=float(msg.range_min), range_max=float(msg.range_max),
                     ranges=np.asarray(msg.ranges, np.float32), intensities=np.asarray(msg.intensities, np.float32))


def odometry(msg, stamp_ns: int) -> Odometry:
    p, q = msg.pose.pose.position, msg.pose.pose.orientation
    v, w = msg.twist.twist.linear, msg.twist.twist.angular
    return Odometry(header=Header(stamp_ns=stamp_ns, frame_id=msg.header.frame_id), child_frame_id=msg.child_frame_id,
                    pose=Pose2D(float(p.x), float(p.y), yaw_of(q.x, q.y, q.z, q.w)),
                    twist=Twist(header=Header(stamp_ns=stamp_ns, frame_id=msg.child_frame_id), linear_x=float(v.x),
                                linear_y=float(v.y), angular_z=float(w.z)),
                    pose_covariance=_planar(msg.pose.covariance), twist_covariance=_planar(msg.twist.covariance))


def read_bag(path: str | Path, scan_topic: str = "/scan", odom_topic: str = "/vesc/odom") -> BagContents:
    """The scans and odometry of a bag, each list in stamp order (RosbagError says what is wrong)."""
    path = Path(path)
    if not path.exists():
        raise RosbagError(f"{path}: no such file or folder")
    try:
        from rosbags.highlevel import AnyReader, AnyReaderError
        from rosbags.rosbag1 import ReaderError as Ros1Error
        from rosbags.rosbag2 import ReaderError as Ros2Error
        from rosbags.serde import SerdeError
    except ImportError:
        raise RosbagError("reading ROS bags needs the rosbags package: pip install 'omninav[rosbag]'") from None
    contents = BagContents()
    try:
        with AnyReader([path]) as reader:
            for conn in reader.connections:
                kind, count = contents.topics.get(conn.topic, (conn.msgtype, 0))
                contents.topics[conn.topic] = (kind, count + conn.msgcount)
            for topic, wanted in ((scan_topic, SCAN_TYPE), (odom_topic, ODOM_TYPE)):
                if topic not in contents.topics:
                    listed = ", ".join(f"{t} ({k})" for t, (k, _) in sorted(contents.topics.items())) or "none"
                    raise RosbagError(f"{path}: no topic {topic} (the bag has: {listed})")
                if contents.topics[topic][0] != wanted:
                    raise RosbagError(f"{path}: topic {topic} carries {contents.topics[topic][0]}, not {wanted}")
            used = [c for c in reader.connections if c.topic in (scan_topic, odom_topic)]
            for conn, record_ns, raw in reader.messages(connections=used):
                msg = reader.deserialize(raw, conn.msgtype)
                stamp = _stamp(msg.header, record_ns, conn.topic, contents)
                if conn.topic == scan_topic:
                    contents.scans.append(laser_scan(msg, stamp))
                else:
                    contents.odometry.append(odometry(msg, stamp))
    except (AnyReaderError, Ros1Error, Ros2Error, SerdeError, OSError) as exc:
        raise RosbagError(f"{path}: not a readable ROS 1 or ROS 2 bag: {exc}") from None
    contents.scans.sort(key=lambda m: m.header.stamp_ns)
    contents.odometry.sort(key=lambda m: m.header.stamp_ns)
    return contents


def keyed_messages(contents: BagContents, keys) -> list[tuple[str, object]]:
    """(key, message) pairs in stamp order, scans before odometry of the same stamp (a KeyLayout's keys)."""
    messages = [(keys.robot("scan"), s) for s in contents.scans] + [(keys.robot("odom"), o) for o in contents.odometry]
    messages.sort(key=lambda item: item[1].header.stamp_ns)   # stable
    return messages
