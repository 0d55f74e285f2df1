"""`omninav localize-eval`: the localizer against the simulator's ground truth.

Everything runs in one process, in lockstep (InProcessRunner): the sim, chassis and lidar services,
the localizer service, and a small harness node. The harness is the test rig, not navigation: at
its first ground-truth message it publishes the world's true occupancy (World.rasterize at 0.05 m)
on the map key and the start request (an initial pose 0.5 m and 15° off the truth, or a global
localization request), then drives a scripted loop of waypoints on the TRUE pose through cmd_vel.

Modes:
- track: start from the rough initial pose; the error statistics cover every scan from convergence
  to the end.
- global: no initial pose, global localization at the start.
- kidnap: as track; once converged and past --kidnap-at, the robot is teleported (Simulation.teleport:
  the wheels and the gyro do not see it) to a far waypoint of the route, or with --shove DX,DY,DYAW
  pushed by that much (m, m in the map frame, rad: a collision, not a kidnapping). Detected = the
  first filter update after it that injected random poses (recovery_alpha_*); recovered = converged
  again. The localizer's beam fit (pose_fit) is reported before and just after the jump.

The pose the localizer gives at a scan is its map→odom transform (published at every scan) composed
with the odometry at the scan's stamp: what a consumer of the transform sees. Converged at time t
means the position error stays below 10 cm from t for at least CONVERGED_HOLD_S.
"""
from __future__ import annotations

import argparse
import json
import math
import sys
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..schemas import decode
from ..schemas.messages import Header, Odometry, Pose2D, PoseFit, PoseWithCovariance, Transform, Twist
from ..sim.node import SimNode, SimNodeParams
from ..sim.world import World, WorldError
from ..services.chassis.kinematics import DRIVES
from ..services.chassis.node import ChassisNode, ChassisNodeParams
from ..services.lidar.node import LidarNode, LidarNodeParams
from ..services.runtime.inprocess import InProcessRunner
from ..services.runtime.node import NS_PER_S, Node
from ..services.runtime.params import parse_overrides, read_params_mapping
from ..parameters.declare import ParamError
from ..parameters.from_mapping import load_params
from ..services.runtime.run import configure_logging
from ..geometry.se2 import compose, wrap_angle
from . import localize_realdata as realdata
from ..services.localizer.node import LocalizerNode, LocalizerParams
from ..parameters.declare import Parameters

MODES = ("track", "global", "kidnap")
PARAMS_FILE = Path(__file__).resolve().parents[1] / "compose" / "params" / "amcl_paper.yaml"
MAP_RESOLUTION = 0.05
CONVERGED_M = 0.10
CONVERGED_HOLD_S = 1.0
START_OFFSET = (0.5 * math.cos(2.0), 0.5 * math.sin(2.0), math.radians(15.0))   # 0.5 m and 15° off
ROUTE_CLEARANCE = 0.05   # m between obstacles and the robot's circumscribed circle along a route



@dataclass(frozen=True)
class Route:
    """Waypoints (x, y) from the start pose; after the last one the robot goes on at points[loop_from],
    so the points before it only lead in."""
    points: tuple[tuple[float, float], ...]
    loop_from: int = 0

    def legs(self) -> list[tuple[int, int]]:
        return [(k, k + 1) for k in range(len(self.points) - 1)] + [(len(self.points) - 1, self.loop_from)]

    def after(self, k: int) -> int:
        return k + 1 if k + 1 < len(self.points) else self.loop_from


