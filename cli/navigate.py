"""`omninav navigate --world W --goal X Y YAW [--goal …]`: one navigation mission in the simulator.

Every service runs as its own process under `omninav up` (a compose file written into the run's
folder): recorder, sim, chassis, lidar, map_server (the world's
map; a world without a shipped map is rasterized into the run's folder), the localization (amcl:
the localizer on that map starting at the world's start pose; slam: the slam service, which then
serves the map; truth: truth_pose, the ground truth relayed as the pose), costmap, global_planner
(answering the navigator's plan_request), local_planner, velocity_smoother, collision_monitor and
navigator. Once every service is alive, the goals are sent one after another on `goal` (stamped
with the sim clock); each ends with its nav_status (succeeded, aborted, canceled) or, after
--timeout sim seconds, with a cancel. A failed goal ends the mission. Then everything is stopped
(the recorder last) and the summary is computed from the recording (experiments/mission_score.py).

A crash does not end the mission: `up` restarts every service but the sim and the recorder
(restart: on-failure, at most MAX_RESTARTS times), and each resumes from a state file in the run's
folder (state/): the localizer its pose, the chassis its odometry, the navigator its active goal;
the costmap and the planners rebuild from the map the map server publishes every sim second. The
summary counts the restarts (from the services' Diagnostics). The mission gives up when the sim or
the recorder dies, when a service stays down longer than DOWN_LIMIT_S or when `up` ends: it then
prints the summary of what the recording holds so far (a partial one) and exits 2.

Exit status: 0 every goal reached without collision; 1 the mission failed; 2 a user error (unknown
world, a goal outside the map) or a service that could not start, or one the mission could not
do without — the recording is kept.
"""
from __future__ import annotations

import argparse
import json
import logging
import math
import os
import queue
import shutil
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import yaml
import zenoh

from ..schemas import decode
from ..schemas.keys import DEFAULT_ROBOT, KeyLayout
from ..schemas.messages import CancelGoal, Clock, Goal, Header, NavStatus, Pose2D
from ..services.chassis.kinematics import DRIVES
from ..services.local_planner.control import CONTROLLERS
from ..services.map_server.mapio import MapError, load_map, save_map
from ..experiments.mission_score import (TERMINAL, MissionError, goal_tolerance, load_mission, summarize_mission,
                                         summary_lines)
from ..services.runtime.acl import CREDENTIALS_ENV, OPERATOR
from ..services.runtime.child import Child, call_in_child
from ..services.runtime.errors import UserError, exits_2_on_user_error
from ..experiments.lockstep_mission import GoalSequencer
from ..services.runtime.live import LiveRunner, tokens_present
from ..services.runtime.lockstep import Lockstep
from ..services.runtime.node import CLOCK_TOPIC, NS_PER_S, Node
from ..services.runtime.zenoh_config import ROUTER_ENV, free_loopback_endpoint, open_client, router_endpoint
from ..sim.node import open_world
from ..sim.world import World, WorldError, world_path
from .goal_args import add_goal_argument
from .profile import Profile, load_profile

REPO = Path(__file__).resolve().parents[1]
PARAMS = REPO / "compose" / "params"
SHIPPED_MAPS = {"room": REPO / "compose" / "maps" / "room.yaml"}   # shipped world name -> its map file
MAP_RESOLUTION = 0.05
LOCALIZATIONS = ("amcl", "slam", "truth", "odom")
# the odometry the stack runs on: the chassis's own (its wheels, or follower wheels and gyro), or
# wheels, gyro and laser odometry fused (services/ekf, services/laser_odometry: a push or a slip the
# wheels miss is seen); auto fuses where nothing else would see one - without a map, or on a robot
# without follower wheels (issue 36)
ODOMETRIES = ("auto", "chassis", "fused")
# the navigator's arrival check, tighter than move_base's 0.10 m / 0.05 rad: the local planner's
# final approach stops within 0.02 m / 0.02 rad, and a mission aims for 5 cm and 2°; success only
# once nearly stopped, so the commands still on their way (about 0.1–0.3 s) cannot carry it past;
# a robot that stands still for 10 s (move_base's oscillation check, off by default) recovers;
# the plan is made again every sim second (Nav2's default tree; move_base's planner_frequency is 0),
# so that it moves aside from where the global costmap's mover layer says people will walk
NAVIGATOR = {"xy_goal_tolerance": 0.03, "yaw_goal_tolerance": 0.03, "trans_stopped_vel": 0.02,
             "rot_stopped_vel": 0.02, "oscillation_timeout": 10.0, "oscillation_distance": 0.2,
             "planner_frequency": 1.0}
