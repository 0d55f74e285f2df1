"""ROS 1 and ROS 2 bags as omninav messages: sensor_msgs/LaserScan and nav_msgs/Odometry.

Bags are read with the `rosbags` package (an optional extra: pip install 'omninav[rosbag]'), whose
AnyReader opens ROS 1 .bag files and ROS 2 bag folders (.db3 or .mcap) alike and needs no ROS.

Topics not named are found by type: the bag's one LaserScan topic, its one Odometry topic (a bag
with several of a type must name the one to use). A bag without an Odometry topic gives its
odometry from /tf instead, as REP 105 lays it out: the transforms from `odom` to the one frame
it is the parent of there (the robot's base), the twist the body-frame motion between consecutive
ones. The laser's mounting on the robot — the scans' frame in the base frame — is read from
/tf_static and /tf when the bag has those transforms (`BagContents.laser_pose`).

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

from ...geometry.se2 import compose, inverse, relative
from ...schemas.messages import Header, LaserScan, Odometry, Pose2D, Twist

SCAN_TYPE = "sensor_msgs/msg/LaserScan"
ODOM_TYPE = "nav_msgs/msg/Odometry"
TF_TYPE = "tf2_msgs/msg/TFMessage"
TF_TOPICS = ("/tf", "/tf_static")
ODOM_FRAME = "odom"                 # REP 105's name of the odometry frame
_PLANAR = [0, 1, 5]         # x, y, yaw among ROS's (x, y, z, roll, pitch, yaw) covariance axes

Pose2 = tuple[float, float, float]  # x, y, yaw of a frame in its parent


class RosbagError(ValueError):
    """A bag that cannot be converted (missing, unreadable, without the topics asked for)."""


@dataclass
class BagContents:
    scans: list[LaserScan] = field(default_factory=list)
    odometry: list[Odometry] = field(default_factory=list)
    topics: dict[str, tuple[str, int]] = field(default_factory=dict)    # every topic: (type, messages)
    unstamped: Counter = field(default_factory=Counter)                 # topic -> header stamps of zero
    scan_topic: str = ""
    odom_source: str = ""           # the Odometry topic, or where on /tf the odometry came from
    used_topics: tuple[str, ...] = ()
    laser_pose: Pose2 | None = None  # the scans' frame in the robot's base frame, when the bag's tf has it


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


def _frame(name: str) -> str:
    return name.lstrip("/")         # ROS 1 frames may carry tf_prefix's leading slash


def _planar_transform(transform) -> Pose2:
    t, q = transform.translation, transform.rotation
    return float(t.x), float(t.y), yaw_of(q.x, q.y, q.z, q.w)


def _chain(links: dict[tuple[str, str], Pose2], start: str, end: str) -> Pose2 | None:
    """Frame `end` in frame `start` through the known transforms (parent, child) -> child in parent,
    walked either way; None when they do not join the two."""
    steps: dict[str, list[tuple[str, Pose2]]] = {}
    for (parent, child), pose in links.items():
        steps.setdefault(parent, []).append((child, pose))
        steps.setdefault(child, []).append((parent, inverse(pose)))
    found: dict[str, np.ndarray] = {start: np.zeros(3)}
    todo = [start]
    while todo:
        frame = todo.pop()
        for other, pose in steps.get(frame, ()):
            if other not in found:
                found[other] = compose(found[frame], pose)
                todo.append(other)
    return tuple(float(v) for v in found[end]) if end in found else None


def _one_topic(path: Path, topics: dict[str, tuple[str, int]], wanted: str, option: str) -> list[str]:
    """The topics carrying `wanted`; a RosbagError when there are several (the user must choose)."""
    found = sorted(t for t, (kind, _) in topics.items() if kind == wanted)
    if len(found) > 1:
        raise RosbagError(f"{path}: several {wanted} topics ({', '.join(found)}): name the one to use with {option}")
    return found


def _listed(topics: dict[str, tuple[str, int]]) -> str:
    """The bag's topics and their types, for an error."""
    return ", ".join(f"{t} ({k})" for t, (k, _) in sorted(topics.items())) or "none"


def _check_topic(path: Path, topics: dict[str, tuple[str, int]], topic: str, wanted: str) -> None:
    if topic not in topics:
        raise RosbagError(f"{path}: no topic {topic} (the bag has: {_listed(topics)})")
    if topics[topic][0] != wanted:
        raise RosbagError(f"{path}: topic {topic} carries {topics[topic][0]}, not {wanted}")


def tf_odometry(transforms: list[tuple[int, Pose2]], base: str) -> list[Odometry]:
    """Odometry messages from the (stamp, odom → base transform) of a bag's /tf, in stamp order: the
    twist of each is the body-frame motion since the one before (zero for the first); transforms
    that repeat a stamp are dropped."""
    out: list[Odometry] = []
    last: tuple[int, Pose2] | None = None
    for stamp, pose in sorted(transforms, key=lambda item: item[0]):
        if last is not None and stamp <= last[0]:
            continue
        vx = vy = wz = 0.0
        if last is not None:
            dt = (stamp - last[0]) * 1e-9
            vx, vy, wz = (float(v) / dt for v in relative(last[1], pose))
        out.append(Odometry(header=Header(stamp_ns=stamp, frame_id=ODOM_FRAME), child_frame_id=base,
                            pose=Pose2D(*pose), twist=Twist(header=Header(stamp_ns=stamp, frame_id=base),
                                                            linear_x=vx, linear_y=vy, angular_z=wz),
                            pose_covariance=np.zeros((3, 3)), twist_covariance=np.zeros((3, 3))))
        last = stamp, pose
    return out


