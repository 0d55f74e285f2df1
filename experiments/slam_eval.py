"""`omninav slam-eval LOG --relations REL [--method hector [--no-odometry]]`: run SLAM on a CARMEN
log in-process and score it.

With --method hector, hector mapping (services/slam/hector.py) sees every scan, with odometry's
pose as its first guess unless --no-odometry, and its pose at every scan is scored.

The filter sees every scan of the log's front laser with the odometry pose at its stamp, as fast
as it can. Its trajectory — the best particle's poses at the scans it processed, and in between
the odometry's motion from the previous processed scan (what the map → odom transform gives a
robot at those times) — is scored with the relations metric, and so is raw odometry.

wall_s times the filter alone: reading the log and compiling the kernels (once per machine,
cached) are reported apart, as load_s and warmup_s.
"""
from __future__ import annotations

import argparse
import dataclasses
import json
import resource
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..services.importers.carmen import CarmenError, read_log
from ..services.runtime.params import parse_overrides, read_yaml, unwrap_ros
from ..parameters.declare import ParamError
from ..parameters.from_mapping import load_params
from ..geometry.se2 import compose, relative
from ..services.slam.hector import HectorParams, HectorSlam
from ..services.slam.params import MODES, SlamParams
from ..services.slam.rbpf import Rbpf
from ..services.slam.relations import RelationsError, interpolate, load_relations, score

# Settings for the 2-D laser benchmark logs (SICK LMS, 0.5 degree beams, ~5 Hz, building-scale
# loops), over the gmapping defaults: every scan that moved a little is processed, and a
# correlative search recovers from odometry glitches and closes loops. docs/slam.md says why.
BENCHMARK_SETTINGS = {
    "particles": 10,
    "linearUpdate": 0.1,
    "angularUpdate": 0.05,
    "iterations": 10,
    "lstep": 0.1,
    "astep": 0.02,
}

# hector_mapping's defaults but for the map: hector's 1024 cells of 2.5 cm cover 25.6 m, the
# building is about 60 m across and its lasers reach 80 m
HECTOR_BENCHMARK_SETTINGS = {"map_resolution": 0.05, "map_size": 2048}


@dataclass
class LogData:
    stamps_ns: np.ndarray     # (n,) scan stamps
    odom: np.ndarray          # (n, 3) odometric robot pose at each scan
    ranges: np.ndarray        # (n, beams)
    angles: np.ndarray        # (beams,)
    range_max: float
    laser_offset: np.ndarray  # (3,) the laser in the robot frame, as the log states it

    @property
    def duration_s(self) -> float:
        return float(self.stamps_ns[-1] - self.stamps_ns[0]) * 1e-9 if len(self.stamps_ns) > 1 else 0.0


def load_log(path: str | Path, max_seconds: float | None = None) -> LogData:
    """The front laser's scans of a CARMEN log with the odometry at each, optionally only the
    first max_seconds."""
    log = read_log(path)
    scans = log.laser_scans(1)
    if not scans:
        raise CarmenError(f"{path}: no front laser lines (FLASER, ROBOTLASER1 or RAWLASER1)")
    if len({len(s.scan.ranges) for s in scans}) != 1:
        raise CarmenError(f"{path}: the front laser's beam count changes within the log")
    stamps = np.array([s.scan.header.stamp_ns for s in scans], np.int64)
    if max_seconds is not None:
        keep = stamps <= stamps[0] + int(max_seconds * 1e9)
        scans, stamps = [s for s, k in zip(scans, keep) if k], stamps[keep]
    if all(s.robot_pose is not None for s in scans):
        odom = np.array([s.robot_pose for s in scans])
    else:
        if not log.odometry:
            raise CarmenError(f"{path}: the laser lines carry no pose and there are no ODOM lines")
        o_stamps = np.array([o.header.stamp_ns for o in log.odometry], np.float64)
        o_poses = np.array([(o.pose.x, o.pose.y, o.pose.theta) for o in log.odometry])
        odom, _ = interpolate(o_stamps - o_stamps[0], o_poses, stamps - o_stamps[0])
    first = scans[0].scan
    angles = first.angle_min + np.arange(len(first.ranges)) * first.angle_increment
    offsets = [s.laser_offset for s in scans if s.laser_offset is not None]
    return LogData(stamps, odom, np.array([s.scan.ranges for s in scans], np.float64), angles,
                   float(first.range_max), offsets[0] if offsets else np.zeros(3))


def full_trajectory(slam: Rbpf, odom: np.ndarray) -> np.ndarray:
    """A pose for every scan: the best particle's where it processed the scan, else its pose at
    the previous processed scan moved by the odometry since."""
    indices, poses = slam.trajectory()
    anchor = np.searchsorted(indices, np.arange(len(odom)), side="right") - 1
    return compose(poses[anchor], relative(odom[indices[anchor]], odom))