# the world's robot (the mecanum paper's) has follower wheels and a gyro: odometry from them rolls
# with the ground, so a person who shoves the robot moves its odometry too, and AMCL stays on the
# robot instead of being left where the wheels say it stood (a profile's robot keeps its own)
FOLLOWER_ODOMETRY = {"odom_source": "followers"}
# with a push in the odometry, amcl_paper.yaml's quick kidnapping recovery (0.01 / 0.5) has nothing
# left to find and only harms: people hiding walls dip the recent fit, random poses go in and the
# pose wanders (generated crossing and head-on worlds: median error 0.76 m against 0.02 m with
# ROS's suggested 0.001 / 0.1, the same recordings replayed into the localizer)
RECOVERY_WITH_FOLLOWERS = {"recovery_alpha_slow": 0.001, "recovery_alpha_fast": 0.1}
# where a mission's localizer departs from ROS amcl (docs/localizer.md): it keeps converging while
# the robot stands (a shove or a late correction is not left standing), and its recovery draws half
# its random poses near the estimate (a shove moves the robot a little). It keeps amcl's reset of the
# weight averages after an injection: without it, a place whose scans fit the map less well for good
# (a room past a door, people in view) kept the injection going and the filter never settled
# (generated doorway worlds: 3.3 m off against 8 cm, the same recordings replayed into the localizer)
LOCALIZER_BEYOND_ROS = {"temporal_update": 0.2, "recovery_local_share": 0.5}
# without a map the plan was made through unknown space: replan as the scans fill it in
MAPLESS_NAVIGATOR = {"planner_frequency": 2.0}
# the chassis's parameters that say how the robot follows a command: the collision monitor's model of it
CHASSIS_RESPONSE = ("cmd_vel_delay_s", "acc_lim_x", "acc_lim_y", "acc_lim_theta")
SETTLE_S = 1.0          # sim s after the last goal ends: the robot comes to rest before the stop
CANCEL_WAIT_S = 2.0     # sim s to wait for the navigator to confirm a cancel
POLL_S = 0.1
STOP_TIMEOUT_S = 300     # wall s for `up` to stop everything (the recorder may take 120 s on a loaded machine)
READY_TIMEOUT_S = 300   # wall s for every service to come up (numba warm-ups on a loaded machine)
# --composed: the containers (compose `process`) of a mission; unnamed services go to the last one.
# two: the simulated hardware beside the robot's stack, as on a robot whose drivers run apart
# the recorder sits with the simulator: neither restarts, so the robot's container can
CONTAINERS = {"two": {"simulator": ("sim", "chassis", "lidar", "recorder"), "robot": ()}, "one": {"stack": ()}}
CLOCK_WAIT_S = 30.0     # wall s for the first clock once every service is alive
STALL_S = 120.0         # wall s without a sim step in lockstep before the mission is given up
# a restarted sim would start its clock again from 0, a restarted recorder its file afresh: without
# either the mission cannot go on; every other service is restarted and resumes
NOT_RESTARTED = ("sim", "recorder")
MAX_RESTARTS = 5        # per service; a service that keeps dying is given up on
DOWN_LIMIT_S = 180.0    # wall s a service may stay down (backoff, imports, numba on a loaded machine)
SAVE_RATE_HZ = 2.0      # sim Hz at which the localizer saves its pose


class NavigateError(UserError):
    """A user error or a mission that could not run: one line, exit status 2."""


# ---------------------------------------------------------------- the mission, as a Node on the bus

class MissionNode(Node):
    """Publishes the goals and cancels the main thread hands it, stamped with the sim clock, and
    keeps the latest nav_status of every goal. The clock is not one of its inputs: the mission needs
    the sim time only to stamp a goal and to judge a timeout, so it reads the newest clock message
    when it needs it (watch_clock: a one-slot ring that Zenoh's own thread fills) instead of waking
    its Python thread for each of the simulator's 100 a second (about 0.03 of a core live)."""
    service = "navigate"

    def setup(self) -> None:
        self.goal_pub = self.publisher("goal")
        self.cancel_pub = self.publisher("cancel")
        self.subscribe("nav_status", self.on_status, synced=False)
        self.outbox: queue.SimpleQueue = queue.SimpleQueue()
        self.statuses: dict[str, NavStatus] = {}
        self._clock = None
        self._clock_ns = 0
        self._clock_lock = threading.Lock()

    def watch_clock(self, session: zenoh.Session) -> None:
        self._clock = session.declare_subscriber(self.keys.resolve(CLOCK_TOPIC), zenoh.handlers.RingChannel(1))

    def sim_now_ns(self) -> int:
        """The stamp of the newest clock message (0 before the first)."""
        with self._clock_lock:
            sample = self._clock.try_recv() if self._clock is not None else None
            if sample is not None:
                self._clock_ns = max(self._clock_ns, decode(sample.payload.to_bytes(), Clock).header.stamp_ns)
            return self._clock_ns

    def wait_clock(self, timeout_s: float) -> bool:
        """Until the first clock message (False after timeout_s wall seconds without one)."""
        deadline = time.monotonic() + timeout_s
        while not self.sim_now_ns():
            if time.monotonic() > deadline:
                return False
            time.sleep(POLL_S)
        return True

    def on_status(self, msg: NavStatus) -> None:
        self.statuses[msg.goal_id] = msg

    def pace_s(self) -> float:
        return POLL_S / 2

    def tick(self) -> None:
        if self.outbox.empty() or not self.sim_now_ns():
            return
        self.now_ns = max(self.now_ns, self.sim_now_ns())
        while True:
            try:
                msg = self.outbox.get_nowait()
            except queue.Empty:
                return
            msg.header = self.header("map")
            (self.goal_pub if isinstance(msg, Goal) else self.cancel_pub).publish(msg)

    def send(self, msg: Goal | CancelGoal) -> None:
        self.outbox.put(msg)