@dataclass
class _Transforms:
    """What a bag's /tf and /tf_static say: each link's first transform (mountings are fixed), and
    every odom → child transform with its stamp."""
    links: dict[tuple[str, str], Pose2] = field(default_factory=dict)
    from_odom: dict[str, list[tuple[int, Pose2]]] = field(default_factory=dict)

    def take(self, msg, record_ns: int, topic: str, contents: BagContents) -> None:
        for transform in msg.transforms:
            parent, child = _frame(transform.header.frame_id), _frame(transform.child_frame_id)
            pose = _planar_transform(transform.transform)
            self.links.setdefault((parent, child), pose)
            if parent == ODOM_FRAME and topic == "/tf":
                self.from_odom.setdefault(child, []).append((_stamp(transform.header, record_ns, topic, contents), pose))


def read_bag(path: str | Path, scan_topic: str | None = None, odom_topic: str | None = None) -> BagContents:
    """The scans and odometry of a bag, each list in stamp order (RosbagError says what is wrong).
    A topic not given is the bag's one topic of its type; without an Odometry topic, odometry comes
    from /tf (module docstring)."""
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
    transforms = _Transforms()
    try:
        with AnyReader([path]) as reader:
            for conn in reader.connections:
                kind, count = contents.topics.get(conn.topic, (conn.msgtype, 0))
                contents.topics[conn.topic] = (kind, count + conn.msgcount)
            topics = contents.topics
            if scan_topic is None:
                found = _one_topic(path, topics, SCAN_TYPE, "--scan-topic")
                scan_topic = found[0] if found else "/scan"
            _check_topic(path, topics, scan_topic, SCAN_TYPE)
            tf_topics = tuple(t for t in TF_TOPICS if topics.get(t, ("", 0))[0] == TF_TYPE)
            if odom_topic is None:
                found = _one_topic(path, topics, ODOM_TYPE, "--odom-topic")
                if found:
                    odom_topic = found[0]
                elif "/tf" not in tf_topics:
                    raise RosbagError(f"{path}: no {ODOM_TYPE} topic and no /tf to take odometry from "
                                      f"(the bag has: {_listed(topics)})")
            if odom_topic is not None:
                _check_topic(path, topics, odom_topic, ODOM_TYPE)
            contents.scan_topic = scan_topic
            contents.used_topics = (scan_topic, *((odom_topic,) if odom_topic else ()), *tf_topics)
            used = [c for c in reader.connections if c.topic in contents.used_topics]
            for conn, record_ns, raw in reader.messages(connections=used):
                msg = reader.deserialize(raw, conn.msgtype)
                if conn.topic in tf_topics:
                    transforms.take(msg, record_ns, conn.topic, contents)
                    continue
                stamp = _stamp(msg.header, record_ns, conn.topic, contents)
                if conn.topic == scan_topic:
                    contents.scans.append(laser_scan(msg, stamp))
                else:
                    contents.odometry.append(odometry(msg, stamp))
    except (AnyReaderError, Ros1Error, Ros2Error, SerdeError, OSError) as exc:
        raise RosbagError(f"{path}: not a readable ROS 1 or ROS 2 bag: {exc}") from None
    if odom_topic is None:
        bases = sorted(transforms.from_odom)
        if len(bases) != 1:
            raise RosbagError(f"{path}: no {ODOM_TYPE} topic, and /tf has "
                              + (f"transforms from {ODOM_FRAME} to several frames ({', '.join(bases)})"
                                 if bases else f"no transform from {ODOM_FRAME}")
                              + ": name the odometry topic with --odom-topic")
        contents.odometry = tf_odometry(transforms.from_odom[bases[0]], bases[0])
        contents.odom_source = f"/tf ({ODOM_FRAME} -> {bases[0]})"
    else:
        contents.odom_source = odom_topic
    contents.scans.sort(key=lambda m: m.header.stamp_ns)
    contents.odometry.sort(key=lambda m: m.header.stamp_ns)
    if contents.scans and contents.odometry and contents.odometry[0].child_frame_id:
        contents.laser_pose = _chain(transforms.links, _frame(contents.odometry[0].child_frame_id),
                                     _frame(contents.scans[0].header.frame_id))
    return contents


def keyed_messages(contents: BagContents, keys) -> list[tuple[str, object]]:
    """(key, message) pairs in stamp order, scans before odometry of the same stamp (a KeyLayout's keys)."""
    messages = [(keys.robot("scan"), s) for s in contents.scans] + [(keys.robot("odom"), o) for o in contents.odometry]
    messages.sort(key=lambda item: item[1].header.stamp_ns)   # stable
    return messages
