"""omninav messages → Rerun log calls: one pure function per message kind (no bus, no server).

The live view in a browser (`omninav view --rerun`, rerun_node.py) and `omninav export --rerun`
(rerun_export.py) both route decoded messages through RERUN_ROUTES, with convert.py's Converter
(grids only when they changed) and RouteTable (which key is which route), so a recording opens in
Rerun's viewer as the running stack looks there.

Frames are entity paths, so Rerun's transform tree places everything as Foxglove's /tf does:
world → map (identity: the simulator's map is drawn in its world frame) → odom (tf/map_odom) →
base_link (wheel odometry) → laser (the lidar's mounting). The root `world` is mirrored in y:
Rerun's 2D view draws y downwards, a map is read with y upwards.
Time is the `sim_time` timeline (each message's stamp), so scrubbing a recording is scrubbing sim time.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Callable

import numpy as np
import rerun as rr
import rerun.blueprint as rrb

from ...schemas import messages as m
from .convert import DIAGNOSTICS, Route, ViewParams

TIMELINE = "sim_time"
APPLICATION_ID = "omninav"
ROOT = "world"
FRAME_PATHS = {"world": ROOT, "map": f"{ROOT}/map", "odom": f"{ROOT}/map/odom",
               "base_link": f"{ROOT}/map/odom/base_link"}
LASER_PATH = f"{FRAME_PATHS['base_link']}/laser"    # the scan's frame, whatever the lidar names it
GLOBAL_COSTMAP = "costmap_global"
GLOBAL_COSTMAP_PATH = f"{FRAME_PATHS['map']}/{GLOBAL_COSTMAP}"    # where the stack's global costmap (frame map) lands

# colours (RGB(A) 0-255) chosen apart from each other and from the viewer's own whites, greys and
# blues, so a screenshot can tell what is drawn (tests/test_view_rerun.py counts them)
FREE_RGB = (240, 234, 210)
OCCUPIED_RGB = (20, 20, 90)
UNKNOWN_RGB = (120, 120, 120)
ROBOT_RGB = (26, 204, 51)          # the footprint where the simulator says the robot is (Foxglove's truth green)
SCAN_RGB = (230, 30, 30)
PLAN_RGB = (120, 40, 255)
LOCAL_PLAN_RGB = (0, 200, 220)
GOAL_RGB = (230, 0, 230)
POSE_RGB = (255, 200, 0)
PARTICLE_RGB = (255, 200, 0, 90)
MOVER_RGBA = (230, 102, 26, 200)
TRACK_RGBA = (204, 26, 204, 150)
LETHAL_RGBA = (255, 0, 255, 110)   # costmaps: lethal and inscribed cells over the map, the rest clear
INFLATED_RGBA = (0, 190, 255, 70)

# what is drawn over what (higher on top)
MAP_ORDER, COSTMAP_ORDER, PLAN_ORDER, MOVER_ORDER, SCAN_ORDER, ROBOT_ORDER = -20.0, -10.0, 10.0, 15.0, 20.0, 30.0
LINE_RADIUS_M = 0.02
SCAN_RADIUS_M = 0.035
PARTICLE_RADIUS_M = 0.02
ARROW_SECONDS = 1.0                 # a track's velocity arrow is as long as it moves in this time
LETHAL, INSCRIBED = 254, 253        # costmap_2d's costs
MIRROR_Y = [[1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, 1.0]]


@dataclass(frozen=True)
class Logged:
    """One rr.log call: an archetype (or several) at an entity path."""
    path: str
    archetypes: Any


def frame_path(frame_id: str, default: str = "map") -> str:
    return FRAME_PATHS.get(frame_id) or FRAME_PATHS[default]


def planar_transform(x: float, y: float, theta: float, scale: float | None = None) -> rr.Transform3D:
    return rr.Transform3D(translation=[float(x), float(y), 0.0],
                          rotation=rr.RotationAxisAngle(axis=[0.0, 0.0, 1.0], radians=float(theta)),
                          scale=scale)


def placed(pose: m.Pose2D, points: np.ndarray) -> np.ndarray:
    """Points (N, 2) of a body frame placed at a pose."""
    c, s = math.cos(pose.theta), math.sin(pose.theta)
    return np.asarray(points, float) @ np.array([[c, s], [-s, c]]) + (pose.x, pose.y)


def closed(points: np.ndarray) -> np.ndarray:
    return np.vstack([points, points[:1]])


# ---------------------------------------------------------------- one function per message kind

def _grid(header: m.Header, info: m.MapMetaData, rgb: np.ndarray, name: str, default_frame: str,
          order: float) -> list[Logged]:
    """Cell (row, col) at the grid's origin + (col, row) · resolution: rows run +x and stack +y, as
    Rerun's image rows do in the mirrored root."""
    path = f"{frame_path(header.frame_id, default_frame)}/{name}"
    o = info.origin
    return [Logged(path, [planar_transform(o.x, o.y, o.theta, scale=info.resolution),
                          rr.Image(np.ascontiguousarray(rgb), draw_order=order,
                                   magnification_filter="Nearest")])]


