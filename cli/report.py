"""`omninav report FILE.mcap -o run.png`: one picture of what happened in a recorded run.

It draws the world (or its map), the map the robot navigated on and the last global costmap when
the recording has them (a navigation run), the global plans and goals, the true trajectory, the
localizer's estimate (its pose key: path and final pose, in the map frame, which is the simulator's
world frame), the wheel-odometry trajectory (and the follower-wheel one) expressed in the world frame
by aligning the first odometry pose with the truth at the same stamp, the scans at a few moments
(the returns within range_max, placed with the true pose at the scan's stamp), the movers' traces,
start and end. The title sums up the sim time (of the mission, from the first goal to the last
goal's end, when the recording has goals; else of the whole recording), distance, the final
odometry and localizer errors and the collisions the sim counted.

The drawing helpers (draw_world, draw_track, draw_scan, draw_footprint, draw_run) take a
matplotlib Axes, so other tools can draw maps, costmaps and paths onto the same kind of figure.
"""
from __future__ import annotations

import argparse
import math
import sys
from dataclasses import dataclass, field
from pathlib import Path
from typing import Iterator

import numpy as np
from matplotlib import colormaps
from matplotlib.axes import Axes
from matplotlib.collections import PathCollection
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from matplotlib.patches import Circle, Patch, Polygon

from ..services.runtime.errors import UserError, exits_2_on_user_error
from ..schemas import MessageError, decode
from ..schemas.keys import DEFAULT_ROBOT, KeyLayout, type_for_key
from ..schemas.messages import (Costmap, Diagnostic, Goal, LaserScan, NavStatus, Obstacles, OccupancyGrid, Odometry,
                                Path as PathMsg, PoseWithCovariance)
from ..experiments.mission_score import TERMINAL
from ..services.recorder.mcap_io import Record, RecordingError, read_records
from ..geometry.se2 import compose, inverse, wrap_angle
from ..sim.lidar import LidarParams, laser_pose
from ..sim.world import World, WorldError, load_world, world_path
from ..geometry.footprint import DEFAULT_FOOTPRINT
from ..geometry.grid import GRID_OBSTACLE

NS_PER_S = 1e9
SCAN_MOMENTS = 4
WORLD_KEY = "world"          # the sim's Diagnostic value naming its world file


class ReportError(UserError):
    """A user error: printed as one line, exit status 2."""


# ---------------------------------------------------------------- the data of a run

@dataclass(frozen=True)
class Track:
    """Poses over time, sorted by stamp."""
    stamps: np.ndarray          # (N,) int64 ns
    poses: np.ndarray           # (N, 3) x, y, theta

    def __len__(self) -> int:
        return len(self.stamps)

    def at(self, stamps) -> np.ndarray:
        """The poses recorded nearest to the given stamps (ns)."""
        stamps = np.asarray(stamps, np.int64)
        if len(self.stamps) == 1:
            return self.poses[np.zeros(len(stamps), int)]
        right = np.clip(np.searchsorted(self.stamps, stamps), 1, len(self.stamps) - 1)
        left = right - 1
        nearer_left = np.abs(stamps - self.stamps[left]) <= np.abs(self.stamps[right] - stamps)
        return self.poses[np.where(nearer_left, left, right)]

    @property
    def length(self) -> float:
        """Path length (m)."""
        return float(np.hypot(*np.diff(self.poses[:, :2], axis=0).T).sum()) if len(self) > 1 else 0.0