# ---------------------------------------------------------------- the compose file

def map_for(world: World, name: str, folder: Path) -> Path:
    """The map_server YAML of the world: the shipped one, or the world rasterized into `folder`."""
    shipped = SHIPPED_MAPS.get(name)
    if shipped is not None and Path(world.source).resolve() == world_path(name).resolve():
        return shipped
    return save_map(world.rasterize(MAP_RESOLUTION), folder / f"{world.name}_map")


def state_files(state_dir: Path | None) -> dict[str, dict]:
    """Per service, the parameters that make it keep its state in `state_dir` and resume from it
    after a restart; none without a folder."""
    if state_dir is None:
        return {}
    return {"localizer": {"pose_file": str(state_dir / "localizer_pose.yaml"), "save_pose_rate": SAVE_RATE_HZ},
            "chassis": {"odom_file": str(state_dir / "chassis_odom.yaml")},
            "navigator": {"goal_file": str(state_dir / "navigator_goal.yaml")}}


def localization_service(kind: str, start: dict, map_file: Path, seed: int, followers: bool) -> dict:
    if kind == "truth":
        return {"name": "truth_pose", "service": "truth_pose"}
    if kind == "slam":
        return {"name": "slam", "service": "slam", "params": {**start, "seed": seed}}
    return {"name": "localizer", "service": "localizer", "params_file": str(PARAMS / "amcl_paper.yaml"),
            "params": {"map_file": str(map_file), **start, "seed": seed, **LOCALIZER_BEYOND_ROS,
                       **(RECOVERY_WITH_FOLLOWERS if followers else {}),
                       "initial_cov_xx": 0.0025, "initial_cov_yy": 0.0025, "initial_cov_aa": 0.0025}}


HOLONOMIC_STRAFE = 0.3     # m/s: as far as base_local_planner's y_vels reach; dwa's ±0.1 leaves a person's way too slowly


# TEB for these robots: among the tracked people (include_dynamic_obstacles, off in TEB by default);
# its clearances (teb_local_planner's defaults, 0.5 / 0.6 m from the footprint, leave no way through
# a 0.9 m door for a 0.64 m wide robot), people kept farther than walls; a long holonomic robot
# facing the way it goes (weight_strafe, docs/local_planner.md)
TEB_SETTINGS = {"include_dynamic_obstacles": True, "min_obstacle_dist": 0.05, "inflation_dist": 0.3,
                "dynamic_obstacle_inflation_dist": 0.8, "weight_strafe": 1.0}


def controller_params(controller: str | None) -> dict:
    """The local planner's settings for a controller other than its default (DWA)."""
    if controller is None:
        return {}
    return {"controller": controller, **({"teb": TEB_SETTINGS} if controller == "teb" else {})}


def drive_params(drive: str) -> dict:
    """The local planner's settings for the drive: a differential drive cannot strafe, the
    holonomic drives strafe out of a person's way at up to HOLONOMIC_STRAFE (docs/scenarios.md)."""
    if drive == "diff":
        return {"holonomic_robot": False, "max_vel_y": 0.0, "min_vel_y": 0.0, "y_vels": []}
    return {"max_vel_y": HOLONOMIC_STRAFE, "min_vel_y": -HOLONOMIC_STRAFE}


def robot_params(profile: Profile | None) -> dict[str, dict]:
    """Per service, the parameters a robot profile sets: its footprint where a service takes one,
    then the profile's own `params`; the simulator drives the wheels the chassis drives and moves
    the profile's `body` (its real outline, mass and ground: no other service sees it), and the
    collision monitor's model of how the robot follows its commands is the chassis's (unless set)."""
    if profile is None:
        return {}
    footprint = [list(p) for p in profile.footprint]
    out = {"sim": {"footprint": footprint}, "collision_monitor": {"footprint": footprint},
           "local_planner": {"footprint": footprint, "footprint_padding": profile.footprint_padding}}
    for service, values in profile.params.items():
        out[service] = {**out.get(service, {}), **values}
    out["sim"]["chassis"] = out.get("chassis", {})      # the simulated wheels are the chassis's
    if profile.body:
        out["sim"]["body"] = profile.body
    response = {k: v for k, v in out["sim"]["chassis"].items() if k in CHASSIS_RESPONSE}
    out["collision_monitor"] = {**response, **out["collision_monitor"]}
    return out