# Routes in free space from each world's start pose: the robot may turn anywhere along them
# (route_problems checks the clearance), and no mover crosses them.
ROUTES: dict[str, Route] = {
    "room": Route(((1.3, 0.8), (8.3, 0.8), (8.3, 3.5), (6.2, 3.5), (6.2, 6.9), (3.8, 6.9), (3.8, 4.6), (1.3, 4.6))),
    # down into the lower rooms, through both, up into the upper right room, and back the same way
    "office": Route(((1.0, 6.0), (4.0, 6.0), (4.0, 4.0), (6.4, 4.0), (6.4, 2.5), (12.0, 2.5), (12.0, 6.0),
                     (13.5, 6.0), (13.5, 9.3), (13.5, 6.0), (12.0, 6.0), (12.0, 2.5), (6.4, 2.5), (6.4, 4.0),
                     (4.0, 4.0), (4.0, 6.0))),
    # into the first aisle (across the forklift's lane at x = 3 long before it comes by at 48 s), then up
    # and down its west half: every other way between aisles crosses the lane of a mover
    "warehouse": Route(((1.0, 1.0), (1.2, 4.25), (4.6, 4.25), (8.7, 4.25)), loop_from=2),
}


def circumscribed_radius(world: World) -> float:
    return float(np.max(np.hypot(*world.robot.footprint.T)))


def route_problems(world: World, route: Route) -> list[str]:
    """Where the robot, turned any way, would come closer than ROUTE_CLEARANCE to an obstacle."""
    reach = circumscribed_radius(world) + ROUTE_CLEARANCE
    points = np.asarray(route.points, float)
    problems = []
    for k, (i, j) in enumerate(route.legs()):
        a, b = points[i], points[j]
        samples = a + (b - a) * np.linspace(0.0, 1.0, max(2, math.ceil(np.hypot(*(b - a)) / 0.02)))[:, None]
        clearance = world.distance(samples) - reach
        if clearance.min() < 0:
            x, y = samples[int(np.argmin(clearance))]
            problems.append(f"segment {k} ({a[0]:g}, {a[1]:g}) → ({b[0]:g}, {b[1]:g}) passes ({x:.2f}, {y:.2f}), "
                            f"{clearance.min() + ROUTE_CLEARANCE:+.2f} m from obstacles for the robot's "
                            f"{reach - ROUTE_CLEARANCE:.2f} m circumscribed circle")
    return problems


def route_command(pose, target, holonomic: bool, speed: float, turn: float) -> tuple[float, float, float]:
    """Twist (vx, vy, wz) towards target: holonomic robots move straight at it while turning to face
    their way; a differential drive turns on the spot first when it faces more than 0.35 rad off."""
    dx, dy = target[0] - pose[0], target[1] - pose[1]
    distance = math.hypot(dx, dy)
    heading_error = float(wrap_angle(math.atan2(dy, dx) - pose[2]))
    wz = max(-turn, min(turn, 2.0 * heading_error))
    v = min(speed, 1.5 * distance)
    if holonomic:
        c, s = math.cos(pose[2]), math.sin(pose[2])
        return (v * (c * dx + s * dy) / distance, v * (-s * dx + c * dy) / distance, wz)
    if abs(heading_error) > 0.35:
        return (0.0, 0.0, wz)
    return (v * math.cos(heading_error), 0.0, wz)


# ---------------------------------------------------------------- the harness node

@dataclass(frozen=True)
class HarnessParams(Parameters):
    route: Route = Route(((0.0, 0.0),))
    holonomic: bool = True
    speed: float = 0.4          # m/s
    turn: float = 0.8           # rad/s
    reached: float = 0.1        # m: a waypoint this close counts as reached
    control_period_s: float = 0.05
    start: str = "track"        # track: initial pose off the truth; global: global localization request