@dataclass
class RunData:
    truth: Track | None = None
    odom: Track | None = None
    estimate: Track | None = None                       # the localizer's pose (map frame)
    follower: Track | None = None
    scans: list[LaserScan] = field(default_factory=list)
    mover_stamps: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    mover_circles: np.ndarray = field(default_factory=lambda: np.zeros((0, 0, 3)))   # (T, K, 3)
    sim_values: dict = field(default_factory=dict)      # the last sim Diagnostic's values
    malformed: int = 0
    map: OccupancyGrid | None = None                    # the last map served (navigation runs)
    costmap: Costmap | None = None                      # the last global costmap
    plans: list[PathMsg] = field(default_factory=list)  # the global plans with poses, in stamp order
    goals: list[Goal] = field(default_factory=list)
    statuses: list[NavStatus] = field(default_factory=list)

    @property
    def span_ns(self) -> tuple[int, int] | None:
        stamps = [t.stamps for t in (self.truth, self.odom, self.follower) if t is not None and len(t)]
        stamps += [np.array([s.header.stamp_ns for s in self.scans], np.int64)] if self.scans else []
        if not stamps:
            return None
        return int(min(s.min() for s in stamps)), int(max(s.max() for s in stamps))


def _track(messages: list[Odometry] | list[PoseWithCovariance]) -> Track | None:
    if not messages:
        return None
    stamps = np.array([m.header.stamp_ns for m in messages], np.int64)
    poses = np.array([(m.pose.x, m.pose.y, m.pose.theta) for m in messages], np.float64)
    order = np.argsort(stamps, kind="stable")
    return Track(stamps[order], poses[order])


def _read(path: Path) -> Iterator[Record]:
    try:
        yield from read_records(path)
    except RecordingError as exc:
        raise ReportError(str(exc)) from None


def load_run(path: str | Path, robot: str = DEFAULT_ROBOT) -> RunData:
    """Everything the picture needs from a recording (raises ReportError)."""
    path = Path(path)
    keys = KeyLayout(robot)
    wanted = {keys.sim_robot("truth"): "truth", keys.robot("odom"): "odom",
              keys.robot("odom_follower"): "follower", keys.robot("scan"): "scan", keys.sim("movers"): "movers",
              keys.robot("map"): "map", keys.robot("costmap/global"): "costmap", keys.robot("plan"): "plans",
              keys.robot("goal"): "goals", keys.robot("pose"): "estimate", keys.robot("nav_status"): "statuses"}
    diag_prefix = keys.diagnostics("sim").rsplit("/", 1)[0] + "/"
    found: dict[str, list] = {name: [] for name in wanted.values()}
    run = RunData()
    sim_diag: Diagnostic | None = None
    for rec in _read(path):
        name = wanted.get(rec.key)
        if name is None and not rec.key.startswith(diag_prefix):
            continue
        try:
            msg = decode(rec.payload, type_for_key(rec.key), key=rec.key)
        except MessageError:
            run.malformed += 1
            continue
        if name is not None:
            found[name].append(msg)
        elif WORLD_KEY in msg.values and (sim_diag is None or (msg.header.stamp_ns, msg.header.seq)
                                          >= (sim_diag.header.stamp_ns, sim_diag.header.seq)):
            sim_diag = msg
    run.truth, run.odom, run.follower, run.estimate = (_track(found[n])
                                                       for n in ("truth", "odom", "follower", "estimate"))
    run.scans = sorted(found["scan"], key=lambda s: s.header.stamp_ns)
    movers: list[Obstacles] = sorted(found["movers"], key=lambda m: m.header.stamp_ns)
    if movers:
        count = len(movers[0].circles)          # traces need one count: keep the messages that have it
        movers = [m for m in movers if len(m.circles) == count]
        run.mover_stamps = np.array([m.header.stamp_ns for m in movers], np.int64)
        run.mover_circles = np.array([m.circles for m in movers], np.float64).reshape(len(movers), count, 3)
    run.sim_values = dict(sim_diag.values) if sim_diag is not None else {}
    for name in ("map", "costmap", "plans", "goals", "statuses"):
        found[name].sort(key=lambda m: (m.header.stamp_ns, m.header.seq))
    run.map = found["map"][-1] if found["map"] else None
    run.costmap = found["costmap"][-1] if found["costmap"] else None
    run.plans = [p for p in found["plans"] if len(p.poses)]
    run.goals = found["goals"]
    run.statuses = found["statuses"]
    return run