def occupancy_colours(data: np.ndarray) -> np.ndarray:
    """int8 occupancy (-1 unknown, 0..100 percent) as RGB: free to occupied blended, unknown grey."""
    p = np.clip(data.astype(np.float32), 0, 100)[..., None] / 100.0
    rgb = (1 - p) * np.array(FREE_RGB, np.float32) + p * np.array(OCCUPIED_RGB, np.float32)
    rgb[data < 0] = UNKNOWN_RGB
    return rgb.round().astype(np.uint8)


def costmap_colours(data: np.ndarray) -> np.ndarray:
    """uint8 costs as RGBA over the map: lethal and inscribed cells tinted, inflation faint, free
    and unknown clear."""
    rgba = np.zeros(data.shape + (4,), np.uint8)
    rgba[(data > 0) & (data < INSCRIBED)] = INFLATED_RGBA
    rgba[(data == INSCRIBED) | (data == LETHAL)] = LETHAL_RGBA
    return rgba


def occupancy_grid(msg: m.OccupancyGrid, params: ViewParams) -> list[Logged]:
    return _grid(msg.header, msg.info, occupancy_colours(msg.data), "occupancy", "map", MAP_ORDER)


def costmap(name: str) -> Callable[[m.Costmap, ViewParams], list[Logged]]:
    return lambda msg, params: _grid(msg.header, msg.info, costmap_colours(msg.data), name, "map", COSTMAP_ORDER)


def scan_points(msg: m.LaserScan) -> np.ndarray:
    """The valid returns (range_min ≤ r ≤ range_max, finite) as points (N, 2) in the laser's frame."""
    ranges = np.asarray(msg.ranges, float)
    angles = msg.angle_min + np.arange(len(ranges)) * msg.angle_increment
    valid = np.isfinite(ranges) & (ranges >= msg.range_min) & (ranges <= msg.range_max)
    return np.column_stack([ranges[valid] * np.cos(angles[valid]), ranges[valid] * np.sin(angles[valid])])


def laser_scan(msg: m.LaserScan, params: ViewParams) -> list[Logged]:
    return [Logged(LASER_PATH, planar_transform(*params.laser_mount)),
            Logged(f"{LASER_PATH}/scan", rr.Points2D(scan_points(msg), radii=SCAN_RADIUS_M, colors=SCAN_RGB,
                                                     draw_order=SCAN_ORDER))]


def frame_transform(msg: m.Transform, params: ViewParams) -> list[Logged]:
    t = msg.transform
    return [Logged(frame_path(msg.child_frame_id, "odom"), planar_transform(t.x, t.y, t.theta))]


def odometry_transform(msg: m.Odometry, params: ViewParams) -> list[Logged]:
    """odom → base_link from wheel odometry."""
    p = msg.pose
    return [Logged(frame_path(msg.child_frame_id, "base_link"), planar_transform(p.x, p.y, p.theta))]


def truth_robot(msg: m.Odometry, params: ViewParams) -> list[Logged]:
    """The footprint where the simulator says the robot is, with a line showing its heading."""
    footprint = np.asarray(params.footprint, float)
    reach = float(np.hypot(footprint[:, 0], footprint[:, 1]).max())
    heading = placed(msg.pose, [[0.0, 0.0], [reach, 0.0]])
    return [Logged(f"{frame_path(msg.header.frame_id, 'world')}/robot",
                   rr.LineStrips2D([closed(placed(msg.pose, footprint)), heading], radii=LINE_RADIUS_M,
                                   colors=ROBOT_RGB, draw_order=ROBOT_ORDER))]


def pose(msg: m.PoseWithCovariance, params: ViewParams) -> list[Logged]:
    p = msg.pose
    reach = float(np.hypot(*np.asarray(params.footprint, float).T).max())
    return [Logged(f"{frame_path(msg.header.frame_id)}/pose",
                   rr.Arrows2D(origins=[[p.x, p.y]], vectors=[[reach * math.cos(p.theta), reach * math.sin(p.theta)]],
                               radii=LINE_RADIUS_M, colors=POSE_RGB, draw_order=ROBOT_ORDER))]


def particle_cloud(msg: m.ParticleCloud, params: ViewParams) -> list[Logged]:
    return [Logged(f"{frame_path(msg.header.frame_id)}/particles",
                   rr.Points2D(np.asarray(msg.poses)[:, :2], radii=PARTICLE_RADIUS_M, colors=PARTICLE_RGB,
                               draw_order=PLAN_ORDER))]