def run(params: SlamParams, data: LogData) -> tuple[Rbpf, np.ndarray, float]:
    """Run the filter over the whole log; returns it, the trajectory and the wall time (s)."""
    slam = Rbpf(params, data.angles, data.range_max)
    start = time.perf_counter()
    for stamp, odom, ranges in zip(data.stamps_ns, data.odom, data.ranges):
        slam.process(int(stamp), odom, ranges)
    wall = time.perf_counter() - start
    return slam, full_trajectory(slam, data.odom), wall


def run_hector(params: HectorParams, data: LogData, odometry: bool) -> tuple[HectorSlam, np.ndarray, float]:
    """Hector over the whole log (odometry as the first guess if `odometry`); returns it, its pose at
    every scan and the wall time (s)."""
    slam = HectorSlam(params, data.angles, data.range_max, data.laser_offset)
    poses = np.empty((len(data.stamps_ns), 3))
    start = time.perf_counter()
    for i, (stamp, odom, ranges) in enumerate(zip(data.stamps_ns, data.odom, data.ranges)):
        slam.process(int(stamp), odom if odometry else None, ranges)
        poses[i] = slam.pose()
    return slam, poses, time.perf_counter() - start


def warm_up(params: SlamParams, data: LogData) -> float:
    """Compile (or load from cache) the kernels on the first scans, outside the timed run."""
    start = time.perf_counter()
    head = min(len(data.stamps_ns), 12)
    warm = dataclasses.replace(params, particles=2, search_below=2.0)  # forces every kernel to run
    slam = Rbpf(warm, data.angles, data.range_max)
    for i in range(head):
        slam.process(int(data.stamps_ns[i]), data.odom[i] + [0.2 * i, 0.0, 0.1 * i], data.ranges[i])
    return time.perf_counter() - start


def settings(args: argparse.Namespace, data: LogData) -> SlamParams | HectorParams:
    if args.method == "hector":
        values = dict(HECTOR_BENCHMARK_SETTINGS)
    else:
        values = dict(BENCHMARK_SETTINGS)
    if args.method == "rbpf" and np.any(np.abs(data.laser_offset) > 1e-9):
        values.update(laser_x=float(data.laser_offset[0]), laser_y=float(data.laser_offset[1]),
                      laser_yaw=float(data.laser_offset[2]))
    if args.params:
        doc = read_yaml(args.params)
        if not isinstance(doc, dict):
            raise ParamError(f"{args.params}: expected a mapping of parameter names to values")
        values.update(unwrap_ros(doc, "slam"))
    values.update(parse_overrides(args.set))
    if args.mode:
        values["mode"] = args.mode
    return load_params(HectorParams if args.method == "hector" else SlamParams, values, "omninav slam-eval")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("log", help="CARMEN log (e.g. ../shared/data/carmen/mit-csail.clf)")
    parser.add_argument("--relations", required=True, help="ground-truth relations (t1 t2 x y z roll pitch yaw)")
    parser.add_argument("--json", action="store_true", help="print one JSON object instead of a table")
    parser.add_argument("--params", help="YAML file of SLAM parameters (over the benchmark settings)")
    parser.add_argument("--set", action="append", default=[], metavar="NAME=VALUE", help="override one parameter")
    parser.add_argument("--method", choices=("rbpf", "hector"), default="rbpf", help="the particle filter (default) or hector mapping")
    parser.add_argument("--no-odometry", action="store_true", help="hector: no odometry, not even as the first guess")
    parser.add_argument("--mode", choices=MODES, help="the filter's: rbpf (default) or scan_matching")
    parser.add_argument("--max-seconds", type=float, metavar="S", help="only the first S seconds of the log")
    parser.add_argument("--save-map", metavar="PATH", help="also write the best particle's map (map_server YAML + PGM)")
    parser.add_argument("--picture", metavar="FILE.png", help="also draw the map with both trajectories")