class Harness(Node):
    """The evaluation rig: map and start request once, then cmd_vel along the route on the true pose."""
    service = "localize_eval"
    Params = HarnessParams

    def __init__(self, params: HarnessParams, grid, **kwargs):
        self.grid = grid
        super().__init__(params, **kwargs)

    def setup(self) -> None:
        self.cmd_pub = self.publisher("cmd_vel")
        self.map_pub = self.publisher("map")
        self.initialpose_pub = self.publisher("initialpose")
        self.global_pub = self.publisher("global_localization")
        self.subscribe("sim/truth", self.on_truth)
        self.target = 0
        self.next_control_ns: int | None = None

    def jump_to(self, waypoint: int) -> None:
        self.target = waypoint

    def on_truth(self, msg: Odometry) -> None:
        t, p = msg.header.stamp_ns, self.params
        pose = (msg.pose.x, msg.pose.y, msg.pose.theta)
        if self.next_control_ns is None:
            self._start(t, pose)
            self.next_control_ns = t
        if t < self.next_control_ns:
            return
        self.next_control_ns += round(p.control_period_s * NS_PER_S)
        target = p.route.points[self.target]
        if math.hypot(target[0] - pose[0], target[1] - pose[1]) < p.reached:
            self.jump_to(p.route.after(self.target))
            target = p.route.points[self.target]
        vx, vy, wz = route_command(pose, target, p.holonomic, p.speed, p.turn)
        self.cmd_pub.publish(Twist(header=self.header("base_link"), linear_x=vx, linear_y=vy, angular_z=wz))

    def _start(self, t: int, pose) -> None:
        self.grid.header = Header(stamp_ns=t, frame_id="map")
        self.map_pub.publish(self.grid)
        if self.params.start == "global":
            self.global_pub.publish(PoseWithCovariance(header=self.header("map")))
        else:
            x, y, theta = (float(v) for v in compose(pose, START_OFFSET))
            self.initialpose_pub.publish(PoseWithCovariance(
                header=self.header("map"), pose=Pose2D(x, y, theta),
                covariance=np.diag([0.25, 0.25, (math.pi / 12) ** 2])))   # amcl's default initial_cov_*


# ---------------------------------------------------------------- the run

@dataclass
class Series:
    """The localizer's error at every scan."""
    t: list[float] = field(default_factory=list)             # sim s
    position: list[float] = field(default_factory=list)      # m
    heading: list[float] = field(default_factory=list)       # rad
    injected: list[int] = field(default_factory=list)        # random poses injected so far
    beam_fit: list[float] = field(default_factory=list)      # the localizer's pose_fit

    def converged_at(self, start_s: float = 0.0, end_s: float = math.inf) -> float | None:
        """The first scan time ≥ start_s from which the error stays < CONVERGED_M for CONVERGED_HOLD_S."""
        t, err = np.asarray(self.t), np.asarray(self.position)
        candidates = np.flatnonzero((t >= start_s) & (t < end_s))
        for i in candidates:
            hold = (t >= t[i]) & (t <= t[i] + CONVERGED_HOLD_S)
            if t[i] + CONVERGED_HOLD_S <= t[-1] and np.all(err[hold] < CONVERGED_M):
                return float(t[i])
        return None

    def stats(self, start_s: float, end_s: float = math.inf) -> dict:
        t = np.asarray(self.t)
        use = (t >= start_s) & (t < end_s)
        pos, head = np.asarray(self.position)[use] * 100.0, np.degrees(np.asarray(self.heading)[use])
        if not use.any():
            return {"samples": 0}
        return {"samples": int(use.sum()), "from_s": round(start_s, 2),
                "position_cm": {"p50": round(float(np.percentile(pos, 50)), 2),
                                "p95": round(float(np.percentile(pos, 95)), 2), "max": round(float(pos.max()), 2)},
                "heading_deg": {"p50": round(float(np.percentile(head, 50)), 3),
                                "p95": round(float(np.percentile(head, 95)), 3), "max": round(float(head.max()), 3)}}


def localizer_params(params_file: str | None, overrides: dict, seed: int) -> LocalizerParams:
    path = Path(params_file) if params_file else PARAMS_FILE
    values = read_params_mapping(path, "amcl") if params_file or PARAMS_FILE.is_file() else {}
    return load_params(LocalizerParams, {**values, **overrides, "seed": seed}, str(path))


