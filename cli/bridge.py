"""`omninav bridge ros2`: omninav's navigation driving a ROS 2 robot that runs rmw_zenoh.

Runs compose/ros2_robot.yaml (localizer, costmap, planners, navigator, the command chain and the
ros2_bridge service; no simulator, chassis or lidar) with what differs per robot set from the
command line: the robot's domain and router, the map, the laser's mounting and the start pose.
Without --laser the mounting is found on the robot before the stack starts: the chain of transforms
from its scans' frame to base_link on /tf and /tf_static (robot_state_publisher's), read as the
ros2_bridge reads them. The robot's router may ask for a login, as rmw_zenoh's security does: --zenoh-config
(usrpwd or TLS, checked: zenoh_config.checked_login_config) or --user/--password-file; a refused login
ends the command with one line, exit 2, before the stack starts, and so does a robot whose rmw_zenoh
is older than the bridge speaks (rmw.SUPPORTED_RMW_ZENOH, read from its graph: graph.py).
--cmd-vel-type says which message the robot's /cmd_vel takes (TwistStamped, Jazzy's default, or Twist).
README "Drive a ROS 2 robot" walks through the robot's side.
"""
from __future__ import annotations

import argparse
import dataclasses
import queue
import sys
import tempfile
import time
from pathlib import Path

import yaml
import zenoh

from ..services.ros2_bridge.translate import (CMD_VEL_TYPES, DEFAULT_CMD_VEL_TYPE, INPUTS, Mounting, Ros2BridgeParams,
                                               laser_mounting, typestore)
from ..services.ros2_bridge.node import (LoginRefused, OlderRmwZenoh, declare_ros_subscription, open_ros_session,
                                         refuse_older_peer, robot_graph, ros_endpoints, ros_login)
from ..services.ros2_bridge.rmw import NodeIdentity
from ..services.runtime import launcher
from ..services.runtime.params import read_yaml
from ..parameters.declare import ParamError
from ..services.runtime.zenoh_config import check_loopback, login_endpoints, login_refused

COMPOSE = Path(__file__).resolve().parents[1] / "compose" / "ros2_robot.yaml"
BRIDGE = "ros2_bridge"
LASER = ("laser_x", "laser_y", "laser_yaw")
START = ("initial_pose_x", "initial_pose_y", "initial_pose_a")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("middleware", choices=["ros2"], help="ros2: a ROS 2 robot with rmw_zenoh")
    parser.add_argument("--domain", type=int, help="the robot's ROS_DOMAIN_ID (default: the compose file's, 0)")
    parser.add_argument("--router", help="the robot's rmw_zenoh router, on loopback (default: the compose "
                                         "file's, tcp/127.0.0.1:7447)")
    parser.add_argument("--map", help="the robot's map, a map_server YAML (default: the compose file's)")
    parser.add_argument("--laser", nargs=3, type=float, metavar=("X", "Y", "YAW"),
                        help="the laser on base_link: metres, metres, radians (default: found on the robot's "
                             "/tf_static and /tf, from its /scan's frame)")
    parser.add_argument("--tf-timeout", type=float, default=10.0, metavar="S",
                        help="wall seconds to wait for the robot's /scan and transforms without --laser (default 10)")
    parser.add_argument("--initial-pose", nargs=3, type=float, metavar=("X", "Y", "YAW"),
                        help="where the robot starts in the map: metres, metres, radians (or RViz's 2D Pose "
                             "Estimate later)")
    parser.add_argument("--compose", default=str(COMPOSE), help=f"the stack to run (default {COMPOSE.name})")
    parser.add_argument("--for", dest="duration", type=float, metavar="SECONDS",
                        help="stop everything after this many seconds (default: run until Ctrl-C)")
    parser.add_argument("--credentials", metavar="FOLDER", help="as `omninav up --credentials`")
    parser.add_argument("--zenoh-config", metavar="FILE",
                        help="log in to the robot's router as this Zenoh JSON5 config says, e.g. the one "
                             "zenoh_security_tools makes for rmw_zenoh (transport/auth/usrpwd, transport/link/tls; "
                             "its connect/endpoints, if any, name the router); refused if it listens off loopback, "
                             "scouts or loads plugins (default: none, no credentials)")
    parser.add_argument("--user", help="log in to the robot's router with Zenoh's usrpwd as this user (with "
                                       "--password-file; default: none)")
    parser.add_argument("--password-file", metavar="FILE", help="the file holding --user's password alone")
    parser.add_argument("--cmd-vel-type", choices=list(CMD_VEL_TYPES),
                        help=f"the message the robot's /cmd_vel takes: twist_stamped (geometry_msgs/TwistStamped, "
                             f"what Jazzy's diff_drive_controller and Nav2 use) or twist (geometry_msgs/Twist); "
                             f"default: the compose file's, {DEFAULT_CMD_VEL_TYPE}")
    parser.add_argument("--cmd-vel-frame-id", metavar="FRAME",
                        help="a TwistStamped command's header.frame_id (default: the compose file's, base_link)")