def fuses_odometry(odometry: str, localization: str, followers: bool) -> bool:
    """Whether a mission runs on fused odometry (ODOMETRIES); the simulator's truth needs none."""
    return odometry == "fused" or (odometry == "auto" and localization != "truth"
                                   and (localization == "odom" or not followers))


def compose_for(world: World, world_file: Path, map_file: Path, drive: str, localization: str, recording: Path,
                seed: int, rate: float, robot: str, profile: Profile | None = None,
                sim_dt: float | None = None, state_dir: Path | None = None, controller: str | None = None,
                odometry: str = "auto") -> dict:
    """The compose mapping of a mission (absolute paths: `up` may run anywhere). `profile`: the
    robot (cli/profile.py), else the world's robot with the sample parameters. With localization
    `odom` there is no map: no map_server, no localizer, and a global costmap of the robot's own
    scans (map→odom stays the start pose). `sim_dt`: the simulator's step (default its own).
    `state_dir`: where the localizer, chassis and navigator keep what they resume from after a restart.
    `controller`: the local planner's (default its own, DWA). `odometry`: ODOMETRIES."""
    x, y, yaw = (float(v) for v in world.robot.start)
    start = {"initial_pose_x": x, "initial_pose_y": y, "initial_pose_a": yaw}
    followers = profile is None        # the world's robot has follower wheels; a profile's says what it has
    fused = fuses_odometry(odometry, localization, followers)
    common = profile.costmap_common_params if profile is not None else PARAMS / "costmap_common_params.yaml"
    own_files = {"global": PARAMS / ("costmap_global_mapless_params.yaml" if localization == "odom" else
                                     "costmap_global_movers_params.yaml"),
                 "local": (profile and profile.costmap_local_params) or PARAMS / "costmap_local_params.yaml"}
    costmap_files = {f"{which}_costmap_files": [str(common), str(own)] for which, own in own_files.items()}
    if controller == "teb" and localization != "odom":
        costmap_files["global_costmap_files"].append(str(PARAMS / "costmap_global_teb_params.yaml"))
    services = [
        {"name": "recorder", "service": "recorder", "params": {"output": str(recording)}},
        {"name": "sim", "service": "sim", "params": {"world": str(world_file), "drive": drive, "seed": seed,
                                                     "rate": rate, **({"dt": sim_dt} if sim_dt else {})}},
        {"name": "chassis", "service": "chassis",
         "params": {"drive": drive, **(FOLLOWER_ODOMETRY if followers else {}), "fused_odometry": fused}},
        {"name": "lidar", "service": "lidar", "params": {"world": str(world_file)}},
    ]
    if fused:
        services += [{"name": "laser_odometry", "service": "laser_odometry"}, {"name": "ekf", "service": "ekf"}]
    if localization in ("amcl", "truth"):      # slam serves its own map; odom has none
        services.append({"name": "map_server", "service": "map_server",
                         "params": {"yaml_filename": str(map_file), "publish_period_s": 1.0}})
    if localization != "odom":
        services.append(localization_service(localization, start, map_file, seed, followers))
    services += [
        {"name": "costmap", "service": "costmap", "params": {**costmap_files, **start}},
        # slam's map is still being drawn (and where people walked): the evidence grid alone tells the
        # tracker the static world then
        {"name": "tracker", "service": "tracker", "params": {**start, "use_map": localization != "slam"}},
        {"name": "global_planner", "service": "global_planner",
         "params": {"goal_topic": "plan_request", "planner_frequency": 0.0, "use_dijkstra": False, **start}},
        {"name": "local_planner", "service": "local_planner",
         "params": {**drive_params(drive), **controller_params(controller), **start}},
        {"name": "cmd_vel_mux", "service": "cmd_vel_mux"},
        {"name": "velocity_smoother", "service": "velocity_smoother"},
        {"name": "collision_monitor", "service": "collision_monitor",
         "params": {"chassis_period_s": sim_dt} if sim_dt else {}},
        {"name": "navigator", "service": "navigator",
         "params": {**start, **NAVIGATOR, **(MAPLESS_NAVIGATOR if localization == "odom" else {}),
                    "use_odometry_doubt": localization == "odom"}},
    ]
    overrides, resume = robot_params(profile), state_files(state_dir)
    for service in services:
        name = service["name"]
        extra = {**resume.get(name, {}), **overrides.get(name, {})}
        if extra:
            service["params"] = {**service.get("params", {}), **extra}
        if name in NOT_RESTARTED:
            service["restart"] = "no"
        else:
            service["restart"], service["max_restarts"] = "on-failure", MAX_RESTARTS
    return {"robot": robot, "services": services}


