"""The localizer on a real robot's recording, without ground truth: `omninav localize-eval --bag …`.

Made for the MIT racecar bag in the Stata basement (shared/data/bags, issue 5), and usable on any
ROS bag or omninav MCAP recording with LaserScan and Odometry, plus a map_server map.

The figure: at every scan, the share of its beams (finite returns inside the scan's range limits)
whose end point lies within 0.1 m of an occupied map cell, under
  - the localizer's pose: its map→odom transform (published at every scan) ⊕ the odometry at the
    scan's stamp — what a consumer of the transform sees;
  - raw odometry from the same start: the start pose ⊕ the odometry's motion since the first scan.

The localizer runs exactly its live code: the recording's messages are fed to LocalizerNode in
stamp order, as `replay --into` feeds a service. With --global-localization a global_localization
request, due at the first scan, spreads its particles over all free space instead of starting it
at the start pose.

At the end: the pose near the localizer's last one (within END_SEARCH_M and END_SEARCH_A) where the
last SEARCH_SCANS scans fit the map best (best_fit_near, the same scoring as the start search), its
distance from the localizer's pose, and both shares. A robot that stopped on a stale estimate
shows there (amcl makes no update without motion; see temporal_update).

The start pose is not in the recording. Unless --initial-pose gives it, it is searched for over
the whole map with the first scans (search_start): every free pose on a 0.25 m × 4° grid is scored
with the AMCL likelihood field on the first scan, the best candidates are refined on a 0.05 m × 1°
grid with the first SEARCH_SCANS scans (carried by the odometry), and the best one is the start.
The runner-up more than a metre away is reported too, with each one's scan fit (judge_start: the
figure above, over the first scans); when the runner-up fits within AMBIGUOUS_FIT_GAP of the best,
the start is ambiguous and the report says so.

The laser's mounting on the robot is --laser-x/-y/-yaw; what they leave out comes from the bag's
/tf_static or /tf when it has the transform from the odometry's base frame to the scans' frame
(the rosbag importer reads it), else from the MIT racecar: 0.285 m ahead of base_link (the rear
axle), its base_link→laser transform (mit-racecar/racecar, racecar-v2
static_transforms.launch.xml; the shipped bag has no /tf); docs/localize_eval.md compares other
values on that bag.
"""
from __future__ import annotations

import argparse
import json
import math
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy import ndimage

from ..schemas import MessageError, decode
from ..schemas.codec import encode
from ..schemas.keys import KeyLayout
from ..schemas.messages import Header, LaserScan, OccupancyGrid, Odometry, PoseWithCovariance, Transform
from ..schemas.registry import type_info
from ..services.map_server.mapio import MapError, load_map
from ..geometry.grid import cell_to_world
from ..services.recorder.mcap_io import Record, RecordingError, read_records
from ..services.replay.into import replay_into
from ..services.runtime.node import NS_PER_S
from ..services.runtime.params import parse_overrides, read_params_mapping
from ..parameters.declare import ParamError
from ..parameters.from_mapping import load_params
from ..geometry.se2 import compose, relative, wrap_angle
from ..services.localizer.node import LocalizerNode, LocalizerParams
from ..geometry.odometry_history import OdomHistory
from ..services.localizer.params import AmclParams
from ..services.localizer.sensor import FREE, OCCUPIED, GridFrame, LaserModel, prepare_scan, share_near_obstacles

NEAR_M = 0.1                 # an end point this close to an occupied cell agrees with the map
RACECAR_LASER_X = 0.285      # m, base_link → laser on the MIT racecar (see the module docstring)
SEARCH_STEP_M, SEARCH_STEP_A = 0.25, math.radians(4.0)
REFINE_STEP_M, REFINE_STEP_A, REFINE_CELLS = 0.05, math.radians(1.0), 5   # ±5 steps around a candidate
SEARCH_CLEARANCE_M = 0.15    # the car's centre is at least this far from obstacles
SEARCH_CANDIDATES = 40
SEARCH_SCANS = 3              # few: the racecar's odometry heading drifts fast
SEARCH_BEAMS = 120
AMBIGUOUS_FIT_GAP = 0.1     # a start is ambiguous when a pose > 1 m away fits the first scans nearly as well
END_SEARCH_M, END_SEARCH_A = 1.0, math.radians(10.0)   # where the end's best fit is looked for, around the localizer
START_COV = (0.1 ** 2, 0.1 ** 2, 0.05 ** 2)   # m², m², rad²: a good start, not an exact one

