"""A stand-in for a ROS 2 robot running rmw_zenoh, for tests/test_ros2_bridge.py: no ROS needed.

    python tests/fake_ros2_robot.py ROUTER BAG GOAL_X GOAL_Y GOAL_YAW [--no-tf-static] [--cmd-vel-type TYPE]

Publishes as rmw_zenoh does (rmw.py: keys, 33-byte attachments; CDR by rosbags, ROS 2 Jazzy types)
the racecar bag's /scan and its /vesc/odom as /odom, in stamp order at the bag's pace, once omninav's
bridge has subscribed to both (its liveliness tokens: then the stack behind it is up, as `up` starts
the bridge last); /tf_static with the racecar's laser mounting at its start, transient local as
robot_state_publisher's (before the bridge exists: it must ask the publisher's cache; not with
--no-tf-static), and /goal_pose after the tenth scan. Until the bridge is there the robot stands at
its start, as a robot does: the bag's first scan and its first odometry's odom -> base_link on /tf,
every STAND_PERIOD_NS (what `omninav bridge ros2` looks at to find the laser's mounting). When the bag ends the robot stands: the last scan and odometry go on with advancing stamps,
until the process is stopped. Its base listens on /cmd_vel as Jazzy's diff_drive_controller does
(geometry_msgs/msg/TwistStamped, or the ROS type --cmd-vel-type names), with a liveliness token, and
prints the first moving command it decodes: "cmd_vel heard: <type> in frame <frame_id> stamped <ns>".
"""
from __future__ import annotations

import math
import sys
import time
from pathlib import Path

import zenoh
from rosbags.highlevel import AnyReader
from zenoh.ext import CacheConfig, declare_advanced_publisher

from omninav.services.ros2_bridge.translate import Ros2BridgeParams, typestore
from omninav.services.ros2_bridge.node import ros_session_config
from omninav.services.ros2_bridge.rmw import (PUBLISHER, SUBSCRIPTION, TRANSIENT_LOCAL, NodeIdentity, Qos, entity_gid,
                                              pack_attachment, topic_key)

LASER_X = 0.285        # the MIT racecar's base_link -> laser (docs/localize_eval.md)
STAND_PERIOD_NS = 50_000_000


