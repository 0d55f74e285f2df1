"""The ROS 2 bridge without ROS: rmw_zenoh's keys, tokens and attachments, CDR against rosbags, and a
loopback run where a fake rmw_zenoh robot feeds the racecar bag and the stack answers on /cmd_vel.

Reference values, and where they come from:
- type hashes (RIHS01) of ROS 2 Jazzy, as ROS itself reports them, found by exact search of public
  text: `ros2 topic info -v` output of live Jazzy systems for geometry_msgs/Twist (turtlesim's
  /turtle1/cmd_vel, e.g. kagenokeiyou/ros-notes start/03-topic/01-introduction.md),
  tf2_msgs/TFMessage (Nav2's /robot1/tf), nav_msgs/OccupancyGrid (RViz's /map) and
  nav_msgs/Odometry; the others (LaserScan, PoseStamped, PoseWithCovarianceStamped, Path) in the
  golden-hash tables and generated types of independent rmw_zenoh clients (Rust, Elixir, C++, Go),
  all agreeing; std_msgs/String's is the one of rmw_zenoh's token examples (its chatter demo);
- key and token layout, QoS part, GID and attachment: rmw_zenoh_cpp's sources (rmw.py's docstring
  names the files and commits); the token of a /tf subscription with depth 100,
  `.../MS/%/%/<node>/%tf/tf2_msgs::msg::dds_::TFMessage_/RIHS01_e369…/::,100:,:,:,,`, as ZettaScale's
  (Zenoh's authors') zenoh-cpp example that joins an rmw_zenoh graph declares it;
- the attachment's bytes: zenoh's own zenoh-ext serializer (the one rmw_zenoh uses), called here;
- golden vectors copied from rmw_zenoh itself, each cited where it is used (test_golden_*): the keys and
  tokens of ros2/rmw_zenoh docs/design.md (commit 99a6a2b), the attachment layouts of
  attachment_helpers.cpp and the QoS defaults of qos.cpp at ros2-gbp/rmw_zenoh-release's tags
  release/jazzy/rmw_zenoh_cpp/0.2.3-1 and 0.2.4-1, Zenoh's advanced publisher token before and from 1.3
  (eclipse-zenoh/zenoh zenoh-ext/src/advanced_publisher.rs, tags 1.2.1 and 1.3.0); TwistStamped's Jazzy
  hash as `ros2 topic info -v /cmd_vel` prints it on Jazzy robots and as rmw_zenoh clients written
  against them declare it (the same RIHS01_5f0f… in each).
"""
from __future__ import annotations

import argparse
import math
import subprocess
import sys
import threading

import numpy as np
import pytest
import yaml

from conftest import REPO, SHARED_DATA, wait_until
from omninav.schemas.messages import Goal, Header, LaserScan, OccupancyGrid, MapMetaData, Odometry, Path, Pose2D
from omninav.schemas.messages import PoseWithCovariance, Transform, Twist
from omninav.services.ros2_bridge.translate import (INPUTS, OUTPUTS, Bridge, Mounting, Ros2BridgeParams,
                                                 laser_mounting, ros_outputs, typestore)
from omninav.services.ros2_bridge.rmw import (ATTACHMENT_SIZE, PUBLISHER, SUBSCRIPTION, NodeIdentity, Qos,
                                              dds_type_name, entity_gid, pack_attachment, topic_key,
                                              unpack_attachment)
from omninav.schemas import decode
from omninav.schemas.keys import KeyLayout
from omninav.schemas.messages import Diagnostic
from omninav.services.runtime.run import build_node
from omninav.services.runtime.zenoh_config import open_client

pytest.importorskip("rosbags")
BAG = SHARED_DATA / "bags" / "localization_bag1_2022-03-29-19-23-29.bag"
MAP = SHARED_DATA / "maps" / "basement_fixed.yaml"