def in_world_frame(track: Track, truth: Track) -> Track:
    """An odometry track moved into the world frame: its first pose put on the truth at that stamp."""
    world_from_odom = compose(truth.at(track.stamps[:1])[0], inverse(track.poses[0]))
    return Track(track.stamps, compose(world_from_odom, track.poses))


@dataclass(frozen=True)
class Summary:
    duration_s: float | None              # sim s: of the mission when there are goals, else of the recording
    start_s: float | None                 # sim time where that span starts
    mission: bool                         # the span is the mission's (first goal to the last goal's end)
    distance_m: float | None              # along the true trajectory (else the odometry's)
    odom_error_m: float | None            # at the last odometry pose, against the truth then
    odom_heading_error_rad: float | None
    estimate_error_m: float | None        # at the localizer's last pose, against the truth then
    collisions: int | None


def mission_span_ns(run: RunData) -> tuple[int, int] | None:
    """From the first goal's stamp to the last status of the last goal that ended it (or the end of
    the recording, when it never ended); None without goals."""
    span = run.span_ns
    if not run.goals or span is None:
        return None
    start = min(g.header.stamp_ns for g in run.goals)
    last_goal = max(run.goals, key=lambda g: (g.header.stamp_ns, g.header.seq)).goal_id
    ends = [s.header.stamp_ns for s in run.statuses if s.goal_id == last_goal and s.status in TERMINAL]
    return start, min(ends) if ends else span[1]


def _error_at_end(track: Track, truth: Track) -> tuple[float, float]:
    true_end = truth.at(track.stamps[-1:])[0]
    return (float(np.hypot(*(track.poses[-1, :2] - true_end[:2]))),
            abs(float(wrap_angle(track.poses[-1, 2] - true_end[2]))))


def summarize(run: RunData) -> Summary:
    mission = mission_span_ns(run)
    span = mission or run.span_ns
    track = run.truth if run.truth is not None else run.odom
    error = heading = estimate_error = None
    if run.truth is not None and run.odom is not None:
        error, heading = _error_at_end(in_world_frame(run.odom, run.truth), run.truth)
    if run.truth is not None and run.estimate is not None:
        estimate_error = _error_at_end(run.estimate, run.truth)[0]
    collisions = run.sim_values.get("collisions")
    return Summary((span[1] - span[0]) / NS_PER_S if span else None, span[0] / NS_PER_S if span else None,
                   mission is not None, track.length if track else None, error, heading, estimate_error,
                   int(collisions) if isinstance(collisions, (int, float)) else None)


def title_of(summary: Summary, name: str) -> str:
    parts = [name]
    if summary.duration_s is not None:
        what = "mission" if summary.mission else "recording"
        parts.append(f"{what} {summary.duration_s:.1f} s of sim time "
                     f"(from t = {summary.start_s:.1f} s)")
    if summary.distance_m is not None:
        parts.append(f"{summary.distance_m:.2f} m driven")
    if summary.odom_error_m is not None:
        parts.append(f"final odometry error {summary.odom_error_m:.3f} m, "
                     f"{math.degrees(summary.odom_heading_error_rad):.1f}°")
    if summary.estimate_error_m is not None:
        parts.append(f"final localizer error {summary.estimate_error_m:.3f} m")
    parts.append("collisions: unknown" if summary.collisions is None else f"{summary.collisions} collisions")
    return " | ".join(parts)


# ---------------------------------------------------------------- drawing (reusable)

def new_figure(world: World | None = None, width_in: float = 11.0) -> tuple[Figure, Axes]:
    """An Agg figure with one equal-aspect axes in metres, shaped like the world when there is one."""
    aspect = world.bounds[1] / world.bounds[0] if world is not None else 0.8
    fig = Figure(figsize=(width_in, max(4.0, min(14.0, width_in * 0.75 * aspect + 1.0))), dpi=110)
    ax = fig.add_subplot()
    ax.set_aspect("equal")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    return fig, ax