def evaluate(world_name: str = "room", drive: str = "", mode: str = "track", seed: int = 0,
             params: LocalizerParams | None = None, duration_s: float = 120.0, kidnap_at_s: float = 40.0,
             route: Route | None = None, shove: tuple[float, float, float] | None = None) -> dict:
    """Run the pipeline in lockstep and score the localizer against the ground truth."""
    if mode not in MODES:
        raise ValueError(f"mode must be one of {MODES}, got {mode!r}")
    sim = SimNode(SimNodeParams(world=world_name, drive=drive, seed=seed))
    world, drive = sim.world, sim.sim.drive
    route = route or ROUTES.get(world.name)
    if route is None:
        raise ValueError(f"no route for world {world.name!r} (routes exist for {', '.join(ROUTES)}): give --route")
    problems = route_problems(world, route)
    if problems:
        raise ValueError("the route is not clear: " + "; ".join(problems))
    params = params or localizer_params(None, {}, seed)
    localizer = LocalizerNode(params)
    harness = Harness(HarnessParams(route=route, holonomic=drive != "diff",
                                    start="global" if mode == "global" else "track"),
                      world.rasterize(MAP_RESOLUTION))
    runner = InProcessRunner([sim, ChassisNode(ChassisNodeParams(drive=drive)),
                              LidarNode(LidarNodeParams(world=world_name, seed=seed + 1)), localizer, harness])
    keys = {name: localizer.keys.resolve(name) for name in ("sim/truth", "odom", "tf/map_odom", "pose_fit")}
    truth, odom, fits, series = {}, {}, {}, Series()
    tolerance_ns = round(params.transform_tolerance * NS_PER_S)

    def tap(key: str, payload: bytes, stamp_ns: int) -> None:
        if key == keys["sim/truth"] or key == keys["odom"]:
            msg = decode(payload, Odometry)
            (truth if key == keys["sim/truth"] else odom)[stamp_ns] = (msg.pose.x, msg.pose.y, msg.pose.theta)
        elif key == keys["pose_fit"]:
            fits[stamp_ns] = decode(payload, PoseFit).beam_fit
        elif key == keys["tf/map_odom"]:
            scan_ns = stamp_ns - tolerance_ns
            tf = decode(payload, Transform).transform
            estimate = compose((tf.x, tf.y, tf.theta), odom[scan_ns])
            true = truth[scan_ns]
            series.t.append(scan_ns / NS_PER_S)
            series.position.append(math.hypot(estimate[0] - true[0], estimate[1] - true[1]))
            series.heading.append(abs(float(wrap_angle(estimate[2] - true[2]))))
            series.injected.append(localizer.counters["random_poses_injected"])
            series.beam_fit.append(fits.pop(scan_ns, math.nan))
            for old in [s for s in truth if s < scan_ns]:   # older stamps are never asked for again
                truth.pop(old), odom.pop(old, None)

    runner.tap(tap)
    steps = round(duration_s / sim.params.dt)
    kidnap = None
    for _ in range(steps):
        runner.step()
        if mode == "kidnap" and kidnap is None and series.t and series.t[-1] >= kidnap_at_s \
                and series.converged_at(series.t[-1] - CONVERGED_HOLD_S) is not None:
            kidnap = _kidnap(sim, harness, route, series.t[-1]) if shove is None else _shove(sim, shove, series.t[-1])
    runner.close()

    result = {"world": world.name, "drive": drive, "mode": mode, "seed": seed, "duration_s": duration_s,
              "scans": len(series.t), "filter_updates": localizer.counters["filter_updates"],
              "particles_at_end": localizer.amcl.n if localizer.amcl else 0,
              "collisions": sim.sim.collisions}
    end = kidnap["at_s"] if kidnap else math.inf
    converged = series.converged_at(0.0, end)
    result["converged"] = converged is not None
    result["converged_at_s"] = converged
    result["after_convergence"] = series.stats(converged, end) if converged is not None else {"samples": 0}
    if mode == "kidnap":
        result["kidnap"] = kidnap_result(series, kidnap, converged)
    return result