# amcl for the racecar (Ackermann steering, VESC odometry, 1081-beam 270° lidar, about 2 m/s); the rest
# keeps ROS amcl's defaults. The VESC's heading comes from the commanded steering and is poor: scan
# matching between scans 0.1 s apart turned 0.02 rad where it turned 0.30, or −0.26 where it turned
# −0.18. So the rotation noise is large (alpha1, alpha2 = 1: σ_rot = |rot| + trans), the
# translation noise modest, and the filter updates every 5 cm.
RACECAR_AMCL = {
    "odom_model_type": "diff-corrected", "odom_alpha1": 1.0, "odom_alpha2": 1.0, "odom_alpha3": 0.1,
    "odom_alpha4": 0.1, "laser_max_beams": 100, "laser_sigma_hit": 0.1, "min_particles": 500,
    "max_particles": 5000, "kld_err": 0.05, "update_min_d": 0.05, "update_min_a": 0.05, "resample_interval": 1,
}


class RealDataError(ValueError):
    """A recording or map that cannot be used; the text says which and why."""


@dataclass
class Run:
    scans: list[LaserScan]
    odometry: list[Odometry]
    laser_pose: tuple[float, float, float] | None = None    # the scans' frame in the base frame, when known


def load_run(path: str | Path, scan_topic: str | None = None, odom_topic: str | None = None, robot: str = "r1") -> Run:
    """Scans and odometry of a ROS bag (through the rosbag importer: topics not given are found by
    type, the laser's mounting read from its tf) or of an omninav MCAP recording."""
    path = Path(path)
    laser_pose = None
    if path.suffix == ".mcap":
        keys = KeyLayout(robot)
        try:
            records = list(read_records(path, [keys.robot("scan"), keys.robot("odom")]))
            scans = [decode(r.payload, LaserScan, key=r.key) for r in records if r.key == keys.robot("scan")]
            odometry = [decode(r.payload, Odometry, key=r.key) for r in records if r.key == keys.robot("odom")]
        except RecordingError as exc:
            raise RealDataError(str(exc)) from None
        except MessageError as exc:
            raise RealDataError(f"{path}: {exc}") from None
    else:
        from ..services.importers.rosbag import RosbagError, read_bag
        try:
            contents = read_bag(path, scan_topic, odom_topic)
        except RosbagError as exc:
            raise RealDataError(str(exc)) from None
        scans, odometry, laser_pose = contents.scans, contents.odometry, contents.laser_pose
    if len(scans) < SEARCH_SCANS or len(odometry) < 2:
        raise RealDataError(f"{path}: {len(scans)} scans and {len(odometry)} odometry messages: too few to localize")
    return Run(sorted(scans, key=lambda m: m.header.stamp_ns), sorted(odometry, key=lambda m: m.header.stamp_ns),
               laser_pose)


def laser_mounting(given: tuple[float | None, float | None, float | None],
                   from_bag: tuple[float, float, float] | None) -> tuple[tuple[float, float, float], str]:
    """(x, y, yaw, where it came from): the values given, the rest from the bag's tf, else the racecar's."""
    fallback, source = (from_bag, "the bag's tf") if from_bag is not None else ((RACECAR_LASER_X, 0.0, 0.0),
                                                                                 "the MIT racecar's default")
    pose = tuple(float(g) if g is not None else float(f) for g, f in zip(given, fallback))
    if all(g is not None for g in given):
        source = "given"
    elif any(g is not None for g in given):
        source = f"given, the rest from {source}"
    return pose, source


def odometry_history(odometry: list[Odometry]) -> OdomHistory:
    history = OdomHistory(keep_ns=2 ** 62)
    for msg in odometry:
        history.add(msg.header.stamp_ns, np.array([msg.pose.x, msg.pose.y, msg.pose.theta]))
    return history