def main(router: str, bag: str, goal: tuple[float, float, float], tf_static: bool, cmd_vel_type: str) -> None:
    store = typestore()
    t = store.types
    with zenoh.open(ros_session_config(Ros2BridgeParams(ros_router=router))) as session:
        me = NodeIdentity(0, str(session.info.zid()), "fake_robot")
        publishers, tokens = {}, listen_to_cmd_vel(session, me, store, cmd_vel_type)   # kept to the end
        for number, (topic, msgtype) in enumerate((("/scan", "sensor_msgs/msg/LaserScan"),
                                                   ("/odom", "nav_msgs/msg/Odometry"),
                                                   ("/tf_static", "tf2_msgs/msg/TFMessage"),
                                                   ("/tf", "tf2_msgs/msg/TFMessage"),
                                                   ("/goal_pose", "geometry_msgs/msg/PoseStamped")), start=1):
            type_hash = store.hash_rihs01(msgtype)
            latched = topic == "/tf_static"     # robot_state_publisher's: transient local, kept for late joiners
            qos = Qos(durability=TRANSIENT_LOCAL, depth=1) if latched else Qos()
            token = me.entity_token(number, PUBLISHER, topic, msgtype, type_hash, qos)
            publishers[topic] = [declare_advanced_publisher(session, topic_key(0, topic, msgtype, type_hash),
                                                            congestion_control=zenoh.CongestionControl.BLOCK,
                                                            cache=CacheConfig(max_samples=1) if latched else None,
                                                            publisher_detection=latched),
                                 msgtype, entity_gid(token), 0]
            tokens.append(session.liveliness().declare_token(token))

        def publish(topic: str, msg, stamp_ns: int) -> None:
            entry = publishers[topic]
            entry[3] += 1
            entry[0].put(bytes(store.serialize_cdr(msg, entry[1])),
                         attachment=pack_attachment(entry[3], stamp_ns, entry[2]))

        with AnyReader([Path(bag)]) as reader:
            used = [c for c in reader.connections if c.topic in ("/scan", "/vesc/odom")]
            messages = [(c.topic, reader.deserialize(raw, c.msgtype)) for c, _, raw in reader.messages(connections=used)]
        messages.sort(key=lambda item: _ns(item[1].header.stamp))
        first = _ns(messages[0][1].header.stamp)
        # at once, as robot_state_publisher at its start: the bridge, not there yet, gets it from the cache
        if tf_static:
            publish("/tf_static", t["tf2_msgs/msg/TFMessage"](transforms=[
                _transform(t, first, "base_link", "laser", LASER_X, 0.0, 0.0, 1.0)]), first)
        scan = next(msg for topic, msg in messages if topic == "/scan")
        odom = next(msg for topic, msg in messages if topic == "/vesc/odom")
        p, q = odom.pose.pose.position, odom.pose.pose.orientation
        odom_base = t["tf2_msgs/msg/TFMessage"](transforms=[
            _transform(t, _ns(odom.header.stamp), "odom", "base_link", p.x, p.y, q.z, q.w)])
        print("standing at the start", flush=True)
        wanted = ("%scan/sensor_msgs", "%odom/nav_msgs")
        while not all(any("/MS/" in str(r.ok.key_expr) and w in str(r.ok.key_expr)
                          for r in session.liveliness().get("@ros2_lv/0/**", timeout=1.0) if r.ok is not None)
                      for w in wanted):
            publish("/scan", scan, _ns(scan.header.stamp))
            publish("/tf", odom_base, _ns(odom.header.stamp))
            time.sleep(STAND_PERIOD_NS / 1e9)
        print("bridge subscribed", flush=True)


        started, scans, last = time.monotonic(), 0, {}
        for topic, msg in messages:
            stamp = _ns(msg.header.stamp)
            time.sleep(max(0.0, (stamp - first) / 1e9 - (time.monotonic() - started)))
            name = "/scan" if topic == "/scan" else "/odom"
            publish(name, msg, stamp)
            last[name] = msg
            scans += name == "/scan"
            if scans == 10 and name == "/scan":
                x, y, yaw = goal
                pose = t["geometry_msgs/msg/Pose"](
                    position=t["geometry_msgs/msg/Point"](x=x, y=y, z=0.0),
                    orientation=t["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=math.sin(yaw / 2), w=math.cos(yaw / 2)))
                publish("/goal_pose", t["geometry_msgs/msg/PoseStamped"](
                    header=t["std_msgs/msg/Header"](stamp=msg.header.stamp, frame_id="map"), pose=pose), stamp)
                print("goal sent", flush=True)
        print("bag done; standing", flush=True)
        while True:     # until stopped
            stamp += STAND_PERIOD_NS
            for name, msg in last.items():
                msg.header.stamp = _time(t, stamp)
                publish(name, msg, stamp)
            time.sleep(STAND_PERIOD_NS / 1e9)


def listen_to_cmd_vel(session, me: NodeIdentity, store, msgtype: str) -> list:
    """The base's /cmd_vel subscription (entity 6 of this node: its publishers are 1..5), and its token."""
    type_hash = store.hash_rihs01(msgtype)
    heard = []

    def on_command(sample) -> None:
        msg = store.deserialize_cdr(sample.payload.to_bytes(), msgtype)
        twist = msg.twist if hasattr(msg, "twist") else msg
        if not heard and (abs(twist.linear.x) > 1e-3 or abs(twist.angular.z) > 1e-3):
            heard.append(True)
            frame, stamp = (msg.header.frame_id, _ns(msg.header.stamp)) if hasattr(msg, "header") else ("-", 0)
            print(f"cmd_vel heard: {msgtype} in frame {frame} stamped {stamp}", flush=True)
    subscriber = session.declare_subscriber(topic_key(0, "/cmd_vel", msgtype, type_hash), on_command)
    token = session.liveliness().declare_token(
        me.entity_token(me.nid + 6, SUBSCRIPTION, "/cmd_vel", msgtype, type_hash, Qos()))
    return [subscriber, token]


def _ns(time_msg) -> int:
    return int(time_msg.sec) * 1_000_000_000 + int(time_msg.nanosec)


def _transform(types, stamp_ns: int, parent: str, child: str, x: float, y: float, qz: float, qw: float):
    """A planar TransformStamped: parent -> child at (x, y), turned by the quaternion (0, 0, qz, qw)."""
    t = types
    return t["geometry_msgs/msg/TransformStamped"](
        header=t["std_msgs/msg/Header"](stamp=_time(t, stamp_ns), frame_id=parent), child_frame_id=child,
        transform=t["geometry_msgs/msg/Transform"](
            translation=t["geometry_msgs/msg/Vector3"](x=float(x), y=float(y), z=0.0),
            rotation=t["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=float(qz), w=float(qw))))


def _time(types, stamp_ns: int):
    sec, nanosec = divmod(stamp_ns, 1_000_000_000)
    return types["builtin_interfaces/msg/Time"](sec=sec, nanosec=nanosec)


if __name__ == "__main__":
    options = sys.argv[6:]
    main(sys.argv[1], sys.argv[2], (float(sys.argv[3]), float(sys.argv[4]), float(sys.argv[5])),
         tf_static="--no-tf-static" not in options,
         cmd_vel_type=options[options.index("--cmd-vel-type") + 1] if "--cmd-vel-type" in options
         else "geometry_msgs/msg/TwistStamped")
