"""ROS bags as omninav messages: the 2-D projection, a ROS 2 bag written here, the real ROS 1 racecar bag,
and `omninav import rosbag`."""
import math
from types import SimpleNamespace as NS

import numpy as np
import pytest

from omninav.cli.main import main as omninav
from omninav.schemas.codec import decode
from omninav.schemas.keys import KeyLayout
from omninav.services.importers.rosbag import RosbagError, odometry, read_bag, yaw_of
from omninav.services.recorder.mcap_io import read_records
from omninav.geometry.se2 import wrap_angle

from conftest import SHARED_DATA

BAG = SHARED_DATA / "bags" / "localization_bag1_2022-03-29-19-23-29.bag"
KEYS = KeyLayout()
try:
    import rosbags  # noqa: F401
    HAVE_ROSBAGS = True
except ImportError:
    HAVE_ROSBAGS = False
needs_rosbags = pytest.mark.skipif(not HAVE_ROSBAGS, reason="the optional rosbags package is not installed "
                                                            "(pip install '.[rosbag]')")
needs_bag = pytest.mark.skipif(not BAG.is_file(), reason=f"no shared data: {BAG}")


@pytest.mark.parametrize("yaw", [0.0, 0.3, -1.2, 2.9, math.pi - 1e-9, -3.0])
@pytest.mark.parametrize("norm", [1.0, 0.5, 3.0])
def test_yaw_of_a_planar_quaternion_at_any_norm(yaw, norm):
    x, y, z, w = 0.0, 0.0, norm * math.sin(yaw / 2), norm * math.cos(yaw / 2)
    assert wrap_angle(yaw_of(x, y, z, w) - yaw) == pytest.approx(0.0, abs=1e-9)
    assert wrap_angle(yaw_of(-x, -y, -z, -w) - yaw) == pytest.approx(0.0, abs=1e-9)   # q and −q: one rotation


def test_yaw_of_a_tilted_quaternion_is_its_heading():
    # yaw 0.7 after pitch 0.2 and roll −0.1 (ZYX, as ROS's tf): the heading stays 0.7
    cr, sr = math.cos(-0.05), math.sin(-0.05)
    cp, sp = math.cos(0.1), math.sin(0.1)
    cy, sy = math.cos(0.35), math.sin(0.35)
    w, x = cr * cp * cy + sr * sp * sy, sr * cp * cy - cr * sp * sy
    y, z = cr * sp * cy + sr * cp * sy, cr * cp * sy - sr * sp * cy
    assert yaw_of(x, y, z, w) == pytest.approx(0.7, abs=1e-9)


def test_odometry_is_projected_to_2d():
    cov = np.arange(36, dtype=float)
    msg = NS(header=NS(frame_id="odom"), child_frame_id="base_link",
             pose=NS(pose=NS(position=NS(x=1.5, y=-2.0, z=0.3), orientation=NS(x=0.0, y=0.0, z=math.sin(0.4),
                                                                               w=math.cos(0.4))),
                     covariance=cov),
             twist=NS(twist=NS(linear=NS(x=0.5, y=0.1, z=9.0), angular=NS(x=9.0, y=9.0, z=-0.2)), covariance=cov * 2))
    odom = odometry(msg, 123)
    assert odom.header.stamp_ns == odom.twist.header.stamp_ns == 123 and odom.header.frame_id == "odom"
    assert (odom.pose.x, odom.pose.y) == (1.5, -2.0) and odom.pose.theta == pytest.approx(0.8)
    assert (odom.twist.linear_x, odom.twist.linear_y, odom.twist.angular_z) == (0.5, 0.1, -0.2)
    # x, y, yaw of (x, y, z, roll, pitch, yaw), row-major 6×6
    assert odom.pose_covariance.tolist() == [[0, 1, 5], [6, 7, 11], [30, 31, 35]]
    assert odom.twist_covariance.tolist() == [[0, 2, 10], [12, 14, 22], [60, 62, 70]]


def test_a_missing_bag_is_named(tmp_path):
    with pytest.raises(RosbagError, match="no such file"):
        read_bag(tmp_path / "nope.bag")


@needs_rosbags
def test_a_file_that_is_no_bag_is_a_clear_error(tmp_path):
    junk = tmp_path / "junk.bag"
    junk.write_bytes(b"not a bag at all\n" * 10)
    with pytest.raises(RosbagError, match="not a readable ROS 1 or ROS 2 bag"):
        read_bag(junk)