def in_containers(services: list[dict], how: str) -> list[dict]:
    """The services with their container (compose `process`) set, as CONTAINERS[how] groups them. A
    container restarts as a whole: not at all when it holds a service that is not restarted."""
    groups = CONTAINERS[how]
    last = list(groups)[-1]
    placed = [{**s, "process": next((c for c, names in groups.items() if s["name"] in names), last)} for s in services]
    frozen = {s["process"] for s in placed if s["name"] in NOT_RESTARTED}
    return [{**s, "restart": "no", "max_restarts": None} if s["process"] in frozen else s for s in placed]


# ---------------------------------------------------------------- arguments

def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--world", required=True, help="a shipped world's name (room, office, ...) or a world file")
    add_goal_argument(parser, "a goal in the map frame (default: the world file's goals)")
    parser.add_argument("--drive", choices=DRIVES, help="the robot's drive (default: the world's)")
    parser.add_argument("--localization", choices=LOCALIZATIONS, default="amcl",
                        help="amcl on the world's map (default), slam, truth (the simulator's true pose), or "
                             "odom (no map: odometry alone, costmaps from the robot's own scans)")
    parser.add_argument("--profile", help="a robot profile: a shipped one's name (jackal) or a profile file "
                                          "(default: the world's robot)")
    parser.add_argument("--odometry", choices=ODOMETRIES, default="auto",
                        help="chassis (its wheels, or follower wheels and gyro), fused (wheels, gyro and laser "
                             "odometry in an EKF, which sees pushes and slips), or auto (default: fused without a "
                             "map or without follower wheels)")
    parser.add_argument("--controller", choices=CONTROLLERS,
                        help="the local planner's controller (default its own: dwa; teb plans among the tracked people)")
    parser.add_argument("--record", metavar="FILE", help="the recording (default OUT/run.mcap)")
    parser.add_argument("-o", "--out", help="folder for the compose file, map and logs "
                                            "(default out/navigate-<date>-<time>)")
    parser.add_argument("--timeout", type=float, default=120.0, metavar="S",
                        help="sim seconds allowed per goal before it is canceled (default 120)")
    parser.add_argument("--seed", type=int, default=0,
                        help="seed of the simulator's noise and of the localization's filter (default 0)")
    parser.add_argument("--rate", type=float, help="sim seconds per wall second (default 1; with --lockstep: as "
                                                   "fast as the services compute, and at most this fast if given)")
    parser.add_argument("--robot", default=DEFAULT_ROBOT, help="robot namespace (default r1)")
    parser.add_argument("--sim-dt", type=float, metavar="S",
                        help="the simulator's step, s (default its own, 0.01; contacts are looked for in "
                             "substeps of at most 2 ms whatever the step)")
    stepping = parser.add_mutually_exclusive_group()
    stepping.add_argument("--lockstep", action="store_true",
                          help="step the simulator only when every service is done with the last step "
                               "(services/runtime/lockstep.py): no wall clock in the loop, so the same "
                               "messages at any machine load, as fast as the services compute (or at most "
                               "--rate)")
    stepping.add_argument("--in-process", action="store_true",
                          help="run every service in this one process, in lockstep with the simulator "
                               "(the same recording byte for byte every time; --composed does not apply)")
    parser.add_argument("--composed", nargs="?", const="two", choices=sorted(CONTAINERS),
                        help="run the services in containers rather than a process each: two (the default: "
                             "sim, chassis and lidar in one, the rest in the other) or one")
    parser.add_argument("--json", action="store_true", help="print the summary as one JSON object")
    parser.add_argument("--quiet", action="store_true",
                        help="no progress lines (services starting and up, goals sent and ended); the summary only")


def mission_goals(args: argparse.Namespace, world: World) -> np.ndarray:
    """The goals (K, 3) in metres and radians; NavigateError if one lies outside the world's map."""
    if args.goal:
        goals = np.array(args.goal)            # radians already (goal_args)
    elif len(world.goals):
        goals = world.goals.copy()
    else:
        raise NavigateError(f"world {world.name!r} names no goals: give --goal X Y YAW")
    xmin, ymin, xmax, ymax = world.extent
    for x, y, yaw in goals:
        if not all(math.isfinite(v) for v in (x, y, yaw)):
            raise NavigateError(f"goal ({x}, {y}, {yaw}) is not a finite pose")
        if world.outside(np.array([x, y])):
            raise NavigateError(f"goal ({x:g}, {y:g}) lies outside the map of {world.name!r}, which spans "
                                f"x {xmin:g}..{xmax:g}, y {ymin:g}..{ymax:g} m")
    return goals


def check_goals(map_file: Path, world: World, goals: np.ndarray) -> None:
    """NavigateError naming every goal (or the start) in an obstacle or out of reach on the map.
    navigate runs it in a child process (services/runtime/child.py): its A* and distance transform
    import numba and scipy, 90 MB that navigate would hold for the whole mission."""
    from ..experiments.reachability import mission_problems

    try:
        grid = load_map(map_file)
    except MapError as exc:
        raise NavigateError(f"the mission's map is not usable: {exc}") from None
    problems = mission_problems(grid, world.robot.footprint, world.robot.start, goals)
    if problems:
        raise NavigateError(f"on the map {map_file}: " + "; ".join(problems))


