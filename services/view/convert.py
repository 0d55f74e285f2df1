"""omninav messages → Foxglove's well-known schemas: one pure function per message kind (no bus).

The live view (node.py) and `omninav export --foxglove` (export.py) both route decoded messages
through `ROUTES`, so a recording opens in Foxglove with the same channels as the running stack.
Frames: world → map (identity: the simulator's maps are drawn in its world frame) → odom (the
localizer's or SLAM's tf/map_odom) → base_link (wheel odometry) → laser (the lidar's mounting).
Adding a message kind is one function plus one Route.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from json import JSONDecodeError, loads
from typing import Any, Callable

import numpy as np
from foxglove.messages import (ArrowPrimitive, Color, CylinderPrimitive, FrameTransform, FrameTransforms, Grid, LaserScan,
                               LinePrimitive, LinePrimitiveLineType, PackedElementField,
                               PackedElementFieldNumericType, Point3, Pose, PoseInFrame, PosesInFrame, Quaternion,
                               SceneEntity, SceneUpdate, Timestamp, Vector2, Vector3)

from ...schemas import messages as m
from ...schemas.keys import KeyLayout, type_for_key
from ...geometry.footprint import DEFAULT_FOOTPRINT
from ...parameters.declare import Parameters, param

NS_PER_S = 1_000_000_000
WORLD_FRAME, MAP_FRAME, ODOM_FRAME, BASE_FRAME = "world", "map", "odom", "base_link"
TRUTH_COLOR = Color(r=0.1, g=0.8, b=0.2, a=1.0)
MOVER_COLOR = Color(r=0.9, g=0.4, b=0.1, a=0.8)
MOVER_HEIGHT_M = 0.5
TRACK_COLOR = Color(r=0.8, g=0.1, b=0.8, a=0.6)
TRACK_HEIGHT_M = 0.3            # lower than the movers, so a track and the mover it follows both show
ARROW_SECONDS = 1.0             # a velocity arrow is as long as the track moves in this time
MAX_SEC = 2**32 - 1


@dataclass(frozen=True)
class JsonMessage:
    """A message for a JSON channel, with the JSON Schema that names and describes its type."""
    schema_name: str
    schema: dict
    value: dict


Output = tuple[str, Any]        # (Foxglove topic, a foxglove.messages instance or a JsonMessage)

DIAGNOSTIC_SCHEMA = {
    "type": "object",
    "properties": {
        "timestamp": {"type": "object", "properties": {"sec": {"type": "integer"}, "nsec": {"type": "integer"}}},
        "name": {"type": "string", "description": "the service"},
        "level": {"type": "integer", "description": "0 ok, 1 warn, 2 error"},
        "message": {"type": "string"},
        "values": {"type": "object", "description": "counters, first input seqs, parameters"},
    },
}


@dataclass(frozen=True)
class ViewParams(Parameters):
    """What the messages do not say: the robot's outline and where its lidar sits."""
    # polygon in base_link, m: the simulator's default robot
    footprint: tuple[tuple[float, float], ...] = param(tuple(map(tuple, DEFAULT_FOOTPRINT.tolist())), min_items=3)
    laser_mount: tuple[float, float, float] = param((0.0, 0.0, 0.0), items=3, finite=True)            # x, y, yaw of the laser in base_link


# ---------------------------------------------------------------- geometry helpers

def timestamp(stamp_ns: int) -> Timestamp:
    """Foxglove's time is unsigned 32-bit seconds: a stamp outside that (only a broken publisher
    sends one) is shown at the nearest end rather than refused."""
    sec, nsec = divmod(stamp_ns, NS_PER_S)
    if not 0 <= sec <= MAX_SEC:
        sec, nsec = min(max(sec, 0), MAX_SEC), 0
    return Timestamp(sec=sec, nsec=nsec)