# ---------------------------------------------------------------- a ROS 2 bag

STORAGES = ("sqlite3", "mcap")      # the two storage plugins of ROS 2 bags: .db3 files, .mcap files (CDR in both)


def _write_ros2_bag(path, storage: str = "sqlite3"):
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.ROS2_HUMBLE)
    t = store.types
    Time, Header = t["builtin_interfaces/msg/Time"], t["std_msgs/msg/Header"]
    Vec, Quat, Point = t["geometry_msgs/msg/Vector3"], t["geometry_msgs/msg/Quaternion"], t["geometry_msgs/msg/Point"]
    scan_type, odom_type = "sensor_msgs/msg/LaserScan", "nav_msgs/msg/Odometry"
    plugin = {"sqlite3": StoragePlugin.SQLITE3, "mcap": StoragePlugin.MCAP}[storage]
    with Writer(path, version=8, storage_plugin=plugin) as writer:
        scans = writer.add_connection("/scan", scan_type, typestore=store)
        odoms = writer.add_connection("/odom", odom_type, typestore=store)
        other = writer.add_connection("/chatter", "std_msgs/msg/String", typestore=store)
        for k in range(3):
            stamp = Time(sec=100 + k, nanosec=5)
            scan = t[scan_type](header=Header(stamp=stamp, frame_id="laser"), angle_min=-1.0, angle_max=1.0,
                                angle_increment=1.0, time_increment=0.0, scan_time=0.1, range_min=0.1, range_max=8.0,
                                ranges=np.array([1.0, np.inf, 2.5 + k], np.float32),
                                intensities=np.array([], np.float32))
            writer.write(scans, 10 ** 9 * (100 + k), bytes(store.serialize_cdr(scan, scan_type)))
            pose = t["geometry_msgs/msg/PoseWithCovariance"](
                pose=t["geometry_msgs/msg/Pose"](position=Point(x=0.1 * k, y=0.0, z=0.0),
                                                 orientation=Quat(x=0.0, y=0.0, z=math.sin(0.1 * k), w=math.cos(0.1 * k))),
                covariance=np.zeros(36))
            twist = t["geometry_msgs/msg/TwistWithCovariance"](
                twist=t["geometry_msgs/msg/Twist"](linear=Vec(x=1.0, y=0.0, z=0.0), angular=Vec(x=0.0, y=0.0, z=0.2)),
                covariance=np.zeros(36))
            # the last odometry has no header stamp: it takes the time the bag recorded it at
            odom_stamp = stamp if k < 2 else Time(sec=0, nanosec=0)
            odom = t[odom_type](header=Header(stamp=odom_stamp, frame_id="odom"), child_frame_id="base_link",
                                pose=pose, twist=twist)
            writer.write(odoms, 10 ** 9 * (100 + k) + 7, bytes(store.serialize_cdr(odom, odom_type)))
        writer.write(other, 10 ** 9 * 100, bytes(store.serialize_cdr(t["std_msgs/msg/String"](data="hi"),
                                                                      "std_msgs/msg/String")))


@needs_rosbags
@pytest.mark.parametrize("storage", STORAGES)
def test_a_ros2_bag_converts(tmp_path, storage):
    path = tmp_path / "ros2bag"
    _write_ros2_bag(path, storage)
    assert [f.suffix for f in path.iterdir() if f.name != "metadata.yaml"] == [{"sqlite3": ".db3", "mcap": ".mcap"}[storage]]
    contents = read_bag(path, "/scan", "/odom")
    assert [s.header.stamp_ns for s in contents.scans] == [100 * 10 ** 9 + 5, 101 * 10 ** 9 + 5, 102 * 10 ** 9 + 5]
    assert contents.scans[2].ranges.tolist() == [1.0, np.inf, 4.5] and contents.scans[0].range_max == 8.0
    assert [o.header.stamp_ns for o in contents.odometry] == [100 * 10 ** 9 + 5, 101 * 10 ** 9 + 5, 102 * 10 ** 9 + 7]
    assert contents.unstamped == {"/odom": 1}
    assert contents.odometry[2].pose.x == pytest.approx(0.2) and contents.odometry[2].pose.theta == pytest.approx(0.4)
    assert contents.topics["/chatter"] == ("std_msgs/msg/String", 1)