def check_and_prepare(map_file: Path, world: World, goals: np.ndarray, compose: dict, compose_file: Path):
    """In a child process: yields None once the goals are checked (check_goals), then writes the
    compose file and yields what `up` makes of it (launcher.prepare: the file loaded, then every
    identity's rights): `up --prepared` takes them, so one child imports the stack, not two, and
    `up` builds no Node to open its router."""
    from ..services.runtime.launcher import prepare

    check_goals(map_file, world, goals)
    yield None
    # what loading and building say (parameters without effect…) each service says again in
    # services.log as it starts; here it would land on navigate's terminal
    logging.disable(logging.WARNING)
    compose_file.write_text(yaml.safe_dump(compose, sort_keys=False))
    yield from prepare(compose_file)


def check_numbers(args: argparse.Namespace) -> None:
    for name, value in (("--timeout", args.timeout), ("--rate", 1.0 if args.rate is None else args.rate),
                        ("--sim-dt", 0.01 if args.sim_dt is None else args.sim_dt)):
        if not (math.isfinite(value) and value > 0):
            raise NavigateError(f"{name} must be a positive number, got {value:g}")
    if args.seed < 0:
        raise NavigateError(f"--seed must be ≥ 0, got {args.seed}")


# ---------------------------------------------------------------- running it

class ServiceDied(Exception):
    """A service of the mission is gone."""


class Mission:
    """The running stack: `up`, the mission node, and a liveliness subscriber that notices a
    service whose token goes away (its process ended; `up` restarts it) and comes back."""

    def __init__(self, router: str, names: list[str], up: subprocess.Popen, node: MissionNode | GoalSequencer,
                 log: Path, say, lockstep: Lockstep | None = None):
        self.names, self.up, self.log, self.say = names, up, log, say
        self.node = node
        self.runner = LiveRunner(self.node, router, lockstep=lockstep)
        self.worker = threading.Thread(target=self.runner.run, name="navigate-bus", daemon=True)
        self.session = open_client(router)
        self.down: dict[str, float] = {}        # service -> when (monotonic) its token went away
        self.watch = self.session.liveliness().declare_subscriber(node.keys.alive_of_all(), self._on_token)
        if isinstance(node, MissionNode):
            node.watch_clock(self.session)

    def _on_token(self, sample) -> None:
        name = KeyLayout.service_of_alive(str(sample.key_expr))
        if name not in self.names:
            return
        if sample.kind == zenoh.SampleKind.DELETE:
            self.down[name] = time.monotonic()
            self.say(f"{name} stopped at sim {self.now_s:.1f} s" +
                     ("" if name in NOT_RESTARTED else "; up restarts it"))
        elif self.down.pop(name, None) is not None:
            self.say(f"{name} is back at sim {self.now_s:.1f} s")

    @property
    def now_s(self) -> float:
        now_ns = self.node.sim_now_ns() if isinstance(self.node, MissionNode) else self.node.now_ns
        return now_ns / NS_PER_S

    def __enter__(self) -> "Mission":
        self.worker.start()
        return self

    def __exit__(self, *exc) -> None:
        self.runner.stop()
        self.worker.join(10.0)
        self.watch.undeclare()
        self.session.close()

    def check_alive(self) -> None:
        """ServiceDied naming a service the mission cannot do without (the sim, the recorder) or
        one down longer than DOWN_LIMIT_S, or if `up` ended."""
        now = time.monotonic()
        lost = sorted(name for name, since in self.down.items()
                      if name in NOT_RESTARTED or now - since > DOWN_LIMIT_S)
        if lost:
            raise ServiceDied(f"service(s) {', '.join(lost)} stopped and did not come back; see {self.log}")
        if self.up.poll() is not None:
            raise ServiceDied(f"omninav up ended (exit {self.up.returncode}); see {self.log}")

    def wait_sim(self, done, seconds: float) -> bool:
        """Until done() or `seconds` of sim time have passed (False then); checks the services."""
        until = self.now_s + seconds
        while not done():
            if self.now_s >= until:
                return False
            self.check_alive()
            time.sleep(POLL_S)
        return True

    def run_goal(self, goal_id: str, pose, timeout_s: float, say) -> str:
        """Send one goal and wait for its end; the final status ('timeout' if it had to be canceled)."""
        node = self.node
        x, y, yaw = (float(v) for v in pose)
        node.send(Goal(header=Header(), goal_id=goal_id, pose=Pose2D(x, y, yaw)))
        say(f"{goal_id}: goal ({x:.2f}, {y:.2f}, {math.degrees(yaw):.1f} deg) sent at sim {self.now_s:.1f} s")

        def ended() -> bool:
            status = node.statuses.get(goal_id)
            return status is not None and status.status in TERMINAL

        if not self.wait_sim(ended, timeout_s):
            node.send(CancelGoal(header=Header(), goal_id=goal_id))
            self.wait_sim(ended, CANCEL_WAIT_S)
            say(f"{goal_id}: no result within {timeout_s:g} sim s; canceled")
            return "timeout"
        status = node.statuses[goal_id]
        say(f"{goal_id}: {status.status}{f' ({status.reason})' if status.reason else ''} at sim {self.now_s:.1f} s")
        return status.status