def yaw_quaternion(theta: float) -> Quaternion:
    return Quaternion(x=0.0, y=0.0, z=math.sin(theta / 2), w=math.cos(theta / 2))


def pose_3d(x: float, y: float, theta: float) -> Pose:
    return Pose(position=Vector3(x=float(x), y=float(y), z=0.0), orientation=yaw_quaternion(float(theta)))


def poses_3d(poses: np.ndarray) -> list[Pose]:
    return [pose_3d(x, y, theta) for x, y, theta in poses]


def frame_transform(stamp_ns: int, parent: str, child: str, x: float, y: float, theta: float) -> FrameTransform:
    return FrameTransform(timestamp=timestamp(stamp_ns), parent_frame_id=parent, child_frame_id=child,
                          translation=Vector3(x=float(x), y=float(y), z=0.0), rotation=yaw_quaternion(float(theta)))


def footprint_at(pose: m.Pose2D, footprint) -> list[Point3]:
    """The footprint polygon placed at a pose, as points of a closed loop."""
    c, s = math.cos(pose.theta), math.sin(pose.theta)
    return [Point3(x=pose.x + c * px - s * py, y=pose.y + s * px + c * py, z=0.0) for px, py in footprint]


# ---------------------------------------------------------------- one function per message kind

def _grid(header: m.Header, info: m.MapMetaData, data: np.ndarray, field: str,
          numeric_type: PackedElementFieldNumericType) -> Grid:
    return Grid(timestamp=timestamp(header.stamp_ns), frame_id=header.frame_id or MAP_FRAME,
                pose=pose_3d(info.origin.x, info.origin.y, info.origin.theta), column_count=info.width,
                cell_size=Vector2(x=info.resolution, y=info.resolution), row_stride=info.width, cell_stride=1,
                fields=[PackedElementField(name=field, offset=0, type=numeric_type)],
                data=np.ascontiguousarray(data).tobytes())


def occupancy_grid(msg: m.OccupancyGrid) -> Grid:
    """Cells as int8 'occupancy': -1 unknown, 0..100 percent (both rows run +x, rows stack +y)."""
    return _grid(msg.header, msg.info, msg.data, "occupancy", PackedElementFieldNumericType.Int8)


def costmap_grid(msg: m.Costmap) -> Grid:
    """Cells as uint8 'cost', costmap_2d's raw 0..255 (254 lethal, 255 unknown)."""
    return _grid(msg.header, msg.info, msg.data, "cost", PackedElementFieldNumericType.Uint8)


def laser_scan(msg: m.LaserScan) -> LaserScan:
    last_angle = msg.angle_min + (len(msg.ranges) - 1) * msg.angle_increment
    return LaserScan(timestamp=timestamp(msg.header.stamp_ns), frame_id=msg.header.frame_id, pose=pose_3d(0, 0, 0),
                     start_angle=msg.angle_min, end_angle=last_angle,
                     ranges=msg.ranges.astype(float).tolist(), intensities=msg.intensities.astype(float).tolist())


def laser_mount(msg: m.LaserScan, params: ViewParams) -> FrameTransforms:
    """base_link → the scan's frame, so the 3D panel places the scan on the robot."""
    return FrameTransforms(transforms=[frame_transform(msg.header.stamp_ns, BASE_FRAME, msg.header.frame_id,
                                                       *params.laser_mount)])


def transform(msg: m.Transform) -> FrameTransforms:
    t = msg.transform
    return FrameTransforms(transforms=[frame_transform(msg.header.stamp_ns, msg.header.frame_id, msg.child_frame_id,
                                                       t.x, t.y, t.theta)])


def odometry_transform(msg: m.Odometry) -> FrameTransforms:
    """odom → base_link from wheel odometry (what the chassis's tf/odom_base also says)."""
    p = msg.pose
    return FrameTransforms(transforms=[frame_transform(msg.header.stamp_ns, msg.header.frame_id, msg.child_frame_id,
                                                       p.x, p.y, p.theta)])