def path(name: str, rgb: tuple[int, int, int]) -> Callable[[m.Path, ViewParams], list[Logged]]:
    """A plan as a line through its poses (none when the planner failed: that clears the old one)."""
    def draw(msg: m.Path, params: ViewParams) -> list[Logged]:
        strips = [np.asarray(msg.poses)[:, :2]] if len(msg.poses) else []
        return [Logged(f"{frame_path(msg.header.frame_id)}/{name}",
                       rr.LineStrips2D(strips, radii=LINE_RADIUS_M, colors=rgb, draw_order=PLAN_ORDER))]
    return draw


def goal(msg: m.Goal, params: ViewParams) -> list[Logged]:
    """The waypoints in order, then the goal pose."""
    points = np.vstack([np.asarray(msg.waypoints, float).reshape(-1, 3)[:, :2], [[msg.pose.x, msg.pose.y]]])
    return [Logged(f"{frame_path(msg.header.frame_id)}/goal",
                   rr.Points2D(points, radii=3 * LINE_RADIUS_M, colors=GOAL_RGB, draw_order=PLAN_ORDER))]


def movers(msg: m.Obstacles, params: ViewParams) -> list[Logged]:
    """Each mover as a disc of its radius."""
    circles = np.asarray(msg.circles, float).reshape(-1, 3)
    return [Logged(f"{frame_path(msg.header.frame_id, 'world')}/movers",
                   rr.Points2D(circles[:, :2], radii=circles[:, 2], colors=MOVER_RGBA, draw_order=MOVER_ORDER))]


def tracks(msg: m.Tracks, params: ViewParams) -> list[Logged]:
    """Each tracked moving obstacle as a disc of its estimated radius with an arrow along its velocity."""
    states = np.asarray(msg.states, float).reshape(-1, 4)
    base = f"{frame_path(msg.header.frame_id, 'odom')}/tracks"
    return [Logged(f"{base}/discs", rr.Points2D(states[:, :2], radii=np.asarray(msg.radii, float),
                                                colors=TRACK_RGBA, draw_order=MOVER_ORDER)),
            Logged(f"{base}/velocity", rr.Arrows2D(origins=states[:, :2], vectors=states[:, 2:] * ARROW_SECONDS,
                                                   radii=LINE_RADIUS_M, colors=TRACK_RGBA, draw_order=MOVER_ORDER))]


DIAGNOSTIC_LEVELS = {0: "INFO", 1: "WARN", 2: "ERROR"}


def diagnostic(msg: m.Diagnostic, params: ViewParams) -> list[Logged]:
    """A service's Diagnostic as a text log line (its counters and parameters in the text)."""
    values = ", ".join(f"{k}={v}" for k, v in sorted(msg.values.items()))
    return [Logged(f"diagnostics/{msg.name}", rr.TextLog(f"{msg.message} {values}".strip(),
                                                         level=DIAGNOSTIC_LEVELS.get(msg.level, "ERROR")))]


RERUN_ROUTES: tuple[Route, ...] = (
    Route("map", occupancy_grid, grid=True),
    Route("costmap/global", costmap(GLOBAL_COSTMAP), grid=True),
    Route("costmap/local", costmap("costmap_local"), grid=True),
    Route("scan", laser_scan),
    Route("sim/truth", truth_robot),
    Route("odom", odometry_transform),
    Route("tf/map_odom", frame_transform),
    Route("pose", pose),
    Route("particlecloud", particle_cloud),
    Route("plan", path("plan", PLAN_RGB)),
    Route("local_plan", path("local_plan", LOCAL_PLAN_RGB)),
    Route("goal", goal),
    Route("sim/movers", movers),
    Route("tracks", tracks),
    Route(DIAGNOSTICS, diagnostic),
)


def scene_setup() -> list[Logged]:
    """What holds for the whole recording: the mirrored root (static)."""
    return [Logged(ROOT, rr.Transform3D(mat3x3=MIRROR_Y))]


def blueprint() -> rrb.Blueprint:
    """One 2D view of the world with the panels folded away; the global costmap is logged but hidden
    (it would tint every wall; tick it in the viewer's entity list)."""
    return rrb.Blueprint(
        rrb.Horizontal(
            rrb.Spatial2DView(name="omninav", origin="/", contents=["+ /world/**", f"- {GLOBAL_COSTMAP_PATH}"]),
            rrb.TextLogView(name="diagnostics", origin="/diagnostics"),
            column_shares=[4, 1]),
        collapse_panels=True)


def log_static(recording: rr.RecordingStream) -> None:
    for logged in scene_setup():
        recording.log(logged.path, logged.archetypes, static=True)


def log_at(recording: rr.RecordingStream, stamp_ns: int, outputs: list[Logged]) -> None:
    """Log outputs at a message's sim stamp on the TIMELINE."""
    if not outputs:
        return
    recording.set_time(TIMELINE, duration=np.timedelta64(max(stamp_ns, 0), "ns"))
    for logged in outputs:
        archetypes = logged.archetypes if isinstance(logged.archetypes, list) else [logged.archetypes]
        recording.log(logged.path, *archetypes)