@needs_rosbags
@pytest.mark.parametrize("storage", STORAGES)
def test_import_rosbag_writes_a_ros2_bag_of_either_storage_as_a_recording(tmp_path, capsys, storage):
    bag, out = tmp_path / "ros2bag", tmp_path / "bag.mcap"
    _write_ros2_bag(bag, storage)
    assert omninav(["import", "rosbag", str(bag), "-o", str(out), "--odom-topic", "/odom"]) == 0
    printed = capsys.readouterr().out
    assert "3 scans from /scan" in printed and "3 odometry messages from /odom" in printed
    assert "not converted: /chatter" in printed
    records = list(read_records(out))
    scans = [decode(r.payload) for r in records if r.key == KEYS.robot("scan")]
    odoms = [decode(r.payload) for r in records if r.key == KEYS.robot("odom")]
    assert [s.ranges.tolist() for s in scans] == [[1.0, np.inf, 2.5], [1.0, np.inf, 3.5], [1.0, np.inf, 4.5]]
    assert (scans[1].angle_min, scans[1].angle_increment, scans[1].range_max) == (-1.0, 1.0, 8.0)
    assert [o.pose.x for o in odoms] == pytest.approx([0.0, 0.1, 0.2])
    assert [o.pose.theta for o in odoms] == pytest.approx([0.0, 0.2, 0.4])
    assert {(o.twist.linear_x, o.twist.angular_z) for o in odoms} == {(1.0, 0.2)}
    assert [o.header.stamp_ns for o in odoms] == [100 * 10 ** 9 + 5, 101 * 10 ** 9 + 5, 102 * 10 ** 9 + 7]


@needs_rosbags
def test_a_missing_or_mistyped_topic_is_named(tmp_path):
    path = tmp_path / "ros2bag"
    _write_ros2_bag(path)
    with pytest.raises(RosbagError, match=r"no topic /vesc/odom \(the bag has: /chatter .*/odom .*/scan"):
        read_bag(path, "/scan", "/vesc/odom")
    with pytest.raises(RosbagError, match="/chatter carries std_msgs/msg/String, not nav_msgs/msg/Odometry"):
        read_bag(path, "/scan", "/chatter")


# ---------------------------------------------------------------- the racecar's ROS 1 bag

@needs_rosbags
@needs_bag
def test_the_racecar_bag_converts():
    from rosbags.highlevel import AnyReader

    contents = read_bag(BAG)                      # defaults: /scan and /vesc/odom
    assert len(contents.scans) == 281 and len(contents.odometry) == 350
    for msgs in (contents.scans, contents.odometry):
        stamps = [m.header.stamp_ns for m in msgs]
        assert stamps == sorted(stamps) and stamps[-1] - stamps[0] > 6 * 10 ** 9   # a 7 s run
    scan = contents.scans[0]
    assert scan.header.frame_id == "laser" and scan.ranges.shape == (1081,) and scan.ranges.dtype == np.float32
    assert scan.angle_min == pytest.approx(-2.356194, abs=1e-6) and scan.range_max == 30.0
    assert scan.angle_min + 1080 * scan.angle_increment == pytest.approx(scan.angle_max, abs=1e-5)
    odom = contents.odometry
    assert {o.header.frame_id for o in odom} == {"odom"} and {o.child_frame_id for o in odom} == {"base_link"}
    # against the bag's own first odometry message, read here independently
    with AnyReader([BAG]) as reader:
        conn = next(c for c in reader.connections if c.topic == "/vesc/odom")
        _, _, raw = next(iter(reader.messages(connections=[conn])))
        first = reader.deserialize(raw, conn.msgtype)
    q = first.pose.pose.orientation
    assert odom[0].header.stamp_ns == first.header.stamp.sec * 10 ** 9 + first.header.stamp.nanosec
    assert odom[0].pose.x == first.pose.pose.position.x and odom[0].pose.y == first.pose.pose.position.y
    assert wrap_angle(odom[0].pose.theta - 2 * math.atan2(q.z, q.w)) == pytest.approx(0.0, abs=1e-9)  # q.x = q.y = 0
    assert odom[0].twist.linear_x == first.twist.twist.linear.x