def usable_scans(run: Run, history: OdomHistory) -> list[LaserScan]:
    """The scans inside the odometry's time span (the pose at the others is unknown)."""
    return [s for s in run.scans if history.at(s.header.stamp_ns) is not None]


# ---------------------------------------------------------------- the figure

class Agreement:
    """Share of a scan's end points within NEAR_M of an occupied cell, for a robot pose."""

    def __init__(self, grid: OccupancyGrid, laser_pose):
        occupied = np.asarray(grid.data) == OCCUPIED
        self.distance = ndimage.distance_transform_edt(~occupied) * grid.info.resolution
        self.affine = GridFrame.of(grid).affine
        self.laser_pose = laser_pose

    def end_points(self, scan: LaserScan) -> np.ndarray:
        """Base-frame end points (B, 2) of the valid returns."""
        r = np.asarray(scan.ranges, np.float64)
        angles = scan.angle_min + np.arange(r.size) * scan.angle_increment
        with np.errstate(invalid="ignore"):
            valid = np.isfinite(r) & (r > scan.range_min) & (r < scan.range_max)
        lx, ly, lyaw = self.laser_pose
        a = lyaw + angles[valid]
        return np.column_stack([lx + r[valid] * np.cos(a), ly + r[valid] * np.sin(a)])

    def share(self, pose, points: np.ndarray) -> float:
        return share_near_obstacles(self.distance, self.affine, pose, points[:, 0], points[:, 1], NEAR_M)


# ---------------------------------------------------------------- the start pose

def _weigh(laser: LaserModel, poses: np.ndarray, beams) -> np.ndarray:
    weights = np.ones(len(poses))
    for start in range(0, len(poses), 200_000):
        chunk = np.ascontiguousarray(poses[start:start + 200_000])
        laser.weigh(chunk, len(chunk), beams, weights[start:start + 200_000])
    return weights