def stack(args: argparse.Namespace) -> dict:
    """The compose mapping to run: the file's, with the command line's values set (ValueError/ParamError
    naming what is wrong)."""
    source = Path(args.compose)
    data = read_yaml(source)
    services = _services(data)
    if BRIDGE not in services:
        raise ValueError(f"{source}: has no service named {BRIDGE}")
    for entry in services.values():
        if "params_file" in entry:      # relative to the compose file, which is written elsewhere now
            entry["params_file"] = str((source.parent / entry["params_file"]).resolve())
    bridge = services[BRIDGE].setdefault("params", {})
    if args.domain is not None:
        if args.domain < 0:
            raise ValueError(f"--domain {args.domain}: a ROS domain id is ≥ 0")
        bridge["domain"] = args.domain
    if args.router is not None:
        bridge["ros_router"] = check_loopback(args.router)
    login = {"ros_zenoh_config": args.zenoh_config, "ros_password_file": args.password_file}
    bridge.update({name: str(Path(value).resolve()) for name, value in login.items() if value})
    if args.user:
        bridge["ros_user"] = args.user
    if args.cmd_vel_type:
        bridge["cmd_vel_type"] = args.cmd_vel_type
    if args.cmd_vel_frame_id:
        bridge["cmd_vel_frame_id"] = args.cmd_vel_frame_id
    given = ros_login(bridge_params(data))      # ValueError naming the key that is refused
    if given is not None and login_endpoints(given) and args.router is not None:
        raise ValueError(f"--router {args.router} and connect/endpoints of --zenoh-config {args.zenoh_config}: "
                         f"give the robot's router once")
    if args.map is not None:
        map_file = Path(args.map).resolve()
        if not map_file.is_file():
            raise ValueError(f"--map {args.map}: no such file")
        services["map_server"].setdefault("params", {})["yaml_filename"] = str(map_file)
    set_params(services, LASER, args.laser)
    set_params(services, START, args.initial_pose)
    return data


def _services(data: dict) -> dict[str, dict]:
    return {entry.get("name"): entry for entry in data.get("services", []) if isinstance(entry, dict)}


def set_params(services: dict[str, dict], names: tuple[str, ...], values) -> None:
    """names[i] = values[i] in every service that has that parameter (nothing where values is None)."""
    for entry in services.values():
        params = entry.get("params") or {}
        for name, value in zip(names, values or ()):
            if name in params:
                params[name] = value


def mount_laser_from_tf(data: dict, timeout_s: float) -> str:
    """Find the laser's mounting on the robot (find_laser) and set it where --laser would; what was found,
    as a line to print (LookupError naming what is missing)."""
    (x, y, yaw), how = find_laser(bridge_params(data), timeout_s)
    set_params(_services(data), LASER, (x, y, yaw))
    return f"laser mounting from {how} x={x:.4f} y={y:.4f} yaw={yaw:.4f}"


def bridge_params(data: dict) -> Ros2BridgeParams:
    given = _services(data)[BRIDGE].get("params") or {}
    return Ros2BridgeParams(**{f.name: given[f.name] for f in dataclasses.fields(Ros2BridgeParams) if f.name in given})