JAZZY_HASHES = {
    "sensor_msgs/msg/LaserScan": "RIHS01_64c191398013af96509d518dac71d5164f9382553fce5c1f8cca5be7924bd828",
    "nav_msgs/msg/Odometry": "RIHS01_3cc97dc7fb7502f8714462c526d369e35b603cfc34d946e3f2eda2766dfec6e0",
    "tf2_msgs/msg/TFMessage": "RIHS01_e369d0f05a23ae52508854b66f6aa0437f3449d652e8cbf22d5abe85d020f087",
    "geometry_msgs/msg/PoseStamped": "RIHS01_10f3786d7d40fd2b54367835614bff85d4ad3b5dab62bf8bca0cc232d73b4cd8",
    "geometry_msgs/msg/PoseWithCovarianceStamped":
        "RIHS01_26432f9803e43727d3c8f668d1fdb3c630f548af631e2f4e31382371bfea3b6e",
    "geometry_msgs/msg/Twist": "RIHS01_9c45bf16fe0983d80e3cfe750d6835843d265a9a6c46bd2e609fcddde6fb8d2a",
    "geometry_msgs/msg/TwistStamped": "RIHS01_5f0fcd4f81d5d06ad9b4c4c63e3ea51b82d6ae4d0558f1d475229b1121db6f64",
    "nav_msgs/msg/OccupancyGrid": "RIHS01_8d348150c12913a31ee0ec170fbf25089e4745d17035792a1ba94d6f0bc0cfc7",
    "nav_msgs/msg/Path": "RIHS01_1957a5bb3cee5da65c4e52e52b65a93df227efce4c20f8458b36e73066ca334b",
    "std_msgs/msg/String": "RIHS01_df668c740482bbd48fb39d76a70dfd4bd59db1288021743503259e948f6b1a18",
}


@pytest.fixture(scope="module")
def store():
    return typestore()