class ScanFit:
    """Scores robot poses by how well a few consecutive scans fit the map (AMCL's likelihood field,
    SEARCH_BEAMS beams, σ 0.1 m), each scan seen from where the odometry says the robot went."""

    def __init__(self, grid: OccupancyGrid, scans: list[LaserScan], history: OdomHistory, laser_pose):
        params = AmclParams(laser_max_beams=SEARCH_BEAMS, laser_sigma_hit=0.1)
        self.laser = LaserModel(grid, params)
        self.beams = [prepare_scan(s.ranges, s.angle_min, s.angle_increment, s.range_min, s.range_max, params,
                                   laser_pose) for s in scans]
        first = history.at(scans[0].header.stamp_ns)
        self.moves = [relative(first, history.at(s.header.stamp_ns)) for s in scans]

    def first_scan(self, poses: np.ndarray) -> np.ndarray:
        return _weigh(self.laser, poses, self.beams[0])

    def log_likelihood(self, poses: np.ndarray) -> np.ndarray:
        total = np.zeros(len(poses))
        for move, beams in zip(self.moves, self.beams):
            total += np.log(_weigh(self.laser, compose(poses, move), beams))
        return total

    def refine(self, candidates: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Every pose within REFINE_CELLS steps of the candidates, best first, with its score."""
        steps = np.arange(-REFINE_CELLS, REFINE_CELLS + 1)
        offsets = np.stack(np.meshgrid(steps * REFINE_STEP_M, steps * REFINE_STEP_M, steps * REFINE_STEP_A,
                                       indexing="ij"), axis=-1).reshape(-1, 3)
        fine = (np.asarray(candidates)[:, None, :] + offsets[None, :, :]).reshape(-1, 3)
        total = self.log_likelihood(fine)
        order = np.argsort(total)[::-1]
        return fine[order], total[order]


def search_start(grid: OccupancyGrid, scans: list[LaserScan], history: OdomHistory, laser_pose) -> dict:
    """The pose at scans[0] that best explains the first scans (see the module docstring)."""
    fit = ScanFit(grid, scans[:SEARCH_SCANS], history, laser_pose)
    # free poses: on free cells, SEARCH_CLEARANCE_M from obstacles and unknown space
    data = np.asarray(grid.data)
    clear = ndimage.distance_transform_edt(data == FREE) * grid.info.resolution >= SEARCH_CLEARANCE_M
    stride = max(1, round(SEARCH_STEP_M / grid.info.resolution))
    rows, cols = np.nonzero(clear[::stride, ::stride])
    xs, ys = cell_to_world(grid.info, rows * stride, cols * stride)
    yaws = np.arange(-math.pi, math.pi, SEARCH_STEP_A)
    coarse = np.column_stack([np.repeat(xs, len(yaws)), np.repeat(ys, len(yaws)), np.tile(yaws, len(xs))])
    best = coarse[np.argsort(fit.first_scan(coarse))[::-1][:SEARCH_CANDIDATES]]
    fine, total = fit.refine(best)
    start = fine[0]
    far = next((i for i in range(len(fine)) if math.hypot(*(fine[i, :2] - start[:2])) > 1.0), None)
    return {"pose": start, "score": float(total[0]),
            "runner_up": None if far is None else {"pose": fine[far], "score": float(total[far])}}


def judge_start(search: dict, agreement: Agreement, scans: list[LaserScan], history: OdomHistory) -> dict:
    """Adds to a search_start result each candidate's scan fit (the mean share of the first scans'
    returns on mapped walls, each scan seen from where the odometry says the robot went) and
    whether the start is ambiguous: the best pose more than 1 m away fits within AMBIGUOUS_FIT_GAP."""
    used = scans[:SEARCH_SCANS]
    first = history.at(used[0].header.stamp_ns)
    views = [(relative(first, history.at(s.header.stamp_ns)), agreement.end_points(s)) for s in used]

    def fit(pose) -> float:
        return float(np.mean([agreement.share(compose(pose, move), points) for move, points in views]))

    search["fit"] = fit(search["pose"])
    other = search["runner_up"]
    if other is not None:
        other["fit"] = fit(other["pose"])
    search["ambiguous"] = other is not None and other["fit"] >= search["fit"] - AMBIGUOUS_FIT_GAP
    return search


def best_fit_near(grid: OccupancyGrid, scans: list[LaserScan], history: OdomHistory, laser_pose, pose) -> np.ndarray:
    """The pose at scans[0], within END_SEARCH_M and END_SEARCH_A of `pose`, that the scans fit best."""
    fit = ScanFit(grid, scans, history, laser_pose)
    spacing = (2 * REFINE_CELLS + 1) * np.array([REFINE_STEP_M, REFINE_STEP_M, REFINE_STEP_A])
    reach = np.ceil(np.array([END_SEARCH_M, END_SEARCH_M, END_SEARCH_A]) / spacing).astype(int)
    centres = np.stack(np.meshgrid(*(np.arange(-k, k + 1) * d for k, d in zip(reach, spacing)), indexing="ij"),
                       axis=-1).reshape(-1, 3)
    return fit.refine(np.asarray(pose, float) + centres)[0][0]


# ---------------------------------------------------------------- the run

def racecar_params(params_file: str | None, overrides: dict, map_file: str, laser_pose, seed: int,
                   start) -> LocalizerParams:
    values = read_params_mapping(params_file, "amcl") if params_file else dict(RACECAR_AMCL)
    x, y, a = (float(v) for v in start)
    fixed = {"map_file": map_file, "laser_x": laser_pose[0], "laser_y": laser_pose[1], "laser_yaw": laser_pose[2],
             "seed": seed, "initial_pose_x": x, "initial_pose_y": y, "initial_pose_a": a,
             "initial_cov_xx": START_COV[0], "initial_cov_yy": START_COV[1], "initial_cov_aa": START_COV[2]}
    return load_params(LocalizerParams, {**values, **overrides, **fixed}, params_file or "racecar amcl settings")


def localize(run: Run, params: LocalizerParams, start_global: bool = False) -> list[Transform]:
    """The localizer's map→odom transforms, one per scan it used, from its live code; with
    start_global, a global_localization request takes effect at the first scan."""
    node = LocalizerNode(params)
    requests = []
    if start_global:
        due = run.scans[0].header.stamp_ns - round(params.request_delay_s * NS_PER_S) - 1
        requests.append(PoseWithCovariance(header=Header(stamp_ns=due, frame_id=params.global_frame_id)))
    records = []
    for key, messages in (("odom", run.odometry), ("scan", run.scans), ("global_localization", requests)):
        full = node.keys.robot(key)
        for seq, msg in enumerate(messages):
            records.append(Record(full, type_info(type(msg))[0], encode(msg), seq, msg.header.stamp_ns,
                                  msg.header.stamp_ns))
    out = replay_into(node, records, None).outputs
    tf_key = node.keys.robot("tf/map_odom")
    return [decode(r.payload, Transform) for r in out if r.key == tf_key]


def score_run(run: Run, grid: OccupancyGrid, map_file: str, laser_pose, params_file: str | None,
              overrides: dict, seed: int, initial_pose=None, start_global: bool = False) -> dict:
    history = odometry_history(run.odometry)
    scans = usable_scans(run, history)
    if len(scans) < SEARCH_SCANS:
        raise RealDataError(f"only {len(scans)} scans lie within the odometry's time span")
    search = None
    if initial_pose is None:
        search = judge_start(search_start(grid, scans, history, laser_pose), Agreement(grid, laser_pose), scans,
                             history)
        initial_pose = search["pose"]
    params = racecar_params(params_file, overrides, map_file, laser_pose, seed, initial_pose)
    transforms = localize(Run(scans, run.odometry), params, start_global)
    tolerance = round(params.transform_tolerance * NS_PER_S)
    by_stamp = {tf.header.stamp_ns - tolerance: tf.transform for tf in transforms}
    agreement = Agreement(grid, laser_pose)
    t0 = scans[0].header.stamp_ns
    odom0 = history.at(t0)
    rows = []
    for scan in scans:
        stamp = scan.header.stamp_ns
        tf = by_stamp.get(stamp)
        if tf is None:
            continue
        odom = history.at(stamp)
        points = agreement.end_points(scan)
        estimate = compose((tf.x, tf.y, tf.theta), odom)
        raw = compose(initial_pose, relative(odom0, odom))
        rows.append(((stamp - t0) / NS_PER_S, agreement.share(estimate, points), agreement.share(raw, points),
                     estimate, raw))
    t = np.array([r[0] for r in rows])
    amcl, raw = np.array([r[1] for r in rows]), np.array([r[2] for r in rows])
    end = _end_of_run(grid, scans, history, laser_pose, rows[-1][3], agreement)
    return {"scans": len(run.scans), "odometry": len(run.odometry), "scans_scored": len(rows),
            "duration_s": round(float(t[-1]), 3) if len(t) else 0.0,
            "laser_pose": [float(v) for v in laser_pose],
            "start": {"pose": [round(float(v), 4) for v in initial_pose],
                      "how": "given" if search is None else "searched",
                      "localizer": "from particles over all free space (global localization)" if start_global
                      else "at the start pose",
                      **({} if search is None else _search_summary(search))},
            "near_m": NEAR_M,
            "localizer": _summary(t, amcl), "raw_odometry": _summary(t, raw), "end": end,
            "series": {"t": [round(float(v), 4) for v in t], "localizer": [round(float(v), 4) for v in amcl],
                       "raw_odometry": [round(float(v), 4) for v in raw]},
            "paths": {"localizer": [list(map(float, r[3])) for r in rows],
                      "raw_odometry": [list(map(float, r[4])) for r in rows]}}


def _end_of_run(grid, scans, history, laser_pose, estimate, agreement: Agreement) -> dict:
    """Where the last scans fit the map best near the localizer's last pose, and how far that is."""
    last = scans[-SEARCH_SCANS:]
    at_last = compose(estimate, relative(history.at(scans[-1].header.stamp_ns), history.at(last[0].header.stamp_ns)))
    best = best_fit_near(grid, last, history, laser_pose, at_last)
    best_last = compose(best, relative(history.at(last[0].header.stamp_ns), history.at(scans[-1].header.stamp_ns)))
    points = agreement.end_points(scans[-1])
    return {"localizer_pose": [round(float(v), 4) for v in estimate],
            "best_fit_pose": [round(float(v), 4) for v in best_last],
            "distance_m": round(math.hypot(*(best_last[:2] - np.asarray(estimate)[:2])), 3),
            "heading_deg": round(math.degrees(abs(float(wrap_angle(best_last[2] - estimate[2])))), 2),
            "localizer_share": round(agreement.share(estimate, points), 4),
            "best_fit_share": round(agreement.share(best_last, points), 4)}