def follow_sequence(mission: Mission, sequencer: GoalSequencer, say) -> None:
    """Until the sequencer (which sends the goals on the sim clock, in lockstep) is done; says what
    each goal came to; ServiceDied if the stack cannot go on."""
    told, last_step, stepped_at = 0, -1.0, time.monotonic()
    while not sequencer.finished:
        mission.check_alive()
        if mission.now_s != last_step:
            last_step, stepped_at = mission.now_s, time.monotonic()
        elif time.monotonic() - stepped_at > STALL_S:
            raise ServiceDied(f"the simulator has not stepped for {STALL_S:g} s (lockstep: its log says "
                              f"whom it waits for); see {mission.log}")
        for goal_id, outcome in list(sequencer.outcomes.items())[told:]:
            say(f"{goal_id}: {outcome} at sim {mission.now_s:.1f} s")
            told += 1
        time.sleep(POLL_S)
    for goal_id, outcome in list(sequencer.outcomes.items())[told:]:
        say(f"{goal_id}: {outcome}")


def wait_until_ready(router: str, names: list[str], up: subprocess.Popen, robot: str, say) -> bool:
    """Until every service of the compose file has declared its liveliness token (or up died);
    says which are up whenever more are."""
    keys = KeyLayout(robot)
    deadline = time.monotonic() + READY_TIMEOUT_S
    while not Path(os.environ[CREDENTIALS_ENV]).exists():     # `up` writes the run's identities first
        if up.poll() is not None or time.monotonic() > deadline:
            return False
        time.sleep(POLL_S)
    ready: set[str] = set()
    session = open_client(router, stopped=lambda: up.poll() is not None or time.monotonic() > deadline)
    if session is None:
        return False
    with session:
        while time.monotonic() < deadline and up.poll() is None:
            alive = {keys.service_of_alive(key) for key in tokens_present(session, [keys.alive(n) for n in names])}
            if len(alive) > len(ready):
                waiting = [n for n in names if n not in alive]
                say(f"{len(alive)}/{len(names)} services up" + (f"; waiting for {', '.join(waiting)}" if waiting else ""))
                ready = alive
            if len(alive) == len(names):
                return True
            time.sleep(POLL_S)
    return False


def start_stack(compose_file: Path, router: str, log: Path, lockstep: bool, preparing: Child) -> subprocess.Popen:
    """`up` with the ACL on, handed the compose file as `preparing` prepares it (check_and_prepare);
    this process's sessions use the run's operator identity (goals, cancels). In lockstep the sim
    also waits for this process's goal sequencer ("navigate")."""
    credentials = compose_file.parent / "credentials"
    shutil.rmtree(credentials, ignore_errors=True)     # a previous run's passwords are not this run's
    os.environ[CREDENTIALS_ENV] = str(credentials / OPERATOR)
    with open(log, "wb") as sink:
        up = subprocess.Popen([sys.executable, "-m", "omninav.cli.main", "up", str(compose_file), "--router", router,
                               "--credentials", str(credentials), "--prepared",
                               *(["--lockstep", GoalSequencer.service] if lockstep else [])],
                              cwd=REPO, stdin=subprocess.PIPE, stdout=sink, stderr=subprocess.STDOUT,
                              start_new_session=True)
    preparing.relay(up.stdin)
    return up


def stop_stack(up: subprocess.Popen) -> int:
    if up.poll() is None:
        up.send_signal(signal.SIGINT)
    try:
        return up.wait(STOP_TIMEOUT_S)
    except subprocess.TimeoutExpired:
        up.kill()
        return up.wait()