def ros_time(types, stamp_ns):
    return types["builtin_interfaces/msg/Time"](sec=stamp_ns // 10**9, nanosec=stamp_ns % 10**9)


def header(types, stamp_ns, frame):
    return types["std_msgs/msg/Header"](stamp=ros_time(types, stamp_ns), frame_id=frame)


def pose3d(types, x, y, qz, qw):
    return types["geometry_msgs/msg/Pose"](position=types["geometry_msgs/msg/Point"](x=x, y=y, z=0.0),
                                           orientation=types["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=qz, w=qw))


# ---------------------------------------------------------------- rmw_zenoh's layout

def test_every_bridged_type_has_the_jazzy_type_hash(store):
    for topic in (*INPUTS, *ros_outputs("twist"), *ros_outputs("twist_stamped")):
        assert store.hash_rihs01(topic.msgtype) == JAZZY_HASHES[topic.msgtype], topic.name
    assert store.hash_rihs01("std_msgs/msg/String") == JAZZY_HASHES["std_msgs/msg/String"]


def test_data_keys_are_rmw_zenohs():
    assert topic_key(0, "/scan", "sensor_msgs/msg/LaserScan", JAZZY_HASHES["sensor_msgs/msg/LaserScan"]) == \
        "0/scan/sensor_msgs::msg::dds_::LaserScan_/" + JAZZY_HASHES["sensor_msgs/msg/LaserScan"]
    assert topic_key(7, "/robot1/cmd_vel/", "geometry_msgs/msg/Twist", "H") == \
        "7/robot1/cmd_vel/geometry_msgs::msg::dds_::Twist_/H"
    with pytest.raises(ValueError, match="package/msg/Name"):
        dds_type_name("LaserScan")


def test_liveliness_tokens_are_rmw_zenohs():
    me = NodeIdentity(domain=0, zid="aac3178e146ba6f1fc6e6a4085e77f21", name="omninav_bridge")
    assert me.node_token() == "@ros2_lv/0/aac3178e146ba6f1fc6e6a4085e77f21/0/0/NN/%/%/omninav_bridge"
    tf_hash = JAZZY_HASHES["tf2_msgs/msg/TFMessage"]
    assert me.entity_token(3, SUBSCRIPTION, "/tf", "tf2_msgs/msg/TFMessage", tf_hash, Qos(depth=100)) == (
        "@ros2_lv/0/aac3178e146ba6f1fc6e6a4085e77f21/0/3/MS/%/%/omninav_bridge/%tf/"
        f"tf2_msgs::msg::dds_::TFMessage_/{tf_hash}/::,100:,:,:,,")
    # rmw_zenoh's defaults are left out, anything else is written as its rmw enum value
    best_effort_latched = Qos(reliability=2, durability=1, depth=42)
    token = me.entity_token(1, PUBLISHER, "/ns/map", "nav_msgs/msg/OccupancyGrid", "H", best_effort_latched)
    assert token.endswith("/MP/%/%/omninav_bridge/%ns%map/nav_msgs::msg::dds_::OccupancyGrid_/H/2:1:,:,:,:,,")
    with pytest.raises(ValueError, match="entity kind"):
        me.entity_token(1, "NN", "/tf", "tf2_msgs/msg/TFMessage", tf_hash, Qos())


def test_gids_are_16_bytes_and_differ_per_entity():
    me = NodeIdentity(0, "1234", "n")
    gids = {entity_gid(me.entity_token(i, PUBLISHER, "/cmd_vel", "geometry_msgs/msg/Twist", "H", Qos()))
            for i in range(1, 50)}
    assert len(gids) == 49 and all(len(g) == 16 for g in gids)


def test_attachment_is_zenoh_ext_serialization_of_seq_stamp_gid():
    from zenoh.ext import Int64, z_serialize
    gid = bytes(range(200, 216))
    packed = pack_attachment(42, 1_648_596_209_123_456_789, gid)
    assert len(packed) == ATTACHMENT_SIZE == 33
    assert packed == z_serialize((Int64(42), Int64(1_648_596_209_123_456_789), gid)).to_bytes()
    assert unpack_attachment(packed) == (42, 1_648_596_209_123_456_789, gid)
    with pytest.raises(ValueError, match="33 bytes, not 32"):
        unpack_attachment(packed[:-1])
    with pytest.raises(ValueError, match="GID length 15"):
        unpack_attachment(packed[:16] + bytes([15]) + packed[17:])


# ---------------------------------------------------------------- CDR out: byte for byte as rosbags

def out_topic(name):
    return next(t for t in OUTPUTS if t.omninav == name)


def test_outputs_encode_as_rosbags_serializes_the_same_values(store):
    t, bridge = store.types, Bridge(Ros2BridgeParams())
    stamp = 1_648_596_209_500_000_001
    vector = t["geometry_msgs/msg/Vector3"]

    data = np.array([[0, 100, -1], [50, 0, 0]], np.int8)
    grid = OccupancyGrid(header=Header(stamp_ns=stamp, frame_id="map"),
                         info=MapMetaData(resolution=0.05, width=3, height=2, origin=Pose2D(-1.0, 2.0, math.pi)),
                         data=data)
    meta = t["nav_msgs/msg/MapMetaData"](map_load_time=ros_time(t, stamp), resolution=0.05, width=3, height=2,
                                         origin=pose3d(t, -1.0, 2.0, 1.0, math.cos(math.pi / 2)))
    ros_grid = t["nav_msgs/msg/OccupancyGrid"](header=header(t, stamp, "map"), info=meta,
                                               data=np.array([0, 100, -1, 50, 0, 0], np.int8))
    assert bridge.to_ros(out_topic("map"), grid) == bytes(store.serialize_cdr(ros_grid, "nav_msgs/msg/OccupancyGrid"))

    cov = np.array([[0.1, 0.01, 0.02], [0.01, 0.2, 0.03], [0.02, 0.03, 0.3]])
    full = np.zeros(36)
    full[[0, 1, 5, 6, 7, 11, 30, 31, 35]] = [0.1, 0.01, 0.02, 0.01, 0.2, 0.03, 0.02, 0.03, 0.3]
    ros_pose = t["geometry_msgs/msg/PoseWithCovarianceStamped"](
        header=header(t, stamp, "map"), pose=t["geometry_msgs/msg/PoseWithCovariance"](
            pose=pose3d(t, 3.0, 4.0, math.sin(0.25), math.cos(0.25)), covariance=full))
    pose = PoseWithCovariance(header=Header(stamp_ns=stamp, frame_id="map"), pose=Pose2D(3.0, 4.0, 0.5), covariance=cov)
    assert bridge.to_ros(out_topic("pose"), pose) == \
        bytes(store.serialize_cdr(ros_pose, "geometry_msgs/msg/PoseWithCovarianceStamped"))

    h = header(t, stamp, "map")
    ros_path = t["nav_msgs/msg/Path"](header=h, poses=[
        t["geometry_msgs/msg/PoseStamped"](header=h, pose=pose3d(t, 0.0, 0.0, 0.0, 1.0)),
        t["geometry_msgs/msg/PoseStamped"](header=h, pose=pose3d(t, 1.0, 0.5, math.sin(-0.5), math.cos(-0.5)))])
    path = Path(header=Header(stamp_ns=stamp, frame_id="map"), poses=np.array([[0.0, 0.0, 0.0], [1.0, 0.5, -1.0]]))
    assert bridge.to_ros(out_topic("plan"), path) == bytes(store.serialize_cdr(ros_path, "nav_msgs/msg/Path"))

    ros_tf = t["tf2_msgs/msg/TFMessage"](transforms=[t["geometry_msgs/msg/TransformStamped"](
        header=h, child_frame_id="odom", transform=t["geometry_msgs/msg/Transform"](
            translation=vector(x=2.0, y=-1.5, z=0.0),
            rotation=t["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=math.sin(0.1), w=math.cos(0.1))))])
    map_odom = Transform(header=Header(stamp_ns=stamp, frame_id="map"), child_frame_id="odom",
                         transform=Pose2D(2.0, -1.5, 0.2))
    assert bridge.to_ros(out_topic("tf/map_odom"), map_odom) == \
        bytes(store.serialize_cdr(ros_tf, "tf2_msgs/msg/TFMessage"))


# ---------------------------------------------------------------- CDR in

def in_topic(name):
    return next(t for t in INPUTS if t.name == name)


def scan_cdr(store, stamp, frame="laser"):
    t = store.types
    msg = t["sensor_msgs/msg/LaserScan"](header=header(t, stamp, frame), angle_min=-1.0, angle_max=1.0,
                                         angle_increment=1.0, time_increment=0.0, scan_time=0.025, range_min=0.1,
                                         range_max=30.0, ranges=np.array([1.0, np.inf, 2.5], np.float32),
                                         intensities=np.zeros(3, np.float32))
    return bytes(store.serialize_cdr(msg, "sensor_msgs/msg/LaserScan"))


def tf_cdr(store, edges, static=True):
    t = store.types
    transforms = [t["geometry_msgs/msg/TransformStamped"](
        header=header(t, 0, parent), child_frame_id=child,
        transform=t["geometry_msgs/msg/Transform"](
            translation=t["geometry_msgs/msg/Vector3"](x=x, y=y, z=0.3),
            rotation=t["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=math.sin(yaw / 2), w=math.cos(yaw / 2))))
        for parent, child, x, y, yaw in edges]
    return bytes(store.serialize_cdr(t["tf2_msgs/msg/TFMessage"](transforms=transforms), "tf2_msgs/msg/TFMessage"))


def test_scan_odom_goal_and_initial_pose_come_in_with_the_clock_first(store):
    t, bridge = store.types, Bridge(Ros2BridgeParams())
    out = bridge.from_ros(in_topic("/scan"), scan_cdr(store, 5_000_000_123))
    assert [name for name, _ in out] == ["sim/clock", "scan"]
    clock, scan = out[0][1], out[1][1]
    assert clock.header.stamp_ns == scan.header.stamp_ns == 5_000_000_123
    assert isinstance(scan, LaserScan) and scan.header.frame_id == "laser" and scan.range_max == 30.0
    assert scan.ranges.tolist() == [1.0, math.inf, 2.5]

    cov = np.arange(36, dtype=float)
    odom = t["nav_msgs/msg/Odometry"](
        header=header(t, 4_000_000_000, "odom"), child_frame_id="base_link",
        pose=t["geometry_msgs/msg/PoseWithCovariance"](pose=pose3d(t, 1.0, 2.0, math.sin(0.3), math.cos(0.3)),
                                                       covariance=cov),
        twist=t["geometry_msgs/msg/TwistWithCovariance"](twist=t["geometry_msgs/msg/Twist"](
            linear=t["geometry_msgs/msg/Vector3"](x=0.4, y=0.0, z=0.0),
            angular=t["geometry_msgs/msg/Vector3"](x=0.0, y=0.0, z=-0.2)), covariance=cov))
    out = bridge.from_ros(in_topic("/odom"), bytes(store.serialize_cdr(odom, "nav_msgs/msg/Odometry")))
    assert [name for name, _ in out] == ["odom"]          # older than the clock: no new clock
    o = out[0][1]
    assert isinstance(o, Odometry) and (o.pose.x, o.pose.y) == (1.0, 2.0) and o.pose.theta == pytest.approx(0.6)
    assert o.twist.linear_x == 0.4 and o.twist.angular_z == -0.2
    assert o.pose_covariance.tolist() == [[0, 1, 5], [6, 7, 11], [30, 31, 35]]

    goal = t["geometry_msgs/msg/PoseStamped"](header=header(t, 0, "map"),
                                              pose=pose3d(t, 3.0, -1.0, math.sin(0.5), math.cos(0.5)))
    out = bridge.from_ros(in_topic("/goal_pose"), bytes(store.serialize_cdr(goal, "geometry_msgs/msg/PoseStamped")))
    g = out[0][1]
    assert out[0][0] == "goal" and isinstance(g, Goal) and g.goal_id == "ros2-1"
    assert g.header.stamp_ns == 5_000_000_123                 # stamped 0: takes effect now
    assert (g.pose.x, g.pose.y) == (3.0, -1.0) and g.pose.theta == pytest.approx(1.0)
    goal.header.frame_id = "odom"
    assert bridge.from_ros(in_topic("/goal_pose"), bytes(store.serialize_cdr(goal, "geometry_msgs/msg/PoseStamped"))) == []
    assert "'odom'" in bridge.problems[0]

    initial = t["geometry_msgs/msg/PoseWithCovarianceStamped"](
        header=header(t, 6_000_000_000, "map"),
        pose=t["geometry_msgs/msg/PoseWithCovariance"](pose=pose3d(t, -2.0, 0.5, 0.0, 1.0), covariance=cov))
    out = bridge.from_ros(in_topic("/initialpose"),
                          bytes(store.serialize_cdr(initial, "geometry_msgs/msg/PoseWithCovarianceStamped")))
    p = out[0][1]
    assert out[0][0] == "initialpose" and p.header.stamp_ns == 6_000_000_000 and (p.pose.x, p.pose.y) == (-2.0, 0.5)
    assert p.covariance.tolist() == [[0, 1, 5], [6, 7, 11], [30, 31, 35]]


def test_the_laser_mounting_on_tf_is_checked_against_the_stacks():
    store = typestore()
    bridge = Bridge(Ros2BridgeParams(laser_x=0.285 + 0.1, laser_y=0.05, laser_yaw=math.pi / 2))
    # no transform yet: passed on (the configured mounting is used), counted
    assert [n for n, _ in bridge.from_ros(in_topic("/scan"), scan_cdr(store, 1))] == ["sim/clock", "scan"]
    assert bridge.counts == {"scans_without_tf_mounting": 1}
    # base_link -> mount -> laser, through an intermediate frame: composes to the configured mounting
    bridge.from_ros(in_topic("/tf_static"), tf_cdr(store, [("base_link", "mount", 0.285, 0.0, 0.0),
                                                           ("mount", "laser", 0.1, 0.05, math.pi / 2)]))
    assert [n for n, _ in bridge.from_ros(in_topic("/scan"), scan_cdr(store, 2))] == ["sim/clock", "scan"]
    # the robot's /tf now says otherwise: scans are held back and the values found are named
    bridge.from_ros(in_topic("/tf"), tf_cdr(store, [("mount", "laser", 0.3, 0.05, math.pi / 2)]))
    assert bridge.from_ros(in_topic("/scan"), scan_cdr(store, 3)) == []
    assert bridge.counts["scans_dropped_mounting"] == 1
    assert "x=0.5850 y=0.0500 yaw=1.5708" in bridge.problems[0] and "laser_x=0.385" in bridge.problems[0]



def test_the_laser_mounting_is_the_chain_from_the_scans_frame_to_base_link(store):
    mounting = Mounting()
    with pytest.raises(LookupError, match=r"no /scan seen"):
        laser_mounting(None, mounting, "base_link")
    # two hops, the first on /tf_static, the second on /tf: base_link -> mount -> laser
    mounting.update(store.deserialize_cdr(tf_cdr(store, [("base_link", "mount", 0.2, 0.0, math.pi / 2)]),
                                          "tf2_msgs/msg/TFMessage"), "/tf_static")
    with pytest.raises(LookupError, match=r"no chain of transforms from frame 'laser' to 'base_link' on /tf or "
                                          r"/tf_static \(frames seen: base_link, mount\)"):
        laser_mounting("laser", mounting, "base_link")
    mounting.update(store.deserialize_cdr(tf_cdr(store, [("mount", "laser", 0.1, 0.0, -math.pi / 2)]),
                                          "tf2_msgs/msg/TFMessage"), "/tf")
    (x, y, yaw), how = laser_mounting("/laser", mounting, "base_link")
    assert (x, y, yaw) == pytest.approx((0.2, 0.1, 0.0))
    assert how == "/tf and /tf_static: base_link -> mount -> laser"
    # a missing link: without base_link -> mount, laser -> mount stops short of base_link
    del mounting.edges["mount"]
    with pytest.raises(LookupError, match=r"\(frames seen: laser, mount\)$"):
        laser_mounting("laser", mounting, "base_link")
    # a cycle is no chain
    mounting.update(store.deserialize_cdr(tf_cdr(store, [("laser", "mount", 0.0, 0.0, 0.0)]),
                                          "tf2_msgs/msg/TFMessage"))
    assert mounting.chain("laser", "base_link") is None
    # scans taken in base_link itself
    assert laser_mounting("base_link", mounting, "base_link") == ((0.0, 0.0, 0.0), "/scan: base_link")

def test_the_node_counts_a_bad_sample_and_carries_on():
    node = build_node("ros2_bridge")
    published = []
    for pub in node.outputs.values():
        pub.sink = lambda pub, payload, stamp: published.append(pub.key)
    gid = bytes(16)
    node.inbox.put((in_topic("/scan"), b"\x00\x01garbage", pack_attachment(1, 0, gid)))
    node.inbox.put((in_topic("/scan"), scan_cdr(typestore(), 10), pack_attachment(2, 0, gid)))
    node.tick()
    assert node.counters["handler_errors/ros2/scan"] == 1 and node.counters["received/ros2/scan"] == 2
    assert published == ["omninav/sim/clock", "omninav/r1/scan"]
    # the publisher's numbering tells what never came; a sample without rmw_zenoh's attachment is counted
    node.inbox.put((in_topic("/scan"), scan_cdr(typestore(), 20), pack_attachment(5, 0, gid)))
    node.inbox.put((in_topic("/scan"), scan_cdr(typestore(), 30), b""))
    node.tick()
    assert node.counters["lost/ros2/scan"] == 2 and node.counters["no_attachment/ros2/scan"] == 1
    assert published.count("omninav/r1/scan") == 3
    sent = []
    node.ros_sink = lambda topic, payload, stamp: sent.append((topic.name, stamp))
    node.process(0, Twist(header=Header(stamp_ns=11)))      # cmd_vel, the first input
    assert node.inputs[0].key == "omninav/r1/cmd_vel" and sent == [("/cmd_vel", 11)]


def test_the_node_refuses_a_robot_router_off_loopback():
    with pytest.raises(ValueError, match="loopback"):
        build_node("ros2_bridge", overrides={"ros_router": "tcp/192.168.1.10:7447"})


def stack_args(**values):
    defaults = dict(middleware="ros2", domain=None, router=None, map=None, laser=None, initial_pose=None,
                    tf_timeout=10.0, compose=str(REPO / "compose" / "ros2_robot.yaml"), duration=None,
                    credentials=None, zenoh_config=None, user=None, password_file=None,
                    cmd_vel_type=None, cmd_vel_frame_id=None)
    return argparse.Namespace(**{**defaults, **values})


def test_bridge_ros2_sets_the_robots_values_in_every_service():
    from omninav.cli.bridge import stack
    room_map = REPO / "compose" / "maps" / "room.yaml"     # shipped: the test needs no ../shared/data
    data = stack(stack_args(domain=3, router="tcp/127.0.0.1:7500", map=str(room_map), laser=[0.285, 0.0, 0.1],
                            initial_pose=[0.7, -0.3, 1.2]))
    services = {s["name"]: s for s in data["services"]}
    assert services["ros2_bridge"]["params"]["domain"] == 3
    assert services["ros2_bridge"]["params"]["ros_router"] == "tcp/127.0.0.1:7500"
    assert services["map_server"]["params"]["yaml_filename"] == str(room_map.resolve())
    mounted = [s for s in services.values() if "laser_x" in s.get("params", {})]
    assert {s["name"] for s in mounted} == {"localizer", "costmap", "collision_monitor", "ros2_bridge"}
    assert all(s["params"]["laser_yaw"] == 0.1 for s in mounted)
    assert services["localizer"]["params"]["initial_pose_a"] == 1.2
    assert {"sim", "chassis", "lidar"}.isdisjoint(services)
    with pytest.raises(ValueError, match="loopback"):
        stack(stack_args(router="tcp/10.1.2.3:7447"))


# ---------------------------------------------------------------- loopback: a fake robot and the stack

def start_fake_robot(procs, router_endpoint, tmp_path, goal, *options):
    """tests/fake_ros2_robot.py on the robot's router, stopped with procs' processes whatever happens;
    returned once it stands at its start (its /tf_static sent, its first scan repeated)."""
    if not BAG.exists() or not MAP.exists():
        pytest.skip("the racecar bag and the basement map are in ../shared/data")
    log = tmp_path / "fake_robot.log"
    robot = subprocess.Popen([sys.executable, str(REPO / "tests" / "fake_ros2_robot.py"), router_endpoint,
                              str(BAG), *(str(v) for v in goal), *options], stdout=open(log, "wb"),
                             stderr=subprocess.STDOUT, start_new_session=True, cwd=REPO)
    procs.started.append((robot, log))
    wait_until(lambda: "standing at the start" in log.read_text() or robot.poll() is not None, 120,
               what="the fake robot standing at its start")
    assert robot.poll() is None, log.read_text(errors="replace")[-3000:]
    return robot, log


def test_the_stack_drives_a_fake_rmw_zenoh_robot_from_the_racecar_bag(up, endpoint, router_endpoint, tmp_path, store):
    """The robot's router is router_endpoint (plain Zenoh, as rmw_zenohd); omninav's is up's. The bag's
    scans and odometry go in through the bridge, a goal 10 m down the corridor on /goal_pose, and the
    stack's command comes out on the robot's /cmd_vel key, with rmw_zenoh's attachment. The laser's
    mounting is not given: `bridge ros2` finds it on the robot first."""
    import zenoh
    from omninav.cli.bridge import mount_laser_from_tf, stack
    from omninav.services.runtime.zenoh_config import foreign_client_config

    start = (0.749, -0.273, 1.274)      # the bag's start in this map (docs/localize_eval.md)
    goal = (start[0] + 10 * math.cos(start[2]), start[1] + 10 * math.sin(start[2]), start[2])
    robot, log = start_fake_robot(up.procs, router_endpoint, tmp_path, goal)
    data = stack(stack_args(router=router_endpoint, map=str(MAP), initial_pose=list(start)))
    # no --laser: found on the robot, the fake robot's /tf_static (sent before anyone listened) and its /scan
    assert mount_laser_from_tf(data, 120) == "laser mounting from /tf_static: base_link -> laser x=0.2850 y=0.0000 yaw=0.0000"
    mounted = [s["params"] for s in data["services"] if "laser_x" in s.get("params", {})]
    assert len(mounted) == 4 and all((m["laser_x"], m["laser_y"], m["laser_yaw"]) == (0.285, 0.0, 0.0) for m in mounted)
    # TwistStamped, the bridge's default, as Jazzy's diff_drive_controller takes it
    stamped = "geometry_msgs/msg/TwistStamped"
    twist_key = topic_key(0, "/cmd_vel", stamped, JAZZY_HASHES[stamped])
    moving, seen = threading.Event(), []

    def on_cmd_vel(sample):
        attachment = sample.attachment.to_bytes() if sample.attachment is not None else b""
        command = store.deserialize_cdr(sample.payload.to_bytes(), stamped)
        seen.append((unpack_attachment(attachment), command))
        if abs(command.twist.linear.x) > 1e-3 or abs(command.twist.angular.z) > 1e-3:
            moving.set()

    tf_key = topic_key(0, "/tf", "tf2_msgs/msg/TFMessage", JAZZY_HASHES["tf2_msgs/msg/TFMessage"])
    frames = set()

    def on_tf(sample):
        for stamped in store.deserialize_cdr(sample.payload.to_bytes(), "tf2_msgs/msg/TFMessage").transforms:
            frames.add((stamped.header.frame_id, stamped.child_frame_id))

    with zenoh.open(foreign_client_config(router_endpoint)) as robot_side:
        subscriber = robot_side.declare_subscriber(twist_key, on_cmd_vel)
        tf_subscriber = robot_side.declare_subscriber(tf_key, on_tf)
        launcher = up(yaml.safe_dump(data, sort_keys=False))
        wait_until(lambda: moving.is_set() or launcher.poll() is not None or robot.poll() is not None, 400,
                   interval=0.5, what="a moving command on the robot's /cmd_vel")
        assert launcher.poll() is None and robot.poll() is None, log.read_text(errors="replace")[-3000:]
        tokens = [str(r.ok.key_expr) for r in robot_side.liveliness().get("@ros2_lv/0/**", timeout=2.0)
                  if r.ok is not None]
        subscriber.undeclare()
        tf_subscriber.undeclare()
    assert ("map", "odom") in frames        # the localizer's map -> odom, for RViz
    # the laser mounting came from /tf_static, published once before the bridge existed (from the
    # robot's cache, as transient local is), and agreed with the stack's: no scan was held back
    diagnostics = []
    with open_client(endpoint) as omninav_side:
        omninav_side.declare_subscriber(KeyLayout().diagnostics("ros2_bridge"),
                                        lambda s: diagnostics.append(decode(s.payload.to_bytes(), Diagnostic)))
        wait_until(lambda: any(d.values.get("scans_mounting_checked", 0) > 0 for d in diagnostics), 30,
                   what="the bridge's diagnostic counting scans checked against /tf_static")
    assert not any("scans_dropped_mounting" in d.values for d in diagnostics)
    # every sample came with rmw_zenoh's attachment, numbered without gaps
    assert not [k for d in diagnostics for k in d.values if k.startswith(("lost/", "no_attachment/"))]
    # what `ros2 topic list` on the robot is built from: the bridge's node and its endpoints
    bridge_tokens = [k for k in tokens if "/omninav_bridge" in k]
    assert any(k.endswith("/NN/%/%/omninav_bridge") for k in bridge_tokens)
    for topic in OUTPUTS:
        assert any(f"/MP/%/%/omninav_bridge/{topic.name.replace('/', '%')}/" in k for k in bridge_tokens), topic.name
    for topic in INPUTS:
        assert any(f"/MS/%/%/omninav_bridge/{topic.name.replace('/', '%')}/" in k for k in bridge_tokens), topic.name
    cmd_vel_token = next(k for k in bridge_tokens if "/MP/" in k and "%cmd_vel/" in k)
    sequence = [seq for (seq, _, _), _ in seen]
    assert sequence == list(range(sequence[0], sequence[0] + len(sequence)))     # numbered, none lost
    assert all(gid == entity_gid(cmd_vel_token) for (_, _, gid), _ in seen)
    assert all(command.header.frame_id == "base_link" and command.header.stamp.sec > 0 for _, command in seen)
    assert "goal sent" in log.read_text()
    # the robot's base (its TwistStamped subscription, with its token) decoded a moving command too
    wait_until(lambda: f"cmd_vel heard: {stamped} in frame base_link stamped " in log.read_text(), 30,
               what="the fake robot's base hearing a command")


def test_bridge_ros2_without_tf_static_exits_2_naming_the_frames_it_saw(processes, router_endpoint, tmp_path, capsys):
    """The fake robot's scans are in 'laser' and its /tf has odom -> base_link, but nothing mounts the laser."""
    from omninav.cli.bridge import main
    start_fake_robot(processes, router_endpoint, tmp_path, (0.0, 0.0, 0.0), "--no-tf-static")
    assert main(stack_args(router=router_endpoint, tf_timeout=5.0)) == 2
    assert capsys.readouterr().err == (
        "error: no chain of transforms from frame 'laser' to 'base_link' on /tf or /tf_static (frames seen: "
        "base_link, odom) within 5 s; give the laser's mounting by hand: --laser X Y YAW\n")


def test_bridge_ros2_without_a_robot_router_exits_2(capsys):
    from omninav.cli.bridge import main
    from conftest import free_port
    router = f"tcp/127.0.0.1:{free_port()}"
    assert main(stack_args(router=router, tf_timeout=1.0)) == 2
    assert capsys.readouterr().err == (f"error: the robot's router at {router} does not answer (is rmw_zenohd "
                                       "running?) within 1 s; give the laser's mounting by hand: --laser X Y YAW\n")
    assert main(stack_args(tf_timeout=0.0)) == 2
    assert "--tf-timeout 0: wall seconds > 0" in capsys.readouterr().err


def test_the_bridge_waits_for_the_robots_router_and_stops_when_asked(processes, router_endpoint):
    """omninav's side comes up at once; the robot's graph is joined when its router answers."""
    from omninav.services.runtime.zenoh_config import open_router
    from conftest import free_port, wait_alive
    robot_router = f"tcp/127.0.0.1:{free_port()}"
    bridge = processes.omninav("run", "ros2_bridge", "--set", f"ros_router={robot_router}")
    wait_alive(router_endpoint, ["ros2_bridge"], timeout=120)
    wait_until(lambda: "waiting for the robot's router" in processes.log_of(bridge), 30, what="the waiting notice")
    with open_router(robot_router) as robot_side:
        def bridge_node_token():
            return [r for r in robot_side.liveliness().get("@ros2_lv/0/**/NN/%/%/omninav_bridge", timeout=1.0)
                    if r.ok is not None]
        wait_until(bridge_node_token, 60, what="the bridge's node on the robot's graph")
        assert processes.stop(bridge) == 0, processes.log_of(bridge)
        wait_until(lambda: not bridge_node_token(), 30, what="the bridge's node leaving the robot's graph")
    # one still waiting for the robot stops as promptly
    waiting = processes.omninav("run", "ros2_bridge", "--name", "waiting_bridge", "--set", f"ros_router={robot_router}")
    wait_alive(router_endpoint, ["waiting_bridge"], timeout=120)
    assert processes.stop(waiting) == 0, processes.log_of(waiting)