def _search_summary(search: dict) -> dict:
    out = {"score": round(search["score"], 2), "fit": round(search["fit"], 4), "ambiguous": search["ambiguous"]}
    if search["runner_up"] is not None:
        other = search["runner_up"]
        out["runner_up"] = {"pose": [round(float(v), 4) for v in other["pose"]], "score": round(other["score"], 2),
                            "fit": round(other["fit"], 4),
                            "distance_m": round(float(np.hypot(*(other["pose"][:2] - search["pose"][:2]))), 2)}
    return out


def _summary(t: np.ndarray, share: np.ndarray) -> dict:
    """The share over all scans (mean, median, 10th percentile, min), per whole second, and at the end."""
    if len(t) == 0:
        return {"mean": None}
    seconds = np.floor(t).astype(int)
    return {"mean": round(float(np.nanmean(share)), 4), "median": round(float(np.nanmedian(share)), 4),
            "p10": round(float(np.nanpercentile(share, 10)), 4), "min": round(float(np.nanmin(share)), 4),
            "last_second": round(float(np.nanmean(share[t >= t[-1] - 1.0])), 4),
            "per_second": [round(float(np.nanmean(share[seconds == s])), 4) for s in range(seconds[-1] + 1)
                           if np.any(seconds == s)]}


# ---------------------------------------------------------------- the command (inside localize-eval)