def _extent(info) -> tuple[float, float, float, float]:
    x0, y0 = info.origin.x, info.origin.y
    return x0, x0 + info.width * info.resolution, y0, y0 + info.height * info.resolution


def draw_grid(ax: Axes, grid: OccupancyGrid, **style) -> None:
    """An occupancy grid with an unrotated origin: occupied dark, unknown light grey, free white."""
    shade = np.where(grid.data > GRID_OBSTACLE, 0.1, np.where(grid.data < 0, 0.85, 1.0))
    ax.imshow(shade, cmap="gray", vmin=0.0, vmax=1.0, origin="lower", interpolation="nearest",
              extent=_extent(grid.info), **{"zorder": 0, **style})


def draw_costmap(ax: Axes, costmap: Costmap, **style):
    """A costmap's non-zero costs (inflation to lethal) over whatever is drawn below; unknown left out."""
    costs = np.ma.masked_where((costmap.data == 0) | (costmap.data == 255), costmap.data)
    return ax.imshow(costs, cmap="YlOrRd", vmin=0, vmax=254, origin="lower", interpolation="nearest",
                     extent=_extent(costmap.info), **{"alpha": 0.45, "zorder": 0.5, **style})


def draw_world(ax: Axes, world: World) -> None:
    """The static world: the map's cells (occupied dark, unknown light grey), solids, circles."""
    if world.grid is not None:
        draw_grid(ax, world.grid if world.grid.info.origin.theta == 0.0
                  else world.rasterize(world.grid.info.resolution))
    for quad in world.solids:
        ax.add_patch(Polygon(quad, closed=True, facecolor="0.55", edgecolor="0.35", linewidth=0.5, zorder=1))
    for x, y, r in world.circles:
        ax.add_patch(Circle((x, y), r, facecolor="0.55", edgecolor="0.35", linewidth=0.5, zorder=1))
    xmin, ymin, xmax, ymax = world.extent
    margin = 0.3
    ax.set_xlim(xmin - margin, xmax + margin)
    ax.set_ylim(ymin - margin, ymax + margin)


def draw_track(ax: Axes, track: Track, **style) -> Line2D:
    """A trajectory as a line; style goes to Axes.plot."""
    (line,) = ax.plot(track.poses[:, 0], track.poses[:, 1], **style)
    return line


def draw_footprint(ax: Axes, pose, footprint: np.ndarray = DEFAULT_FOOTPRINT, **style) -> None:
    """The robot's outline at a pose, with a tick from its centre towards its front."""
    outline = compose(np.asarray(pose, float), np.column_stack([footprint, np.zeros(len(footprint))]))[:, :2]
    ax.add_patch(Polygon(outline, closed=True, fill=False, **style))
    front = compose(np.asarray(pose, float), np.array([footprint[:, 0].max(), 0.0, 0.0]))
    ax.plot([pose[0], front[0]], [pose[1], front[1]], color=style.get("edgecolor", "k"), linewidth=1.0)


def scan_points(scan: LaserScan, pose, lidar: LidarParams = LidarParams()) -> np.ndarray:
    """World coordinates (M, 2) of a scan's returns, for the robot at `pose` and the lidar's mount:
    readings within [range_min, range_max] (beyond range_max a driver reports no return, REP 117)."""
    x, y, yaw = laser_pose(pose, lidar)
    angles = yaw + scan.angle_min + np.arange(len(scan.ranges)) * scan.angle_increment
    ranges = np.asarray(scan.ranges, np.float64)
    hit = np.isfinite(ranges) & (ranges > 0) & (ranges >= scan.range_min) & (ranges <= scan.range_max)
    return np.column_stack([x + ranges[hit] * np.cos(angles[hit]), y + ranges[hit] * np.sin(angles[hit])])