def find_laser(params: Ros2BridgeParams, timeout_s: float) -> tuple[tuple[float, float, float], str]:
    """The laser on params.base_frame and how it was found (bridge.laser_mounting), from the robot's /scan,
    /tf and /tf_static, subscribed to as the ros2_bridge node does (/tf_static from the publishers'
    caches: robot_state_publisher sent it once, long ago). Waits at most timeout_s of wall time (there is
    no clock yet), then raises laser_mounting's LookupError."""
    store, inbox = typestore(), queue.SimpleQueue()
    scan_frame, mounting = None, Mounting()
    deadline = time.monotonic() + timeout_s
    ros = _open_robot_session(params, deadline)
    with ros:
        me = NodeIdentity(params.domain, str(ros.info.zid()), f"{params.node_name}_setup", params.namespace)
        handles = [ros.liveliness().declare_token(me.node_token())]
        listened = [topic for topic in INPUTS if topic.name in ("/scan", "/tf", "/tf_static")]
        for entity_id, topic in enumerate(listened, start=me.nid + 1):
            handles += declare_ros_subscription(ros, me, entity_id, topic, store.hash_rihs01(topic.msgtype),
                                                lambda payload, _, t=topic: inbox.put((t, payload)))
        try:
            while True:
                try:
                    return laser_mounting(scan_frame, mounting, params.base_frame)
                except LookupError:
                    if time.monotonic() >= deadline:
                        raise
                try:
                    topic, payload = inbox.get(timeout=max(0.0, deadline - time.monotonic()))
                except queue.Empty:
                    continue
                try:
                    msg = store.deserialize_cdr(payload, topic.msgtype)
                except Exception:   # rosbags raises several kinds; the bridge node counts such samples
                    continue
                if topic.name == "/scan":
                    scan_frame = msg.header.frame_id.lstrip("/")
                else:
                    mounting.update(msg, topic.name)
        finally:
            for handle in handles:
                handle.undeclare()


def _open_robot_session(params: Ros2BridgeParams, deadline: float) -> zenoh.Session:
    """A session with the robot's router, tried until the deadline (LookupError if it never answers,
    LoginRefused if it refuses the login), on a robot the bridge can drive (OlderRmwZenoh if not)."""
    session = open_ros_session(params, lambda: time.monotonic() >= deadline)
    if session is None:
        raise LookupError(f"the robot's router at {', '.join(ros_endpoints(params))} does not answer "
                          "(is rmw_zenohd running?)")
    try:
        refuse_older_peer(robot_graph(session, params.domain))
    except OlderRmwZenoh:
        session.close()
        raise
    return session


def check_robot(params: Ros2BridgeParams, timeout_s: float) -> None:
    """With --laser nothing joins the robot before the stack: if its router is there now, log in once
    (LoginRefused if it refuses) and read its graph (OlderRmwZenoh); if not, the bridge waits for it
    (and refuses then, alone)."""
    if login_refused(ros_endpoints(params)):
        _open_robot_session(params, time.monotonic() + timeout_s).close()


def main(args: argparse.Namespace) -> int:
    try:
        if args.tf_timeout <= 0:
            raise ValueError(f"--tf-timeout {args.tf_timeout:g}: wall seconds > 0")
        data = stack(args)
    except (ValueError, ParamError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    try:
        if args.laser is not None:
            check_robot(bridge_params(data), args.tf_timeout)
        else:
            print(mount_laser_from_tf(data, args.tf_timeout), flush=True)
    # a refused login, a robot too old, the compose file's ros_router off loopback
    except (LoginRefused, OlderRmwZenoh, ValueError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    except LookupError as exc:
        print(f"error: {exc} within {args.tf_timeout:g} s" + ("" if args.laser else
              "; give the laser's mounting by hand: --laser X Y YAW"), file=sys.stderr)
        return 2
    with tempfile.TemporaryDirectory(prefix="omninav-bridge-") as folder:
        compose = Path(folder) / "ros2_robot.yaml"
        compose.write_text(yaml.safe_dump(data, sort_keys=False))
        return launcher.main(argparse.Namespace(compose=str(compose), router=None, duration=args.duration,
                                                credentials=args.credentials, lockstep=None, prepared=False))