def truth_robot(msg: m.Odometry, params: ViewParams) -> SceneUpdate:
    """The robot's footprint where the simulator says it is, with a line showing its heading."""
    pose = msg.pose
    outline = LinePrimitive(type=LinePrimitiveLineType.LineLoop, thickness=0.03, scale_invariant=False,
                            points=footprint_at(pose, params.footprint), color=TRUTH_COLOR)
    reach = max(math.hypot(px, py) for px, py in params.footprint)
    heading = LinePrimitive(type=LinePrimitiveLineType.LineStrip, thickness=0.03, scale_invariant=False,
                            points=[Point3(x=pose.x, y=pose.y, z=0.0),
                                    Point3(x=pose.x + reach * math.cos(pose.theta),
                                           y=pose.y + reach * math.sin(pose.theta), z=0.0)],
                            color=TRUTH_COLOR)
    return SceneUpdate(entities=[SceneEntity(timestamp=timestamp(msg.header.stamp_ns), frame_id=msg.header.frame_id,
                                             id="truth", lines=[outline, heading])])


def world_is_map(msg: m.Odometry) -> FrameTransforms:
    """world → map, identity: the simulator's map is drawn in its world frame, so the truth and
    everything in the map frame share one tree."""
    return FrameTransforms(transforms=[frame_transform(msg.header.stamp_ns, msg.header.frame_id, MAP_FRAME, 0, 0, 0)])


def pose_in_frame(msg: m.PoseWithCovariance) -> PoseInFrame:
    p = msg.pose
    return PoseInFrame(timestamp=timestamp(msg.header.stamp_ns), frame_id=msg.header.frame_id or MAP_FRAME,
                       pose=pose_3d(p.x, p.y, p.theta))


def particle_cloud(msg: m.ParticleCloud) -> PosesInFrame:
    return PosesInFrame(timestamp=timestamp(msg.header.stamp_ns), frame_id=msg.header.frame_id or MAP_FRAME,
                        poses=poses_3d(msg.poses))


def path(msg: m.Path) -> PosesInFrame:
    """A plan as its poses (empty when the planner failed: that clears the old one in the panel)."""
    return PosesInFrame(timestamp=timestamp(msg.header.stamp_ns), frame_id=msg.header.frame_id or MAP_FRAME,
                        poses=poses_3d(msg.poses))


def goal(msg: m.Goal) -> PosesInFrame:
    """The waypoints in order, then the goal pose."""
    p = msg.pose
    return PosesInFrame(timestamp=timestamp(msg.header.stamp_ns), frame_id=msg.header.frame_id or MAP_FRAME,
                        poses=poses_3d(msg.waypoints) + [pose_3d(p.x, p.y, p.theta)])


def movers(msg: m.Obstacles) -> SceneUpdate:
    """Each mover as a cylinder; one entity, so movers that left the world disappear with it."""
    cylinders = [CylinderPrimitive(pose=pose_3d(x, y, 0.0), size=Vector3(x=2 * r, y=2 * r, z=MOVER_HEIGHT_M),
                                   bottom_scale=1.0, top_scale=1.0, color=MOVER_COLOR)
                 for x, y, r in msg.circles]
    return SceneUpdate(entities=[SceneEntity(timestamp=timestamp(msg.header.stamp_ns),
                                             frame_id=msg.header.frame_id or WORLD_FRAME, id="movers",
                                             cylinders=cylinders)])