def add_arguments(parser: argparse.ArgumentParser) -> None:
    group = parser.add_argument_group("real data (instead of the simulator)")
    group.add_argument("--bag", help="a ROS 1/2 bag or an omninav .mcap recording with scans and odometry")
    group.add_argument("--map", help="the map_server YAML of the map the robot drove in (needed with --bag)")
    group.add_argument("--scan-topic", default=None, help="the bag's LaserScan topic (default: its one LaserScan topic)")
    group.add_argument("--odom-topic", default=None,
                       help="the bag's Odometry topic (default: its one Odometry topic, else /tf's odom -> base)")
    group.add_argument("--laser-x", type=float, default=None,
                       help=f"m, the laser ahead of the base frame (default: from the bag's tf, else {RACECAR_LASER_X}, "
                            "the MIT racecar's)")
    group.add_argument("--laser-y", type=float, default=None,
                       help="m, the laser left of the base frame (default: from the bag's tf, else 0)")
    group.add_argument("--laser-yaw", type=float, default=None,
                       help="rad, the laser's turn (default: from the bag's tf, else 0)")
    group.add_argument("--initial-pose", metavar="X,Y,YAW", help="the start pose in the map (default: searched)")
    group.add_argument("--global-localization", action="store_true",
                       help="start the localizer with particles over all free space (amcl's global_localization), "
                            "not at the start pose (which still places raw odometry)")
    group.add_argument("--plot", metavar="PNG", help="draw the paths on the map and the shares over time")


def main(args: argparse.Namespace) -> int:
    if not args.map:
        print("omninav localize-eval: --bag needs --map (the map_server YAML of the building)", file=sys.stderr)
        return 2
    try:
        initial = parse_pose(args.initial_pose) if args.initial_pose else None
        grid = load_map(args.map)
        run = load_run(args.bag, args.scan_topic, args.odom_topic)
        laser_pose, laser_source = laser_mounting((args.laser_x, args.laser_y, args.laser_yaw), run.laser_pose)
        result = score_run(run, grid, args.map, laser_pose, args.params,
                           parse_overrides(args.set), args.seed, initial, args.global_localization)
        result["laser_pose_from"] = laser_source
    except (RealDataError, MapError, ParamError, ValueError) as exc:
        print(f"omninav localize-eval: {exc}", file=sys.stderr)
        return 2
    if args.plot:
        plot(result, grid, args.plot)
    if args.json:
        print(json.dumps(result))
    else:
        print(format_result(result, args.bag))
    return 0