@needs_rosbags
@needs_bag
def test_import_rosbag_writes_a_recording(tmp_path, capsys):
    out = tmp_path / "bag.mcap"
    assert omninav(["import", "rosbag", str(BAG), "-o", str(out)]) == 0
    assert "281 scans" in capsys.readouterr().out
    records = list(read_records(out))
    scans = [r for r in records if r.key == KEYS.robot("scan")]
    odoms = [r for r in records if r.key == KEYS.robot("odom")]
    assert len(scans) == 281 and len(odoms) == 350 and len(records) == 631
    assert [r.seq for r in scans] == list(range(281))
    assert [r.stamp_ns for r in records] == sorted(r.stamp_ns for r in records)
    assert decode(scans[0].payload).header.stamp_ns == scans[0].stamp_ns
    # an existing output is kept unless --force
    before = out.read_bytes()
    assert omninav(["import", "rosbag", str(BAG), "-o", str(out)]) == 2
    assert "exists" in capsys.readouterr().err and out.read_bytes() == before


@needs_rosbags
@needs_bag
def test_import_rosbag_with_a_wrong_topic_writes_nothing(tmp_path, capsys):
    out = tmp_path / "bag.mcap"
    assert omninav(["import", "rosbag", str(BAG), "-o", str(out), "--odom-topic", "/odom"]) == 2
    assert "no topic /odom" in capsys.readouterr().err and not out.exists()


# ---------------------------------------------------------------- a bag as other robots record them

def _quat(store, yaw):
    return store.types["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=math.sin(yaw / 2), w=math.cos(yaw / 2))


def _transform(store, stamp, parent, child, x, y, z, yaw):
    t = store.types
    return t["geometry_msgs/msg/TransformStamped"](
        header=t["std_msgs/msg/Header"](stamp=stamp, frame_id=parent), child_frame_id=child,
        transform=t["geometry_msgs/msg/Transform"](translation=t["geometry_msgs/msg/Vector3"](x=x, y=y, z=z),
                                                   rotation=_quat(store, yaw)))


# the robot's odom -> base_footprint poses on /tf, one every 0.1 s: a drive ahead while turning
TF_POSES = [(0.0, 0.0, 0.0), (0.05, 0.0, 0.02), (0.1, 0.002, 0.04), (0.15, 0.005, 0.06)]


def _write_tf_bag(path, scan_topics=("/scan",), leading_slash=False):
    """A ROS 2 bag as a robot without an Odometry topic records it (a TurtleBot-like layout): scans
    in frame base_scan, odometry only as /tf's odom -> base_footprint, and the mounting on
    /tf_static: base_footprint -> base_link -> base_scan."""
    from rosbags.rosbag2 import Writer
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.ROS2_HUMBLE)
    t = store.types
    Time, Header = t["builtin_interfaces/msg/Time"], t["std_msgs/msg/Header"]
    tf_type, scan_type = "tf2_msgs/msg/TFMessage", "sensor_msgs/msg/LaserScan"
    slash = "/" if leading_slash else ""
    with Writer(path, version=8) as writer:
        tf, tf_static = (writer.add_connection(topic, tf_type, typestore=store) for topic in ("/tf", "/tf_static"))
        scans = [writer.add_connection(topic, scan_type, typestore=store) for topic in scan_topics]
        mount = t[tf_type](transforms=[
            _transform(store, Time(sec=50, nanosec=0), f"{slash}base_footprint", f"{slash}base_link", 0.0, 0.0, 0.01, 0.0),
            _transform(store, Time(sec=50, nanosec=0), f"{slash}base_link", f"{slash}base_scan", -0.064, 0.01, 0.12, 0.3)])
        writer.write(tf_static, 50 * 10 ** 9, bytes(store.serialize_cdr(mount, tf_type)))
        for k, (x, y, yaw) in enumerate(TF_POSES):
            stamp = Time(sec=50, nanosec=k * 100_000_000)
            odom = t[tf_type](transforms=[_transform(store, stamp, f"{slash}odom", f"{slash}base_footprint", x, y, 0.0, yaw)])
            writer.write(tf, 50 * 10 ** 9 + k * 10 ** 8, bytes(store.serialize_cdr(odom, tf_type)))
            for conn in scans:
                scan = t[scan_type](header=Header(stamp=stamp, frame_id=f"{slash}base_scan"), angle_min=0.0,
                                    angle_max=6.28, angle_increment=3.14, time_increment=0.0, scan_time=0.2,
                                    range_min=0.12, range_max=3.5, ranges=np.array([1.0, 2.0, 3.0], np.float32),
                                    intensities=np.array([], np.float32))
                writer.write(conn, 50 * 10 ** 9 + k * 10 ** 8 + 1, bytes(store.serialize_cdr(scan, scan_type)))