def draw_scan(ax: Axes, scan: LaserScan, pose, lidar: LidarParams = LidarParams(), **style):
    points = scan_points(scan, pose, lidar)
    return ax.scatter(points[:, 0], points[:, 1], s=4, linewidths=0, **style)


def draw_run(ax: Axes, run: RunData, world: World | None = None, scan_moments: int = SCAN_MOMENTS) -> list:
    """Trajectories, scans, movers and markers of a run; returns the legend handles."""
    handles = []
    footprint = world.robot.footprint if world is not None else DEFAULT_FOOTPRINT
    if run.map is not None and run.map.info.origin.theta == 0.0:
        draw_grid(ax, run.map, alpha=0.5, zorder=0.2)
    if run.costmap is not None and run.costmap.info.origin.theta == 0.0:
        draw_costmap(ax, run.costmap)
        handles.append(Patch(facecolor=colormaps["YlOrRd"](0.6), alpha=0.45, label="global costmap (last)"))
    first_plans = {}
    for plan in run.plans:          # the first plan of each goal stands out; replans are thin
        first_plans.setdefault(plan.goal_id.split("#")[0], plan)
    for k, plan in enumerate(run.plans):
        first = first_plans.get(plan.goal_id.split("#")[0]) is plan
        (line,) = ax.plot(plan.poses[:, 0], plan.poses[:, 1], color="tab:purple", zorder=4.5,
                          linewidth=1.4 if first else 0.6, alpha=0.9 if first else 0.4, linestyle="-")
        if k == 0:
            line.set_label("global plans (first per goal bold)")
            handles.append(line)
    for k, goal in enumerate(run.goals):
        g = goal.pose
        marker = ax.plot(g.x, g.y, "*", color="tab:purple", markersize=13, zorder=8,
                         label="goals" if k == 0 else None)[0]
        ax.annotate("", (g.x + 0.4 * math.cos(g.theta), g.y + 0.4 * math.sin(g.theta)), (g.x, g.y), zorder=8,
                    arrowprops=dict(arrowstyle="->", color="tab:purple", linewidth=1.2))
        if k == 0:
            handles.append(marker)
    for k in range(run.mover_circles.shape[1]):
        trace = run.mover_circles[:, k]
        (line,) = ax.plot(trace[:, 0], trace[:, 1], color="tab:red", linewidth=0.8, alpha=0.5, linestyle=":")
        ax.add_patch(Circle(trace[-1, :2], trace[-1, 2], facecolor="tab:red", alpha=0.35, edgecolor="tab:red"))
        if k == 0:
            line.set_label("movers (trace, last position)")
            handles.append(line)
    truth = run.truth
    odom = run.odom
    if odom is not None and truth is not None:
        odom = in_world_frame(odom, truth)
    main = truth if truth is not None else odom       # what scans are placed with, and start and end
    if main is not None and run.scans:
        picks = np.unique(np.linspace(0, len(run.scans) - 1, min(scan_moments, len(run.scans))).round().astype(int))
        placed_by = "true pose" if truth is not None else "odometry pose"
        for colour, i in zip(_colours(len(picks)), picks):
            scan = run.scans[i]
            pose = main.at([scan.header.stamp_ns])[0]
            dots = draw_scan(ax, scan, pose, color=colour, zorder=3,
                             label=f"scan at {scan.header.stamp_ns / NS_PER_S:.1f} s ({placed_by})")
            draw_footprint(ax, pose, footprint, edgecolor=colour, linewidth=1.0, zorder=4)
            handles.append(dots)
    if truth is not None:
        handles.append(draw_track(ax, truth, color="k", linewidth=1.6, label="truth", zorder=5))
    if odom is not None:
        handles.append(draw_track(ax, odom, color="tab:blue", linewidth=1.2, linestyle="--", zorder=6,
                                  label="wheel odometry" + (" (aligned at start)" if truth is not None else "")))
    if run.estimate is not None:
        handles.append(draw_track(ax, run.estimate, color="tab:cyan", linewidth=1.2, linestyle="-.", zorder=6,
                                  label="localizer estimate"))
        draw_footprint(ax, run.estimate.poses[-1], footprint, edgecolor="tab:cyan", linewidth=1.4, zorder=7)
        handles.append(ax.plot(*run.estimate.poses[-1, :2], "D", color="tab:cyan", markersize=7, zorder=7,
                               label="localizer's final pose")[0])
    if run.follower is not None:
        follower = in_world_frame(run.follower, truth) if truth is not None else run.follower
        handles.append(draw_track(ax, follower, color="tab:orange", linewidth=1.2, linestyle=":", zorder=6,
                                  label="follower-wheel odometry"))
    if main is not None:
        handles.append(ax.plot(*main.poses[0, :2], "o", color="tab:green", markersize=8, zorder=7, label="start")[0])
        handles.append(ax.plot(*main.poses[-1, :2], "s", color="tab:red", markersize=8, zorder=7, label="end")[0])
    return handles