def parse_pose(text: str, option: str = "--initial-pose") -> tuple[float, float, float]:
    try:
        values = tuple(float(v) for v in text.split(","))
    except ValueError:
        values = ()
    if len(values) != 3 or not all(map(math.isfinite, values)):
        raise ValueError(f"{option} {text!r}: expected X,Y,YAW (m, m, rad)")
    return values


def format_result(r: dict, source: str) -> str:
    s = r["start"]
    lines = [f"{source}: {r['scans']} scans, {r['odometry']} odometry messages, {r['scans_scored']} scans scored "
             f"over {r['duration_s']:.2f} s; laser at {r['laser_pose']} in the base frame "
             f"({r.get('laser_pose_from', 'given')})",
             f"start pose ({s['how']}): x {s['pose'][0]:.3f} m, y {s['pose'][1]:.3f} m, yaw {s['pose'][2]:.3f} rad; "
             f"the localizer starts {s['localizer']}"]
    if "runner_up" in s:
        u = s["runner_up"]
        lines.append(f"  search score {s['score']:.1f}, scan fit {s['fit']:.3f}; best pose more than 1 m away: "
                     f"{u['score']:.1f}, scan fit {u['fit']:.3f} ({u['distance_m']:.1f} m off)")
    if s.get("ambiguous"):
        lines.append(f"  AMBIGUOUS START: a pose {s['runner_up']['distance_m']:.1f} m away fits the first scans nearly "
                     f"as well; give --initial-pose if you know which")
    lines.append(f"share of beam end points within {r['near_m']} m of an occupied cell:")
    lines.append(f"  {'':14}{'mean':>7}{'median':>7}{'p10':>7}{'min':>7}{'last 1 s':>10}   per second")
    for name, label in (("localizer", "localizer"), ("raw_odometry", "raw odometry")):
        f = r[name]
        lines.append(f"  {label:14}{f['mean']:7.3f}{f['median']:7.3f}{f['p10']:7.3f}{f['min']:7.3f}"
                     f"{f['last_second']:10.3f}   "
                     + " ".join(f"{v:.3f}" for v in f["per_second"]))
    e = r["end"]
    lines.append(f"at the end: the last scans fit best {e['distance_m']:.3f} m and {e['heading_deg']:.1f}° from the "
                 f"localizer's pose (share {e['best_fit_share']:.3f} there, {e['localizer_share']:.3f} at the localizer's)")
    return "\n".join(lines)


def plot(result: dict, grid: OccupancyGrid, path: str) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (top, bottom) = plt.subplots(2, 1, figsize=(8, 10), gridspec_kw={"height_ratios": [3, 1]})
    rows, cols = np.nonzero(np.asarray(grid.data) == OCCUPIED)
    xs, ys = cell_to_world(grid.info, rows, cols)
    paths = {k: np.array(v) for k, v in result["paths"].items()}
    every = np.vstack(list(paths.values()))
    lo, hi = every[:, :2].min(axis=0) - 6.0, every[:, :2].max(axis=0) + 6.0
    keep = (xs > lo[0]) & (xs < hi[0]) & (ys > lo[1]) & (ys < hi[1])
    top.scatter(xs[keep], ys[keep], s=0.3, c="k")
    for name, colour in (("localizer", "tab:blue"), ("raw_odometry", "tab:red")):
        top.plot(paths[name][:, 0], paths[name][:, 1], colour, label=name.replace("_", " "))
        bottom.plot(result["series"]["t"], result["series"][name], colour, label=name.replace("_", " "))
    top.set_aspect("equal")
    top.set_xlim(lo[0], hi[0])
    top.set_ylim(lo[1], hi[1])
    top.legend()
    top.set_title("paths in the map frame")
    bottom.set_xlabel("s")
    bottom.set_ylabel(f"beams within {result['near_m']} m of a wall")
    bottom.set_ylim(0, 1)
    bottom.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