@needs_rosbags
@pytest.mark.parametrize("leading_slash", [False, True], ids=["ros2 frames", "ros1 /frames"])
def test_a_bag_without_odometry_topic_gives_odometry_and_the_laser_mounting_from_tf(tmp_path, leading_slash):
    path = tmp_path / "tfbag"
    _write_tf_bag(path, leading_slash=leading_slash)
    contents = read_bag(path)                     # no topics named: found by type
    assert contents.scan_topic == "/scan" and contents.odom_source == "/tf (odom -> base_footprint)"
    assert len(contents.scans) == 4
    odom = contents.odometry
    assert [o.header.stamp_ns for o in odom] == [50 * 10 ** 9 + k * 10 ** 8 for k in range(4)]
    assert np.array([(o.pose.x, o.pose.y, o.pose.theta) for o in odom]) == pytest.approx(np.array(TF_POSES))
    assert {o.child_frame_id for o in odom} == {"base_footprint"} and {o.header.frame_id for o in odom} == {"odom"}
    # the body-frame motion over each 0.1 s: 0.5 m/s ahead, 0.2 rad/s; nothing before the first
    assert (odom[0].twist.linear_x, odom[0].twist.angular_z) == (0.0, 0.0)
    assert odom[1].twist.linear_x == pytest.approx(0.5 * math.cos(0.0), rel=1e-6)
    assert [o.twist.angular_z for o in odom[1:]] == pytest.approx([0.2] * 3)
    c, s = math.cos(0.02), math.sin(0.02)
    dx, dy = 0.05, 0.002          # pose 2 seen from pose 1, divided by 0.1 s
    assert odom[2].twist.linear_x == pytest.approx((c * dx + s * dy) / 0.1)
    assert odom[2].twist.linear_y == pytest.approx((-s * dx + c * dy) / 0.1)
    # base_footprint -> base_link -> base_scan, projected to the plane
    assert contents.laser_pose == pytest.approx((-0.064, 0.01, 0.3))


@needs_rosbags
def test_import_rosbag_finds_the_topics_and_says_where_odometry_and_mounting_came_from(tmp_path, capsys):
    bag, out = tmp_path / "tfbag", tmp_path / "bag.mcap"
    _write_tf_bag(bag)
    assert omninav(["import", "rosbag", str(bag), "-o", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "4 scans from /scan" in printed and "4 odometry messages from /tf (odom -> base_footprint)" in printed
    assert "laser mounting in the robot frame (from the bag's tf): x=-0.064 m, y=0.010 m, yaw=0.3000 rad" in printed
    assert "not converted" not in printed
    odoms = [decode(r.payload) for r in read_records(out) if r.key == KEYS.robot("odom")]
    assert [o.pose.x for o in odoms] == pytest.approx([p[0] for p in TF_POSES])


@needs_rosbags
def test_topics_not_named_are_the_bags_one_topic_of_their_type(tmp_path):
    path = tmp_path / "ros2bag"
    _write_ros2_bag(path)
    contents = read_bag(path)
    assert (contents.scan_topic, contents.odom_source) == ("/scan", "/odom") and len(contents.odometry) == 3
    assert contents.laser_pose is None            # no tf in that bag


@needs_rosbags
def test_a_bag_with_two_scan_topics_must_name_one(tmp_path):
    path = tmp_path / "tfbag"
    _write_tf_bag(path, scan_topics=("/front/scan", "/rear/scan"))
    with pytest.raises(RosbagError, match=r"several sensor_msgs/msg/LaserScan topics \(/front/scan, /rear/scan\): "
                                          r"name the one to use with --scan-topic"):
        read_bag(path)
    assert len(read_bag(path, scan_topic="/rear/scan").scans) == 4


@needs_rosbags
def test_a_bag_with_neither_odometry_nor_tf_is_a_clear_error(tmp_path):
    from rosbags.rosbag2 import Writer
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.ROS2_HUMBLE)
    path = tmp_path / "scans_only"
    with Writer(path, version=8) as writer:
        writer.add_connection("/scan", "sensor_msgs/msg/LaserScan", typestore=store)
    with pytest.raises(RosbagError, match=r"no nav_msgs/msg/Odometry topic and no /tf to take odometry from "
                                          r"\(the bag has: /scan \(sensor_msgs/msg/LaserScan\)\)"):
        read_bag(path)