def _colours(n: int) -> list:
    cmap = colormaps["viridis"]
    return [cmap(v) for v in np.linspace(0.1, 0.85, n)] if n else []


def report_figure(run: RunData, world: World | None, name: str) -> Figure:
    fig, ax = new_figure(world)
    if world is not None:
        draw_world(ax, world)
    handles = draw_run(ax, run, world)
    if handles:
        legend = ax.legend(handles=handles, loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8, frameon=False)
        for handle in legend.legend_handles:
            if isinstance(handle, PathCollection):      # scan dots: visible in the legend
                handle.set_sizes([16])
    if world is None:
        ax.autoscale_view()
        ax.margins(0.05)
    ax.set_title(title_of(summarize(run), name), fontsize=10)
    ax.grid(True, linewidth=0.3, alpha=0.5)
    return fig


# ---------------------------------------------------------------- the command

def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("file", help="the recording (MCAP)")
    parser.add_argument("-o", "--output", required=True, metavar="PNG", help="the picture to write")
    parser.add_argument("--world", help="world name or file (default: the one the sim's Diagnostic names)")
    parser.add_argument("--robot", default=DEFAULT_ROBOT, help="robot namespace (default r1)")


def _world(args: argparse.Namespace, run: RunData) -> World | None:
    if args.world:
        try:
            return load_world(world_path(args.world))
        except WorldError as exc:
            raise ReportError(f"--world: {exc}") from None
    recorded = run.sim_values.get(WORLD_KEY)
    if not isinstance(recorded, str) or not recorded:
        print("omninav report: the recording names no world (no sim Diagnostic): drawing only the data",
              file=sys.stderr)
        return None
    try:
        return load_world(world_path(recorded))
    except WorldError as exc:
        print(f"omninav report: cannot draw the recorded world ({exc}); drawing only the data "
              "(give it with --world)", file=sys.stderr)
        return None


@exits_2_on_user_error("report")
def main(args: argparse.Namespace) -> int:
    try:
        KeyLayout(args.robot)
    except ValueError as exc:
        raise ReportError(str(exc)) from None
    if Path(args.output).resolve() == Path(args.file).resolve():
        raise ReportError(f"-o {args.output} is the recording itself; choose another file")
    run = load_run(args.file, args.robot)
    if run.truth is None and run.odom is None and not run.scans:
        raise ReportError(f"{args.file}: nothing to draw for robot {args.robot!r} (no truth, odom or scan)")
    world = _world(args, run)
    name = world.name if world is not None else Path(args.file).stem
    fig = report_figure(run, world, name)
    try:
        Path(args.output).parent.mkdir(parents=True, exist_ok=True)
        fig.savefig(args.output, bbox_inches="tight")
    except (OSError, ValueError) as exc:
        raise ReportError(f"-o {args.output}: cannot write ({exc})") from None
    summary = summarize(run)
    print(f"wrote {args.output}: {title_of(summary, name)}"
          + (f"; {run.malformed} malformed messages skipped" if run.malformed else ""))
    return 0
