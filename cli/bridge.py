"""`omninav bridge ros2`: omninav's navigation driving a ROS 2 robot that runs rmw_zenoh.

Runs compose/ros2_robot.yaml (localizer, costmap, planners, navigator, the command chain and the
ros2_bridge service; no simulator, chassis or lidar) with what differs per robot set from the
command line: the robot's domain and router, the map, the laser's mounting and the start pose.
README "Drive a ROS 2 robot" walks through the robot's side.
"""
from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

import yaml

from ..services.runtime import launcher
from ..services.runtime.params import ParamError, read_yaml
from ..services.runtime.zenoh_config import check_loopback

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
                        help="the laser on base_link: metres, metres, radians (as the robot's /tf says)")
    parser.add_argument("--initial-pose", nargs=3, type=float, metavar=("X", "Y", "YAW"),
                        help="where the robot starts in the map: metres, metres, radians (or RViz's 2D Pose "
                             "Estimate later)")
    parser.add_argument("--compose", default=str(COMPOSE), help=f"the stack to run (default {COMPOSE.name})")
    parser.add_argument("--for", dest="duration", type=float, metavar="SECONDS",
                        help="stop everything after this many seconds (default: run until Ctrl-C)")
    parser.add_argument("--credentials", metavar="FOLDER", help="as `omninav up --credentials`")


def stack(args: argparse.Namespace) -> dict:
    """The compose mapping to run: the file's, with the command line's values set (ValueError/ParamError
    naming what is wrong)."""
    source = Path(args.compose)
    data = read_yaml(source)
    services = {entry.get("name"): entry for entry in data.get("services", []) if isinstance(entry, dict)}
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
    if args.map is not None:
        map_file = Path(args.map).resolve()
        if not map_file.is_file():
            raise ValueError(f"--map {args.map}: no such file")
        services["map_server"].setdefault("params", {})["yaml_filename"] = str(map_file)
    for names, values in ((LASER, args.laser), (START, args.initial_pose)):
        for entry in services.values():
            params = entry.get("params") or {}
            for name, value in zip(names, values or ()):
                if name in params:
                    params[name] = value
    return data


def main(args: argparse.Namespace) -> int:
    try:
        data = stack(args)
    except (ValueError, ParamError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    with tempfile.TemporaryDirectory(prefix="omninav-bridge-") as folder:
        compose = Path(folder) / "ros2_robot.yaml"
        compose.write_text(yaml.safe_dump(data, sort_keys=False))
        return launcher.main(argparse.Namespace(compose=str(compose), router=None, duration=args.duration,
                                                credentials=args.credentials, lockstep=None))