def _kidnap(sim: SimNode, harness: Harness, route: Route, now_s: float) -> dict:
    """Teleport the robot to the waypoint of the loop farthest from it, facing the next one."""
    here = sim.sim.pose
    points = np.asarray(route.points)
    loop = np.arange(route.loop_from, len(points))
    far = int(loop[np.argmax(np.hypot(points[loop, 0] - here[0], points[loop, 1] - here[1]))])
    after = points[route.after(far)]
    pose = (points[far, 0], points[far, 1], math.atan2(after[1] - points[far, 1], after[0] - points[far, 0]))
    sim.sim.teleport(pose)
    harness.jump_to(route.after(far))
    return {"at_s": now_s, "from": [round(float(v), 3) for v in here], "to": [round(float(v), 3) for v in pose]}


def _shove(sim: SimNode, offset, now_s: float) -> dict:
    """Push the robot by `offset` (x, y in the map frame, yaw), the route going on from there."""
    here = sim.sim.pose
    pose = (here[0] + offset[0], here[1] + offset[1], float(wrap_angle(here[2] + offset[2])))
    sim.sim.teleport(pose)
    return {"at_s": now_s, "from": [round(float(v), 3) for v in here], "to": [round(float(v), 3) for v in pose]}


def kidnap_result(series: Series, kidnap: dict | None, converged_s: float) -> dict:
    if kidnap is None:
        return {"done": False, "why": "the filter had not converged by the end of the run"}
    at = kidnap["at_s"]
    t, injected = np.asarray(series.t), np.asarray(series.injected)
    after = np.flatnonzero(t > at)
    injected_before = series.injected[after[0] - 1] if len(after) and after[0] > 0 else 0
    detected = next((series.t[i] for i in after if series.injected[i] > injected_before), None)
    # recovery also injects now and then while tracking well: the rate before tells chance from detection
    tracking = (t >= converged_s) & (t <= at)
    tracked_s = float(t[tracking][-1] - t[tracking][0]) if tracking.sum() > 1 else 0.0
    first_second = injected[(t > at) & (t <= at + 1.0)]
    recovered = series.converged_at(at)
    out = {"done": True, **kidnap, "jump_m": round(float(np.hypot(kidnap["to"][0] - kidnap["from"][0],
                                                               kidnap["to"][1] - kidnap["from"][1])), 2),
           "error_after_m": round(series.position[after[0]], 2) if len(after) else None,
           "detected": detected is not None, "detected_after_s": None if detected is None else round(detected - at, 2),
           "random_poses_per_s_before": round(float(injected[tracking][-1] - injected[tracking][0]) / tracked_s, 1)
           if tracked_s > 0 else None,
           "random_poses_first_s_after": int(first_second[-1] - injected_before) if len(first_second) else 0,
           "beam_fit_min_before": _min_fit(series, (t >= converged_s) & (t <= at)),
           "beam_fit_min_first_s_after": _min_fit(series, (t > at) & (t <= at + 1.0)),
           "recovered": recovered is not None,
           "recovered_after_s": None if recovered is None else round(recovered - at, 2)}
    if recovered is not None:
        out["after_recovery"] = series.stats(recovered)
    return out


def _min_fit(series: Series, use: np.ndarray) -> float | None:
    fits = np.asarray(series.beam_fit)[use]
    return round(float(np.nanmin(fits)), 3) if np.any(np.isfinite(fits)) else None


# ---------------------------------------------------------------- the command

def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--world", default="room", help="shipped world name or world file (default room)")
    parser.add_argument("--drive", choices=DRIVES, default="", help="drive (default: the world's)")
    parser.add_argument("--mode", choices=MODES, default="track", help="track (default), global or kidnap")
    parser.add_argument("--seed", type=int, default=0, help="seed of the sim, lidar and localizer (default 0)")
    parser.add_argument("--params", help=f"amcl parameter YAML, ROS 1 or 2 layout (default {PARAMS_FILE.name} "
                                         "from compose/params)")
    parser.add_argument("--set", action="append", default=[], metavar="NAME=VALUE", help="override one parameter")
    parser.add_argument("--duration", type=float, default=120.0, help="sim seconds to drive (default 120)")
    parser.add_argument("--kidnap-at", type=float, default=40.0,
                        help="kidnap: sim s after which the converged robot is teleported (default 40)")
    parser.add_argument("--shove", metavar="DX,DY,DYAW",
                        help="kidnap: push the robot by this much (m, m, rad) instead of teleporting it far")
    parser.add_argument("--route", help="waypoints 'x,y;x,y;…' to loop through (default: the world's route)")
    parser.add_argument("--json", action="store_true", help="print one JSON object")
    realdata.add_arguments(parser)