def _table(result: dict) -> str:
    rows = [("", "SLAM", "odometry")]
    for key, label, fmt in (("trans_abs_mean_m", "translation |e| mean (m)", "{:.4f}"),
                            ("trans_abs_std_m", "translation |e| std (m)", "{:.4f}"),
                            ("trans_sq_mean", "translation e² mean (m²)", "{:.5f}"),
                            ("rot_abs_mean_deg", "rotation |e| mean (deg)", "{:.3f}"),
                            ("rot_abs_std_deg", "rotation |e| std (deg)", "{:.3f}"),
                            ("rot_sq_mean", "rotation e² mean (deg²)", "{:.3f}")):
        rows.append((label, fmt.format(result[key]), fmt.format(result["odometry"][key])))
    width = max(len(r[0]) for r in rows)
    lines = [f"{a:<{width}}  {b:>10}  {c:>10}" for a, b, c in rows]
    if result["method"] == "hector":
        lines.append(f"relations scored: {result['relations']}; hector, odometry as the first guess: "
                     f"{'yes' if result['odometry_guess'] else 'no'}; the grids took {result['updates']} of "
                     f"{result['scans']} scans")
    else:
        lines.append(f"relations scored: {result['relations']}; mode {result['params']['mode']}, "
                     f"{result['particles']} particles, {result['updates']} of {result['scans']} scans processed, "
                     f"{result['resamples']} resamplings")
    lines.append(f"wall {result['wall_s']:.1f} s for {result['log_s']:.1f} s of log: "
                 f"{result['realtime_factor']:.1f}x real time (load {result['load_s']:.1f} s, "
                 f"warm-up {result['warmup_s']:.1f} s not included)")
    if result["method"] == "rbpf":
        lines.append(f"map memory: {result['bytes_per_particle'] / 1e6:.2f} MB per particle "
                     f"({result['tiles_in_use']} tiles of 4 KiB shared among them)")
    lines.append(f"process peak {result['peak_rss_mb']:.0f} MB")
    return "\n".join(lines)


def main(args: argparse.Namespace) -> int:
    try:
        start = time.perf_counter()
        data = load_log(args.log, args.max_seconds)
        relations = load_relations(args.relations)
        load_s = time.perf_counter() - start
        params = settings(args, data)
    except (CarmenError, RelationsError, ParamError) as exc:
        print(f"omninav slam-eval: {exc}", file=sys.stderr)
        return 2
    if args.method == "hector":
        start = time.perf_counter()
        run_hector(params, LogData(data.stamps_ns[:12], data.odom[:12], data.ranges[:12], data.angles, data.range_max,
                                   data.laser_offset), True)      # compiles the kernels, or loads them
        warmup_s = time.perf_counter() - start
        slam, trajectory, wall = run_hector(params, data, not args.no_odometry)
        facts = dict(method="hector", odometry_guess=not args.no_odometry)
        occ_thresh = SlamParams.occ_thresh
    else:
        warmup_s = warm_up(params, data)
        slam, trajectory, wall = run(params, data)
        facts = dict(method="rbpf", resamples=slam.resamples, particles=slam.n,
                     bytes_per_particle=slam.bytes_per_particle(), tiles_in_use=slam.grids.tiles_in_use())
        occ_thresh = params.occ_thresh
    # relation times are seconds since the epoch: both sides lose the same whole seconds, so the
    # float seconds keep microsecond precision
    base = int(data.stamps_ns[0] // 1_000_000_000)
    stamps_s = (data.stamps_ns - base * 1_000_000_000) * 1e-9
    rel = relations.copy()
    rel[:, :2] -= base
    try:
        result = score(stamps_s, trajectory, rel)
        odometry = score(stamps_s, data.odom, rel)
    except RelationsError as exc:
        print(f"omninav slam-eval: {args.relations}: {exc}", file=sys.stderr)
        return 2
    result.update(wall_s=wall, log_s=data.duration_s, realtime_factor=data.duration_s / wall if wall > 0 else 0.0,
                  load_s=load_s, warmup_s=warmup_s, scans=len(data.stamps_ns), updates=slam.updates, **facts,
                  peak_rss_mb=resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,  # Linux: KiB
                  params=dataclasses.asdict(params), odometry=odometry)
    if args.save_map or args.picture:
        grid = slam.occupancy_grid(occ_thresh)
        if args.save_map:
            from ..services.map_server.mapio import save_map
            save_map(grid, args.save_map)
        if args.picture:
            _draw(args.picture, grid, trajectory, data.odom)
    print(json.dumps(result, indent=2) if args.json else _table(result))
    return 0


def _draw(path: str, grid, trajectory: np.ndarray, odom: np.ndarray) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    info = grid.info
    shade = np.where(grid.data < 0, 0.8, np.where(grid.data >= 50, 0.0, 1.0))
    extent = (info.origin.x, info.origin.x + info.width * info.resolution,
              info.origin.y, info.origin.y + info.height * info.resolution)
    fig, ax = plt.subplots(figsize=(12, 12 * info.height / max(info.width, 1) + 0.5))
    ax.imshow(shade, cmap="gray", vmin=0, vmax=1, origin="lower", extent=extent, interpolation="nearest")
    ax.plot(trajectory[:, 0], trajectory[:, 1], "r-", lw=0.6, label="SLAM")
    start = compose(trajectory[0], relative(odom[0], odom))  # odometry from the same start pose
    ax.plot(start[:, 0], start[:, 1], "b-", lw=0.4, alpha=0.5, label="odometry")
    ax.set_xlim(extent[:2])
    ax.set_ylim(extent[2:])
    ax.set_aspect("equal")
    ax.legend(loc="upper right")
    fig.savefig(path, dpi=150, bbox_inches="tight")
    plt.close(fig)