def tracks(msg: m.Tracks) -> SceneUpdate:
    """Each tracked moving obstacle as a cylinder of its estimated radius with an arrow along its
    velocity (as long as the way it covers in ARROW_SECONDS); one entity, so lost tracks disappear."""
    cylinders, arrows = [], []
    for (x, y, vx, vy), radius in zip(msg.states, msg.radii):
        cylinders.append(CylinderPrimitive(pose=pose_3d(x, y, 0.0), size=Vector3(x=2 * radius, y=2 * radius,
                                                                                  z=TRACK_HEIGHT_M),
                                           bottom_scale=1.0, top_scale=1.0, color=TRACK_COLOR))
        speed = math.hypot(vx, vy)
        if speed > 0:
            arrows.append(ArrowPrimitive(pose=pose_3d(x, y, math.atan2(vy, vx)), shaft_length=speed * ARROW_SECONDS,
                                         shaft_diameter=0.04, head_length=0.1, head_diameter=0.1, color=TRACK_COLOR))
    return SceneUpdate(entities=[SceneEntity(timestamp=timestamp(msg.header.stamp_ns),
                                             frame_id=msg.header.frame_id or ODOM_FRAME, id="tracks",
                                             cylinders=cylinders, arrows=arrows)])


def diagnostic(msg: m.Diagnostic) -> JsonMessage:
    """A service's Diagnostic as JSON (Foxglove shows it in a Raw Messages panel)."""
    return JsonMessage("omninav.Diagnostic", DIAGNOSTIC_SCHEMA, {
        "timestamp": {"sec": msg.header.stamp_ns // NS_PER_S, "nsec": msg.header.stamp_ns % NS_PER_S},
        "name": msg.name, "level": msg.level, "message": msg.message, "values": dict(msg.values)})


# ---------------------------------------------------------------- which key goes where

@dataclass(frozen=True)
class Route:
    """One omninav topic (as services name it: 'scan', 'sim/truth'; DIAGNOSTICS: every service's) and
    what it becomes."""
    source: str
    convert: Callable[[Any, ViewParams], list[Output]]
    grid: bool = False          # a heavy channel: sent only when it changed (see Throttle)


def _to(topic: str, function: Callable[[Any], Any]) -> Callable[[Any, ViewParams], list[Output]]:
    return lambda msg, params: [(topic, function(msg))]


DIAGNOSTICS = "diagnostics"
TF_TOPIC = "/tf"
DIAGNOSTICS_TOPIC = "/diagnostics"
ROUTES: tuple[Route, ...] = (
    Route("map", _to("/map", occupancy_grid), grid=True),
    Route("costmap/global", _to("/costmap/global", costmap_grid), grid=True),
    Route("costmap/local", _to("/costmap/local", costmap_grid), grid=True),
    Route("scan", lambda msg, params: [("/scan", laser_scan(msg)), (TF_TOPIC, laser_mount(msg, params))]),
    Route("sim/truth", lambda msg, params: [("/truth/robot", truth_robot(msg, params)), (TF_TOPIC, world_is_map(msg))]),
    Route("odom", _to(TF_TOPIC, odometry_transform)),
    Route("tf/map_odom", _to(TF_TOPIC, transform)),
    Route("pose", _to("/localizer/pose", pose_in_frame)),
    Route("particlecloud", _to("/localizer/particles", particle_cloud)),
    Route("plan", _to("/plan", path)),
    Route("local_plan", _to("/local_plan", path)),
    Route("goal", _to("/goal", goal)),
    Route("sim/movers", _to("/truth/movers", movers)),
    Route("tracks", _to("/tracks", tracks)),
    Route(DIAGNOSTICS, lambda msg, params: [(f"{DIAGNOSTICS_TOPIC}/{msg.name}", diagnostic(msg))]),
)


class RouteTable:
    """The routes on the keys of one robot namespace (Foxglove's, or another viewer's with a DIAGNOSTICS route)."""

    def __init__(self, keys: KeyLayout, routes: tuple[Route, ...] = ROUTES):
        self.keys = keys
        self.routes = routes
        self._by_key = {self.key_expr(route): route for route in routes}
        self._diagnostics = self._by_key[keys.diagnostics_of_all()]

    def key_expr(self, route: Route) -> str:
        """The key (expression) a route takes its messages from."""
        return self.keys.diagnostics_of_all() if route.source == DIAGNOSTICS else self.keys.resolve(route.source)

    def route_for(self, key: str) -> Route | None:
        """The route of a concrete key (a diagnostics key of any service of this robot), or None."""
        route = self._by_key.get(key)
        if route is None and type_for_key(key) is m.Diagnostic and \
                key.rsplit("/", 1)[0] == self.keys.diagnostics_of_all().rsplit("/", 1)[0]:
            return self._diagnostics
        return route


class Throttle:
    """Grids are large and mostly unchanged between publications: pass one only when its cells or
    placement differ from the last one passed on its topic, and at most once per period of sim
    time (so a costmap updating at 5 Hz reaches the viewer at about 1 Hz)."""

    def __init__(self, period_s: float = 1.0):
        self.period_ns = round(period_s * NS_PER_S)
        self._last: dict[str, tuple[int, tuple, bytes]] = {}     # topic -> (stamp, info, cells)

    def passes(self, topic: str, msg: m.OccupancyGrid | m.Costmap) -> bool:
        info = (msg.info.resolution, msg.info.width, msg.info.height,
                msg.info.origin.x, msg.info.origin.y, msg.info.origin.theta, msg.header.frame_id)
        cells = msg.data.tobytes()
        last = self._last.get(topic)
        if last is not None and (msg.header.stamp_ns - last[0] < self.period_ns or (last[1], last[2]) == (info, cells)):
            return False
        self._last[topic] = (msg.header.stamp_ns, info, cells)
        return True


class Converter:
    """Routes decoded messages to a viewer's outputs (the routes' own: Foxglove messages, Rerun log
    calls), the same for the live view and the export."""

    def __init__(self, params: ViewParams | None = None, grid_period_s: float = 1.0):
        self.params = params or ViewParams()
        self.throttle = Throttle(grid_period_s)

    def outputs(self, route: Route, msg: Any) -> list[Output]:
        if route.grid and not self.throttle.passes(route.source, msg):
            return []
        return route.convert(msg, self.params)


# ---------------------------------------------------------------- goals sent from the Foxglove app

def _finite(value: Any, what: str) -> float:
    number = float(value)
    if not math.isfinite(number):
        raise ValueError(f"{what} is {number}, not a finite number")
    return number


def goal_from_client(data: bytes, stamp_ns: int, goal_id: str) -> m.Goal:
    """A goal from a JSON pose the Foxglove app publishes (its 3D panel's "Publish pose" / 2D goal):
    a geometry_msgs/PoseStamped ({header: {frame_id}, pose}) or a foxglove.PoseInFrame ({frame_id,
    pose}), pose = {position: {x, y, z}, orientation: {x, y, z, w}}. ValueError names what is wrong."""
    try:
        message = loads(data)
        frame = message.get("header", message).get("frame_id", "") or MAP_FRAME
        position, orientation = message["pose"]["position"], message["pose"]["orientation"]
        x, y = _finite(position["x"], "position.x"), _finite(position["y"], "position.y")
        qx, qy, qz, qw = (_finite(orientation.get(axis, 0.0 if axis != "w" else 1.0), f"orientation.{axis}")
                          for axis in "xyzw")
    except JSONDecodeError as exc:
        raise ValueError(f"not JSON: {exc}") from None
    except (KeyError, TypeError, AttributeError) as exc:
        raise ValueError(f"not a PoseStamped or PoseInFrame in JSON: missing or wrong {exc}") from None
    if frame != MAP_FRAME:
        raise ValueError(f"a goal in frame {frame!r}; the navigator takes goals in {MAP_FRAME!r}")
    theta = math.atan2(2 * (qw * qz + qx * qy), 1 - 2 * (qy * qy + qz * qz))
    return m.Goal(header=m.Header(stamp_ns=stamp_ns, frame_id=MAP_FRAME), goal_id=goal_id, pose=m.Pose2D(x, y, theta))