def parse_waypoints(text: str, option: str = "waypoints") -> tuple[tuple[float, float], ...]:
    """'x,y;x,y;…' into waypoints (ValueError naming `option` if it is not at least two finite pairs)."""
    try:
        points = tuple(tuple(float(v) for v in part.split(",")) for part in text.split(";") if part.strip())
    except ValueError:
        points = ()
    if len(points) < 2 or any(len(p) != 2 or not all(map(math.isfinite, p)) for p in points):
        raise ValueError(f"{option} {text!r}: expected at least two waypoints 'x,y;x,y;…'")
    return points


def main(args: argparse.Namespace) -> int:
    configure_logging("localize-eval", "ERROR")   # the localizer's warnings (uncertain pose) are expected here
    if args.bag:
        return realdata.main(args)
    if args.params is None and not PARAMS_FILE.is_file():
        print(f"omninav localize-eval: {PARAMS_FILE} not found (not a checkout?): pass --params", file=sys.stderr)
        return 2
    if not args.duration > 0:
        print("omninav localize-eval: --duration must be positive", file=sys.stderr)
        return 2
    try:
        route = Route(parse_waypoints(args.route, "--route")) if args.route else None
        params = localizer_params(args.params, parse_overrides(args.set), args.seed)
        shove = realdata.parse_pose(args.shove, "--shove") if args.shove else None
        result = evaluate(args.world, args.drive, args.mode, args.seed, params, args.duration, args.kidnap_at, route,
                          shove)
    except (ParamError, WorldError, ValueError) as exc:
        print(f"omninav localize-eval: {exc}", file=sys.stderr)
        return 2
    if args.json:
        print(json.dumps(result))
    else:
        print(format_result(result))
    return 0


def _stats_line(stats: dict) -> str:
    if not stats.get("samples"):
        return "no samples"
    p, h = stats["position_cm"], stats["heading_deg"]
    return (f"position p50 {p['p50']:.1f} / p95 {p['p95']:.1f} / max {p['max']:.1f} cm, heading p50 "
            f"{h['p50']:.2f} / p95 {h['p95']:.2f} / max {h['max']:.2f}° over {stats['samples']} scans")


def format_result(r: dict) -> str:
    lines = [f"localize-eval {r['world']} {r['drive']} {r['mode']} seed {r['seed']}: {r['duration_s']:g} s, "
             f"{r['scans']} scans, {r['filter_updates']} filter updates, {r['particles_at_end']} particles at the "
             f"end, {r['collisions']} collisions"]
    if r["converged"]:
        lines.append(f"  converged (< {CONVERGED_M * 100:.0f} cm) at {r['converged_at_s']:.1f} s; after: "
                     + _stats_line(r["after_convergence"]))
    else:
        lines.append("  never converged")
    k = r.get("kidnap")
    if k is not None:
        if not k["done"]:
            lines.append(f"  no kidnapping: {k['why']}")
        else:
            lines.append(f"  kidnapped at {k['at_s']:.1f} s, {k['jump_m']:.1f} m away (error then "
                         f"{k['error_after_m']} m); detected: "
                         + (f"after {k['detected_after_s']:.1f} s" if k["detected"] else "no")
                         + f" ({k['random_poses_first_s_after']} random poses in the first second, "
                         f"{k['random_poses_per_s_before']}/s while tracking before; beam fit at least "
                         f"{k['beam_fit_min_before']} before, down to {k['beam_fit_min_first_s_after']} in the "
                         f"first second); recovered: "
                         + (f"after {k['recovered_after_s']:.1f} s; then " + _stats_line(k["after_recovery"])
                            if k["recovered"] else "no"))
    return "\n".join(lines)