@exits_2_on_user_error("navigate")
def main(args: argparse.Namespace) -> int:
    check_numbers(args)
    try:
        world = open_world(args.world)
    except WorldError as exc:
        raise NavigateError(str(exc)) from None
    world_file = Path(world.source).resolve()
    profile = load_profile(args.profile) if args.profile else None
    drive = args.drive or (profile.drive if profile else world.robot.drive)
    goals = mission_goals(args, world)
    out = Path(args.out or REPO / "out" / time.strftime("navigate-%Y%m%d-%H%M%S")).resolve()
    out.mkdir(parents=True, exist_ok=True)
    recording = Path(args.record).resolve() if args.record else out / "run.mcap"
    recording.parent.mkdir(parents=True, exist_ok=True)
    if recording.exists():
        raise NavigateError(f"{recording} exists already; give another --record")
    log = out / "services.log"
    say = (lambda text: None) if args.quiet else \
        (lambda text: print(f"navigate: {text}", file=sys.stderr if args.json else sys.stdout, flush=True))

    map_file = map_for(world, args.world, out)
    checked = f"{len(goals)} goal(s) checked on the map {map_file.name}: free for the footprint and reachable from the start"
    state_dir = None if args.in_process else out / "state"      # in one process nothing is restarted
    if state_dir is not None:
        shutil.rmtree(state_dir, ignore_errors=True)           # a previous run's state is not this run's to resume
        state_dir.mkdir()
    # 0: as fast as it may (the Clock says so; in one process the pace does not apply anyway)
    rate = args.rate if args.rate is not None else 0.0 if args.lockstep or args.in_process else 1.0
    compose = compose_for(world, world_file, map_file, drive, args.localization, recording, args.seed,
                          rate, args.robot, profile, sim_dt=args.sim_dt, state_dir=state_dir,
                          controller=args.controller, odometry=args.odometry)
    if args.composed:
        compose["services"] = in_containers(compose["services"], args.composed)
    compose_file = out / "compose.yaml"
    summary_of = f"{len(compose['services'])} services ({args.localization} localization, {drive} drive) in {world.name}"
    if args.in_process:
        call_in_child(check_goals, map_file, world, goals)
        say(checked)
        compose_file.write_text(yaml.safe_dump(compose, sort_keys=False))
        say(summary_of)
        summary = run_in_process(compose, world, goals, args, recording, say)
        print_summary(summary, args.json)
        return 0 if summary.success else 1
    with Child(check_and_prepare, map_file, world, goals, compose, compose_file) as preparing:
        preparing.next()
        say(checked)
        say(summary_of)
        problem = run_processes(compose, compose_file, args, recording, log, goals, say, preparing)
    names = tuple(s["name"] for s in compose["services"])
    try:
        summary = summarize_mission(load_mission(recording, args.robot, names), world, goals_total=len(goals),
                                    recording=str(recording), goal_tolerance_m=goal_tolerance(compose["services"]))
    except MissionError as exc:
        if not problem:
            raise
        say(f"no summary: {exc}")
    else:
        if problem:
            say("the mission was given up; the summary of what the recording holds:")
        print_summary(summary, args.json)
    if problem:
        raise NavigateError(f"{problem}; the recording is kept: {recording}")
    return 0 if summary.success else 1


def print_summary(summary, as_json: bool) -> None:
    print(json.dumps(summary.to_json()) if as_json else "\n".join(summary_lines(summary)), flush=True)


def run_in_process(compose: dict, world: World, goals: np.ndarray, args: argparse.Namespace, recording: Path, say):
    from ..experiments.lockstep_mission import run_mission

    say("running them in lockstep in this process")
    run = run_mission(compose["services"], world, goals, timeout_s=args.timeout, robot=args.robot,
                      recording=recording, progress=say)
    for goal_id, outcome in run.outcomes.items():
        say(f"{goal_id}: {outcome}")
    say(f"{run.sim_s:.1f} sim s")
    return run.summary


def run_processes(compose: dict, compose_file: Path, args: argparse.Namespace, recording: Path, log: Path,
                  goals: np.ndarray, say, preparing: Child) -> str:
    """Every service its own process under `omninav up`, which takes the compose file as `preparing`
    prepares it; the goals sent over the bus. Returns why the mission was given up, or ''."""
    names = [s["name"] for s in compose["services"]]

    # $OMNINAV_ROUTER names the mission's router, so `omninav view` can join it; else any free port
    router = router_endpoint() if os.environ.get(ROUTER_ENV) else free_loopback_endpoint()
    say(f"starting them as processes on the router {router}; log {log}")
    up = start_stack(compose_file, router, log, args.lockstep, preparing)
    problem = ""
    try:
        # `up` validates the compose file (exit 2 naming the key) while the services start
        if not wait_until_ready(router, names, up, args.robot, say):
            problem = f"the services did not all start (up exit {up.poll()}); see {log}"
        elif args.lockstep:
            sequencer = GoalSequencer(goals, args.timeout, robot=args.robot)
            with Mission(router, names, up, sequencer, log, say, Lockstep()) as mission:
                follow_sequence(mission, sequencer, say)
        else:
            with Mission(router, names, up, MissionNode(robot=args.robot), log, say) as mission:
                if not mission.node.wait_clock(CLOCK_WAIT_S):
                    raise ServiceDied(f"no sim clock within {CLOCK_WAIT_S:g} s; see {log}")
                for k, goal in enumerate(goals):
                    if mission.run_goal(f"g{k + 1}", goal, args.timeout, say) != "succeeded":
                        break
                mission.wait_sim(lambda: False, SETTLE_S)
    except ServiceDied as exc:
        problem = str(exc)
    finally:
        stopped = stop_stack(up)
    say(f"stopped every service (up exit {stopped})")
    return problem
