"""World files: static geometry, moving obstacles and the robot's start, loaded and validated.

The format is described in docs/worlds.md. A World holds its static geometry in two forms:
  - `solids` (K, 4, 2): convex quadrilaterals (walls 0.1 m thick, boxes, the outer walls just
    outside the bounds), counter-clockwise; `segments` (4K, 4) are their edges, for ray casting;
  - `circles` (M, 3): static cylinders (x, y, r);
and optionally an occupancy grid from a ROS map (`map:`), whose occupied cells are obstacles.
Movers are circles moving at constant speed along a closed polyline, or on timed keyframes
(sim/keyframes.py); a path mover with a yield distance stops while the robot is in its way, so where
it is depends on the robot (`Movers.pose_after`).
"""
from __future__ import annotations

import math
import os
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path

import numpy as np

from ..schemas.messages import Header, MapMetaData, OccupancyGrid, Pose2D
from ..parameters.from_mapping import unknown_names
from ..services.map_server.mapio import MapError, load_map, read_yaml
from ..geometry.footprint import DEFAULT_FOOTPRINT
from ..geometry.polygons import (point_segment_distance, points_in_polygons, polygon_area, segment_distance,
                                 transform_points)
from ..geometry.grid import GRID_OBSTACLE, cell_to_world, grid_coords, world_to_cell
from .barn_world import BarnWorldError, barn_world_doc
from .people.plans import PeopleSpec
from .people.spec import people_from_mapping
from .keyframes import INTERPOLATIONS, Keyframes, Tracks

WALL_THICKNESS = 0.1          # m, walls and the outer walls along the bounds
# The mecanum paper's robot: 0.832 m long (x) and 0.636 m wide (y), centred on the robot's origin.
DRIVES = ("mecanum", "omni3", "diff")
DATA_ENV = "OMNINAV_DATA"     # overrides where `map: {relative_to: data}` looks
BARN_SUFFIX = ".world"        # a BARN Challenge world (Gazebo SDF), read by sim/barn_world.py
_EPS = 1e-9                   # shapes that only touch a cell's border do not occupy it


class WorldError(ValueError):
    """A world file that cannot be used; the message names the file and the key path."""


def shared_data_dir(near: Path) -> Path | None:
    """The shared data folder: $OMNINAV_DATA, else `shared/data` beside the checkout holding `near`.

    The checkout is the nearest folder above `near` with a pyproject.toml, so a fresh clone with
    ../shared/data beside it works; an installed package needs the environment variable.
    """
    if os.environ.get(DATA_ENV):
        return Path(os.environ[DATA_ENV])
    for folder in Path(near).resolve().parents:
        if (folder / "pyproject.toml").is_file():
            return folder.parent / "shared" / "data"
    return None


# ---------------------------------------------------------------- geometry helpers

def rectangle(center, size, yaw: float = 0.0) -> np.ndarray:
    """The 4 corners (counter-clockwise) of a w × h rectangle centred at `center`, rotated by yaw."""
    hw, hh = size[0] / 2.0, size[1] / 2.0
    local = np.array([[hw, hh], [-hw, hh], [-hw, -hh], [hw, -hh]])
    c, s = math.cos(yaw), math.sin(yaw)
    return local @ np.array([[c, s], [-s, c]]) + np.asarray(center, np.float64)


def wall_rectangle(x1: float, y1: float, x2: float, y2: float) -> np.ndarray:
    """A wall of WALL_THICKNESS around the segment, extended by half the thickness at both ends
    so that walls meeting at a corner close it."""
    length = math.hypot(x2 - x1, y2 - y1)
    return rectangle(((x1 + x2) / 2, (y1 + y2) / 2), (length + WALL_THICKNESS, WALL_THICKNESS),
                     math.atan2(y2 - y1, x2 - x1))


# ---------------------------------------------------------------- movers

YIELD_MARGIN = 0.1   # m beyond its radius that a yielding mover keeps clear ahead of it (personal space)


@dataclass(frozen=True, eq=False)
class Movers:
    """Circular obstacles: path movers, at constant speed along closed polylines, looping forever,
    and keyframe movers, on timed keyframes (sim/keyframes.py).

    A path mover whose path is not a loop (`loop: false`) goes back and forth: its closed polyline
    is the path followed by the path reversed. Where a mover is depends on how long it has moved:
    `pose_after(moving_s)`. One that never stops has moved for the whole sim time (`pose_at(t)`);
    one with a yield distance stops while the robot is in its way (`yielding`), so the simulation
    keeps each mover's moving time as its state (`Simulation.mover_circles`, the sim/movers key).
    A keyframe mover never stops: its moving time is the sim time.
    """

    radius: np.ndarray = field(default_factory=lambda: np.zeros(0))   # (K,)
    speed: np.ndarray = field(default_factory=lambda: np.zeros(0))    # (K,) m/s of a path mover (0 on keyframes)
    # the polyline each centre follows: a path mover's closed loop (first == last), a keyframe
    # mover's trace over one period (open where its loop jumps back)
    loops: tuple[np.ndarray, ...] = ()
    yield_distance: np.ndarray = field(default_factory=lambda: np.zeros(0))  # (K,) m; 0: never yields
    tracks: tuple[Keyframes | None, ...] = ()                          # (K,) a keyframe mover's; none: all path movers

    def __len__(self) -> int:
        return len(self.loops)

    @cached_property
    def on_keyframes(self) -> np.ndarray:
        """Which movers (K,) move on timed keyframes."""
        return np.array([bool(self.tracks) and self.tracks[k] is not None for k in range(len(self))], bool)

    @cached_property
    def _keyframe_tracks(self) -> Tracks | None:
        """The keyframe movers' tracks, evaluated together."""
        return Tracks([self.tracks[k] for k in np.flatnonzero(self.on_keyframes)]) if self.on_keyframes.any() else None

    @cached_property
    def _segments(self) -> tuple[tuple[np.ndarray, np.ndarray], ...]:
        """Per loop, its segments' lengths and the arc length at the end of each."""
        lengths = [np.hypot(*np.diff(loop, axis=0).T) for loop in self.loops]
        return tuple((length, np.cumsum(length)) for length in lengths)

    def _point(self, k: int, s: float) -> tuple[np.ndarray, np.ndarray, int]:
        """Mover k's path at arc length s (taken around the loop): point, unit direction, segment."""
        loop, (lengths, ends) = self.loops[k], self._segments[k]
        s %= ends[-1]
        i = min(int(np.searchsorted(ends, s, side="right")), len(ends) - 1)
        step = loop[i + 1] - loop[i]
        return loop[i] + step * ((s - (ends[i] - lengths[i])) / lengths[i]), step / lengths[i], i

    def _state(self, moving_s) -> tuple[np.ndarray, np.ndarray]:
        """Every mover's position and velocity (K, 2 each) after moving for moving_s[k] seconds."""
        moving_s = np.broadcast_to(np.asarray(moving_s, np.float64), (len(self),))
        positions, velocities = np.zeros((len(self), 2)), np.zeros((len(self), 2))
        if self._keyframe_tracks is not None:
            keyed = self.on_keyframes
            positions[keyed], velocities[keyed] = self._keyframe_tracks.state(moving_s[keyed])
        for k in np.flatnonzero(~self.on_keyframes):
            point, direction, _ = self._point(k, self.speed[k] * moving_s[k])
            positions[k], velocities[k] = point, direction * self.speed[k]
        return positions, velocities

    def pose_after(self, moving_s) -> np.ndarray:
        """Every mover's position (K, 2) after moving for moving_s[k] seconds from its start."""
        return self._state(moving_s)[0]

    def pose_at(self, t: float) -> np.ndarray:
        """Every mover's position (K, 2) at sim time t had none of them stopped (all start at their
        path's first point): the truth for movers without a yield distance."""
        return self.pose_after(t)

    def velocity_at(self, t: float) -> np.ndarray:
        """Every mover's velocity (K, 2) at sim time t had none of them stopped."""
        return self._state(t)[1]

    def circles_at(self, t: float) -> np.ndarray:
        """Movers as circles (K, 3) of (x, y, r) at time t had none of them stopped, as the ray
        caster takes them."""
        return np.column_stack([self.pose_at(t), self.radius]).reshape(-1, 3)

    def way_ahead(self, k: int, moving_s: float) -> np.ndarray:
        """The polyline (N, 2) mover k's centre follows next, turns and reversals included: from
        a radius ahead of where it is (so what is beside or behind its circle is not ahead of it)
        to `yield_distance` ahead."""
        ends = self._segments[k][1]
        s = self.speed[k] * moving_s
        s0, s1 = s + min(self.radius[k], self.yield_distance[k]), s + self.yield_distance[k]
        start, _, first = self._point(k, s0)
        end, _, last = self._point(k, s1)
        laps = int((s1 % ends[-1] < s0 % ends[-1]) or (s1 - s0 >= ends[-1]))
        corners = [self.loops[k][i % len(ends) + 1] for i in range(first, last + laps * len(ends))]
        return np.array([start, *corners, end])

    def yielding(self, moving_s: np.ndarray, outline: np.ndarray) -> np.ndarray:
        """Which movers (K,) stop for a robot whose footprint is the polygon `outline` (P, 2, world
        frame): those with a yield distance whose way ahead, swept by their radius plus
        YIELD_MARGIN, the footprint meets — straight ahead, a robot within yield_distance +
        YIELD_MARGIN of the mover's circle. A robot beside or behind a mover does not stop it."""
        stop = np.zeros(len(self), bool)
        centre = outline.mean(axis=0)
        reach = float(np.hypot(*(outline - centre).T).max())
        edges_a, edges_b = outline, np.roll(outline, -1, axis=0)
        for k in np.flatnonzero(self.yield_distance > 0):
            position = self._point(k, self.speed[k] * moving_s[k])[0]
            sweep = self.radius[k] + YIELD_MARGIN
            if np.hypot(*(position - centre)) > reach + self.radius[k] + self.yield_distance[k] + sweep:
                continue                                      # far away: skip the exact tests
            way = self.way_ahead(k, moving_s[k])
            if point_segment_distance(centre, way[:-1], way[1:]).min() > reach + sweep:
                continue                                      # the circle around the footprint is clear
            gap = segment_distance(edges_a[:, None], edges_b[:, None], way[None, :-1], way[None, 1:]).min()
            stop[k] = gap <= sweep or bool(points_in_polygons(way, outline[None]).any())
        return stop


# ---------------------------------------------------------------- the world

@dataclass(frozen=True)
class Robot:
    start: np.ndarray                  # (3,) x, y, yaw
    drive: str = "mecanum"
    footprint: np.ndarray = field(default_factory=lambda: DEFAULT_FOOTPRINT.copy())  # (P, 2), CCW


@dataclass(frozen=True, eq=False)
class World:
    name: str
    origin: tuple[float, float]        # world coordinates of the bounds' lower-left corner
    bounds: tuple[float, float]        # width, height (m)
    solids: np.ndarray                 # (K, 4, 2) convex quads, counter-clockwise
    circles: np.ndarray                # (M, 3) static cylinders x, y, r
    movers: Movers
    robot: Robot
    grid: OccupancyGrid | None = None  # static map (`map:` key)
    goals: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    source: str = ""                   # the file it came from
    people: PeopleSpec = PeopleSpec()  # who walks the world (sim/people, docs/people.md)

    @cached_property
    def segments(self) -> np.ndarray:
        """Edges of every solid as (N, 4) x1, y1, x2, y2."""
        return np.concatenate([self.solids, np.roll(self.solids, -1, axis=1)], axis=2).reshape(-1, 4)

    @property
    def extent(self) -> tuple[float, float, float, float]:
        """xmin, ymin, xmax, ymax of the bounds."""
        return self.origin[0], self.origin[1], self.origin[0] + self.bounds[0], self.origin[1] + self.bounds[1]

    @cached_property
    def grid_occupied(self) -> np.ndarray | None:
        """The map cells that are obstacles (bool, rows bottom-up), or None without a map."""
        return None if self.grid is None else self.grid.data > GRID_OBSTACLE

    @cached_property
    def _grid_nearest(self) -> tuple[np.ndarray, np.ndarray] | None:
        """For every map cell, the (row, col) of the nearest obstacle cell (None: no obstacle cells)."""
        occupied = self.grid_occupied
        if occupied is None or not occupied.any():
            return None
        # imported here: only worlds drawn on a map need it, and scipy.ndimage takes most of a second to
        # import in every service that reads a world (sim, lidar, costmap, tracker)
        from scipy import ndimage

        _, (rows, cols) = ndimage.distance_transform_edt(~occupied, return_indices=True)
        return rows.astype(np.int32), cols.astype(np.int32)

    def _grid_distance(self, points: np.ndarray) -> np.ndarray:
        """Distance from points (..., 2) to the map's obstacle cells, exact to within one cell."""
        nearest = self._grid_nearest
        if nearest is None:
            return np.full(points.shape[:-1], np.inf)
        info = self.grid.info
        u, v = grid_coords(info, points[..., 0], points[..., 1])
        row = np.clip(np.floor(v).astype(np.int64), 0, info.height - 1)
        col = np.clip(np.floor(u).astype(np.int64), 0, info.width - 1)
        nr, nc = nearest[0][row, col], nearest[1][row, col]
        gap_u = np.maximum(np.abs(u - (nc + 0.5)) - 0.5, 0.0)
        gap_v = np.maximum(np.abs(v - (nr + 0.5)) - 0.5, 0.0)
        return np.hypot(gap_u, gap_v) * info.resolution

    def outside(self, points: np.ndarray) -> np.ndarray:
        xmin, ymin, xmax, ymax = self.extent
        return ((points[..., 0] < xmin) | (points[..., 0] > xmax) |
                (points[..., 1] < ymin) | (points[..., 1] > ymax))

    def distance(self, points, extra_circles: np.ndarray | None = None) -> np.ndarray:
        """Distance (m) from points (..., 2) to the nearest static obstacle; 0 inside one or outside
        the bounds. `extra_circles` (K, 3) adds obstacles such as the movers at some time."""
        points = np.asarray(points, np.float64)
        flat = points.reshape(-1, 2)
        best = np.full(len(flat), np.inf)
        for chunk in range(0, len(flat), 4096):  # bounds the (points × segments) temporaries
            p = flat[chunk:chunk + 4096]
            seg = self.segments
            if len(seg):
                d = point_segment_distance(p[:, None, :], seg[None, :, 0:2], seg[None, :, 2:4]).min(axis=1)
                d[points_in_polygons(p, self.solids).any(axis=1)] = 0.0
                best[chunk:chunk + 4096] = d
        circles = self.obstacle_circles(extra_circles)
        if len(circles):
            d = np.hypot(flat[:, None, 0] - circles[None, :, 0], flat[:, None, 1] - circles[None, :, 1])
            best = np.minimum(best, np.maximum(d - circles[None, :, 2], 0.0).min(axis=1))
        best = np.minimum(best, self._grid_distance(flat))
        best[self.outside(flat)] = 0.0
        return best.reshape(points.shape[:-1])

    def obstacle_circles(self, extra: np.ndarray | None = None) -> np.ndarray:
        """Static circles (M, 3), plus `extra` ones such as the movers at some time."""
        return self.circles if extra is None or len(extra) == 0 else np.vstack([self.circles, extra])

    @cached_property
    def _footprint_samples(self) -> tuple[np.ndarray, np.ndarray]:
        """Points on the footprint's outline and inside it, dense enough to catch every map cell."""
        if self.grid is None:
            return np.zeros((0, 2)), np.zeros((0, 2))
        step = self.grid.info.resolution / 2
        poly = self.robot.footprint
        outline = []
        for a, b in zip(poly, np.roll(poly, -1, axis=0)):
            n = max(1, math.ceil(np.hypot(*(b - a)) / step))
            outline.append(a + (b - a) * (np.arange(n)[:, None] / n))
        lo, hi = poly.min(axis=0), poly.max(axis=0)
        xs, ys = np.arange(lo[0], hi[0], step), np.arange(lo[1], hi[1], step)
        inner = np.stack(np.meshgrid(xs, ys), axis=-1).reshape(-1, 2)
        inner = inner[points_in_polygons(inner, poly[None])[:, 0]]
        return np.vstack(outline), inner

    def footprint_clearance(self, poses, extra_circles: np.ndarray | None = None) -> np.ndarray:
        """Distance (m) between the robot's footprint at poses (Q, 3) (or one pose) and the nearest
        static obstacle; 0 when they overlap. Exact for shapes; within one cell for a map."""
        poses = np.asarray(poses, np.float64)
        single = poses.ndim == 1
        poses = np.atleast_2d(poses)
        poly = transform_points(self.robot.footprint, poses)            # (Q, P, 2)
        a, b = poly, np.roll(poly, -1, axis=1)
        best = np.full(len(poses), np.inf)
        seg = self.segments
        if len(seg):
            d = segment_distance(a[:, :, None, :], b[:, :, None, :], seg[None, None, :, 0:2], seg[None, None, :, 2:4])
            best = d.min(axis=(1, 2))
            corners = self.solids.reshape(-1, 2)                         # a solid inside the footprint
            best[points_in_polygons(corners[None], poly[:, None])[..., 0].any(axis=1)] = 0.0
        circles = _may_be_nearest(self.obstacle_circles(extra_circles), poses, poly, self.robot.footprint)
        if len(circles):
            centres = np.broadcast_to(circles[None, None, :, :2], (len(poses), 1, len(circles), 2))
            d = point_segment_distance(centres, a[:, :, None, :], b[:, :, None, :]) - circles[None, None, :, 2]
            d = np.maximum(d.min(axis=1), 0.0)                           # (Q, M)
            d[points_in_polygons(circles[None, :, :2], poly[:, None])[..., 0]] = 0.0
            best = np.minimum(best, d.min(axis=1))
        inside = self.distance(poly) == 0.0                               # footprint corner in an obstacle
        best[inside.any(axis=1)] = 0.0
        outline, inner = self._footprint_samples
        if len(outline):
            best = np.minimum(best, self._grid_distance(transform_points(outline, poses)).min(axis=1))
            if len(inner):
                covered = self._grid_distance(transform_points(inner, poses)) == 0.0
                best[covered.any(axis=1)] = 0.0
        return best[0] if single else best

    def rasterize(self, resolution: float) -> OccupancyGrid:
        """The true occupancy (100 occupied / 0 free; a map's unknown cells stay −1) of the static
        geometry on a grid aligned with the bounds' lower-left corner, with a margin that holds the
        outer walls. A cell is occupied when any shape overlaps its interior."""
        if not resolution > 0:
            raise ValueError(f"resolution must be positive, got {resolution}")
        margin = math.ceil(WALL_THICKNESS / resolution - _EPS)
        width = math.ceil(self.bounds[0] / resolution - _EPS) + 2 * margin
        height = math.ceil(self.bounds[1] / resolution - _EPS) + 2 * margin
        x0, y0 = self.origin[0] - margin * resolution, self.origin[1] - margin * resolution
        info = MapMetaData(resolution=resolution, width=width, height=height, origin=Pose2D(x0, y0, 0.0))
        data = np.zeros((height, width), np.int8)
        if self.grid is not None:
            xs, ys = cell_to_world(info, *np.indices((height, width)))
            row, col = world_to_cell(self.grid.info, xs, ys)
            inside = (row >= 0) & (row < self.grid.info.height) & (col >= 0) & (col < self.grid.info.width)
            src = self.grid.data[np.clip(row, 0, self.grid.info.height - 1), np.clip(col, 0, self.grid.info.width - 1)]
            data[inside] = np.where(src[inside] > GRID_OBSTACLE, 100, np.where(src[inside] < 0, -1, 0))
        half = resolution / 2
        for quad in self.solids:
            rows, cols, cx, cy = _cells_under(info, quad.min(axis=0), quad.max(axis=0))
            hit = np.ones(cx.shape, bool)
            for edge in (quad[1] - quad[0], quad[2] - quad[1]):       # separating axes of the quad
                n = np.array([-edge[1], edge[0]]) / np.hypot(*edge)
                proj = quad @ n
                centre, reach = cx * n[0] + cy * n[1], half * (abs(n[0]) + abs(n[1]))
                hit &= (centre - reach < proj.max() - _EPS) & (centre + reach > proj.min() + _EPS)
            data[rows[hit], cols[hit]] = 100
        for x, y, r in self.circles:
            rows, cols, cx, cy = _cells_under(info, (x - r, y - r), (x + r, y + r))
            gap = np.hypot(np.maximum(np.abs(cx - x) - half, 0), np.maximum(np.abs(cy - y) - half, 0))
            hit = gap < r - _EPS
            data[rows[hit], cols[hit]] = 100
        return OccupancyGrid(header=Header(frame_id="map"), info=info, data=data)


def _may_be_nearest(circles: np.ndarray, poses: np.ndarray, outlines: np.ndarray, footprint: np.ndarray) -> np.ndarray:
    """The circles that can be the nearest to some footprint (outlines (Q, P, 2) at poses (Q, 3)):
    those whose distance from the pose's origin, less the footprint's reach, is not above the
    distance from a corner of that footprint to the nearest circle (a clutter of hundreds of
    cylinders has a handful near the robot)."""
    if len(circles) == 0:
        return circles
    reach = float(np.hypot(*footprint.T).max())
    radius = circles[None, :, 2]
    lower = np.hypot(poses[:, None, 0] - circles[None, :, 0], poses[:, None, 1] - circles[None, :, 1]) - reach - radius
    upper = np.hypot(outlines[:, :1, 0] - circles[None, :, 0], outlines[:, :1, 1] - circles[None, :, 1]) - radius
    return circles[(lower <= upper.min(axis=1, keepdims=True)).any(axis=0)]


def _cells_under(info: MapMetaData, lo, hi):
    """Rows, cols and centres of the cells of an axis-aligned grid whose interiors meet the box lo..hi."""
    res = info.resolution
    c0 = max(0, math.floor((lo[0] - info.origin.x) / res + _EPS))
    c1 = min(info.width, math.ceil((hi[0] - info.origin.x) / res - _EPS))
    r0 = max(0, math.floor((lo[1] - info.origin.y) / res + _EPS))
    r1 = min(info.height, math.ceil((hi[1] - info.origin.y) / res - _EPS))
    rows, cols = np.mgrid[r0:max(r0, r1), c0:max(c0, c1)]
    cx, cy = cell_to_world(info, rows, cols)
    return rows, cols, cx, cy


# ---------------------------------------------------------------- loading

class _Keys:
    """Reads typed values out of the parsed YAML; every failure names the file and key path."""

    def __init__(self, source: str):
        self.source = source

    def fail(self, where: str, message: str):
        raise WorldError(f"{self.source}: {where}: {message}")

    def number(self, value, where: str, *, positive: bool = False, nonnegative: bool = False) -> float:
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
            self.fail(where, f"expected a number, got {value!r}")
        if positive and value <= 0:
            self.fail(where, f"expected a positive number, got {value!r}")
        if nonnegative and value < 0:
            self.fail(where, f"expected a number ≥ 0, got {value!r}")
        return float(value)

    def numbers(self, value, where: str, count: int, what: str, *, positive: bool = False) -> np.ndarray:
        ok = (isinstance(value, list) and len(value) == count and
              all(isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) for v in value))
        if not ok or (positive and min(value) <= 0):
            self.fail(where, f"expected {what}, got {value!r}")
        return np.array(value, np.float64)

    def items(self, value, where: str) -> list:
        if value is None:
            return []
        if not isinstance(value, list):
            self.fail(where, f"expected a list, got {value!r}")
        return value

    def mapping(self, value, where: str, required: tuple[str, ...] = (), optional: tuple[str, ...] = ()) -> dict:
        """A mapping with the required keys and no key beyond required and optional: a misspelt key
        would otherwise load a different world without a word."""
        if not isinstance(value, dict):
            self.fail(where, f"expected a mapping, got {value!r}")
        problem = unknown_names(value, (*required, *optional))
        if problem:
            self.fail(where or "top level", problem)
        for key in required:
            if key not in value:
                self.fail(f"{where}.{key}", "missing")
        return value

    def points(self, value, where: str, minimum: int) -> np.ndarray:
        rows = self.items(value, where)
        if len(rows) < minimum:
            self.fail(where, f"expected at least {minimum} points [x, y], got {len(rows)}")
        return np.array([self.numbers(p, f"{where}[{i}]", 2, "a point [x, y]") for i, p in enumerate(rows)])


def _load_map_key(keys: _Keys, spec, world_file: Path) -> OccupancyGrid:
    spec = keys.mapping(spec, "map", required=("yaml",), optional=("relative_to",))
    if not isinstance(spec["yaml"], str) or not spec["yaml"]:
        keys.fail("map.yaml", f"expected a path to a map_server YAML file, got {spec['yaml']!r}")
    relative_to = spec.get("relative_to", "world")
    if relative_to == "world":
        path = world_file.parent / spec["yaml"]
    elif relative_to == "data":
        base = shared_data_dir(world_file)
        if base is None:
            keys.fail("map.yaml", f"{spec['yaml']} is in the shared data folder, but {world_file} is not "
                                  f"inside a checkout: set {DATA_ENV} to the folder holding it")
        path = base / spec["yaml"]
        if not path.is_file():
            keys.fail("map.yaml", f"{path} does not exist (the shared data folder is ../shared/data "
                                  f"beside the checkout, or ${DATA_ENV})")
    else:
        keys.fail("map.relative_to", f"expected 'world' or 'data', got {relative_to!r}")
    try:
        return load_map(path)
    except MapError as exc:
        keys.fail("map.yaml", str(exc))


def _grid_extent(grid: OccupancyGrid) -> tuple[tuple[float, float], tuple[float, float]]:
    """Origin and size of the axis-aligned box around a (possibly rotated) map."""
    info = grid.info
    corners = np.array([[0, 0], [info.height, 0], [0, info.width], [info.height, info.width]], np.float64)
    xs, ys = cell_to_world(info, corners[:, 0] - 0.5, corners[:, 1] - 0.5)
    return (float(xs.min()), float(ys.min())), (float(xs.max() - xs.min()), float(ys.max() - ys.min()))


MOVER_KEYS = ("speed", "path", "keyframes", "loop", "interpolation", "yield_distance")


def _keyframes(keys: _Keys, mover: dict, where: str, loop: bool) -> Keyframes:
    """A keyframe mover's track: at least 2 keyframes [t, x, y], times increasing from 0."""
    for key in ("speed", "path"):
        if key in mover:
            keys.fail(f"{where}.{key}", "a mover has speed and path, or keyframes, not both")
    if "yield_distance" in mover:
        keys.fail(f"{where}.yield_distance", "a mover on keyframes never yields: where it is depends on the time alone")
    interpolation = mover.get("interpolation", "linear")
    if interpolation not in INTERPOLATIONS:
        keys.fail(f"{where}.interpolation", f"expected {' or '.join(INTERPOLATIONS)}, got {interpolation!r}")
    rows = keys.items(mover["keyframes"], f"{where}.keyframes")
    if len(rows) < 2:
        keys.fail(f"{where}.keyframes", f"expected at least 2 keyframes [t, x, y], got {len(rows)}")
    frames = np.array([keys.numbers(row, f"{where}.keyframes[{j}]", 3, "a keyframe [t, x, y] (three numbers)")
                       for j, row in enumerate(rows)])
    if frames[0, 0] != 0.0:
        keys.fail(f"{where}.keyframes[0]", f"the first keyframe's time must be 0, got {frames[0, 0]:g}")
    late = np.flatnonzero(np.diff(frames[:, 0]) <= 0)
    if len(late):
        j = int(late[0]) + 1
        keys.fail(f"{where}.keyframes[{j}]", f"time {frames[j, 0]:g} does not come after {frames[j - 1, 0]:g} "
                                             "(times must increase)")
    return Keyframes(frames[:, 0].copy(), frames[:, 1:].copy(), loop, interpolation)


# `generated` says how a generated world was made (kind, seed: docs/scenarios.md); the loader reads
# nothing from it
WORLD_KEYS = ("name", "bounds", "origin", "map", "walls", "boxes", "circles", "movers", "people", "robot", "goals",
              "generated")


def load_world(path: str | Path) -> World:
    """Read and validate a world file (a YAML world, or a BARN `.world` file: sim/barn_world.py); raises
    WorldError naming the file and key on any problem."""
    path = Path(path)
    if path.suffix == BARN_SUFFIX:
        try:
            doc = barn_world_doc(path)
        except BarnWorldError as exc:
            raise WorldError(str(exc)) from None
    else:
        doc = read_yaml(path, WorldError)
    return world_from_mapping(doc, path)


def world_from_mapping(doc: dict, path: str | Path) -> World:
    """Validate a world file's mapping (a map's relative path resolves against `path`'s folder);
    WorldError naming `path` and the key on any problem."""
    path = Path(path)
    keys = _Keys(str(path))
    keys.mapping(doc, "", optional=WORLD_KEYS)

    name = doc.get("name", path.stem)
    if not isinstance(name, str) or not name:
        keys.fail("name", f"expected a non-empty string, got {name!r}")

    grid = _load_map_key(keys, doc["map"], path) if doc.get("map") is not None else None
    if "bounds" in doc:
        bounds = tuple(keys.numbers(doc["bounds"], "bounds", 2, "[width, height] (two positive numbers, m)",
                                    positive=True))
        origin = tuple(keys.numbers(doc.get("origin", [0.0, 0.0]), "origin", 2, "[x, y] (two numbers, m)"))
    elif grid is not None:
        origin, bounds = _grid_extent(grid)
        if "origin" in doc:
            keys.fail("origin", "only allowed together with bounds (a map's extent sets both)")
    else:
        keys.fail("bounds", "missing (give [width, height] in m, or a map)")

    solids = []
    for i, wall in enumerate(keys.items(doc.get("walls"), "walls")):
        x1, y1, x2, y2 = keys.numbers(wall, f"walls[{i}]", 4, "[x1, y1, x2, y2] (four numbers, m)")
        if x1 == x2 and y1 == y2:
            keys.fail(f"walls[{i}]", "has zero length")
        solids.append(wall_rectangle(x1, y1, x2, y2))
    for i, box in enumerate(keys.items(doc.get("boxes"), "boxes")):
        box = keys.mapping(box, f"boxes[{i}]", required=("center", "size"), optional=("yaw",))
        center = keys.numbers(box["center"], f"boxes[{i}].center", 2, "a point [x, y]")
        size = keys.numbers(box["size"], f"boxes[{i}].size", 2, "two positive numbers", positive=True)
        yaw = keys.number(box.get("yaw", 0.0), f"boxes[{i}].yaw")
        solids.append(rectangle(center, size, yaw))
    x0, y0 = origin
    w, h, t = bounds[0], bounds[1], WALL_THICKNESS
    solids += [rectangle((x0 + w / 2, y0 - t / 2), (w + 2 * t, t)),          # outer walls, inner
               rectangle((x0 + w / 2, y0 + h + t / 2), (w + 2 * t, t)),      # faces on the bounds
               rectangle((x0 - t / 2, y0 + h / 2), (t, h)),
               rectangle((x0 + w + t / 2, y0 + h / 2), (t, h))]

    circles = []
    for i, circle in enumerate(keys.items(doc.get("circles"), "circles")):
        circle = keys.mapping(circle, f"circles[{i}]", required=("center", "radius"))
        center = keys.numbers(circle["center"], f"circles[{i}].center", 2, "a point [x, y]")
        circles.append([*center, keys.number(circle["radius"], f"circles[{i}].radius", positive=True)])

    radii, speeds, loops, yields, tracks = [], [], [], [], []
    for i, mover in enumerate(keys.items(doc.get("movers"), "movers")):
        where = f"movers[{i}]"
        mover = keys.mapping(mover, where, required=("radius",), optional=MOVER_KEYS)
        radii.append(keys.number(mover["radius"], f"{where}.radius", positive=True))
        loop = mover.get("loop", True)
        if not isinstance(loop, bool):
            keys.fail(f"{where}.loop", f"expected true or false, got {loop!r}")
        if "keyframes" in mover:
            track = _keyframes(keys, mover, where, loop)
            speeds.append(0.0)
            yields.append(0.0)
            loops.append(track.trace())
            tracks.append(track)
            continue
        for key in ("speed", "path"):
            if key not in mover:
                keys.fail(f"{where}.{key}", "missing (a mover needs speed and path, or keyframes)")
        if "interpolation" in mover:
            keys.fail(f"{where}.interpolation", "only for a mover on keyframes")
        speeds.append(keys.number(mover["speed"], f"{where}.speed", nonnegative=True))
        yield_distance = mover.get("yield_distance")
        yields.append(0.0 if yield_distance is None else
                      keys.number(yield_distance, f"{where}.yield_distance", positive=True))
        path_points = keys.points(mover["path"], f"{where}.path", 2)
        closed = np.vstack([path_points, path_points[:1]]) if loop else np.vstack([path_points, path_points[-2::-1]])
        steps = np.diff(closed, axis=0)
        closed = closed[np.r_[True, np.hypot(steps[:, 0], steps[:, 1]) > 0]]  # repeated points
        if len(closed) < 2:
            keys.fail(f"{where}.path", "all points are the same: a mover needs a path of some length")
        loops.append(closed)
        tracks.append(None)

    if "robot" not in doc:
        keys.fail("robot", "missing (give at least start: [x, y, yaw])")
    robot_doc = keys.mapping(doc["robot"], "robot", required=("start",), optional=("drive", "footprint"))
    start = keys.numbers(robot_doc["start"], "robot.start", 3, "[x, y, yaw] (three numbers)")
    drive = robot_doc.get("drive", "mecanum")
    if drive not in DRIVES:
        keys.fail("robot.drive", f"expected one of {' | '.join(DRIVES)}, got {drive!r}")
    footprint = DEFAULT_FOOTPRINT.copy()
    if robot_doc.get("footprint") is not None:
        footprint = keys.points(robot_doc["footprint"], "robot.footprint", 3)
        area = polygon_area(footprint)
        if abs(area) < 1e-6:
            keys.fail("robot.footprint", "encloses no area")
        footprint = footprint if area > 0 else footprint[::-1].copy()

    goals = [keys.numbers(g, f"goals[{i}]", 3, "[x, y, yaw] (three numbers)")
             for i, g in enumerate(keys.items(doc.get("goals"), "goals"))]

    people = people_from_mapping(doc["people"], keys) if doc.get("people") is not None else PeopleSpec()

    world = World(name=name, origin=(float(x0), float(y0)), bounds=(float(w), float(h)),
                  solids=np.array(solids).reshape(-1, 4, 2), circles=np.array(circles).reshape(-1, 3),
                  movers=Movers(np.array(radii), np.array(speeds), tuple(loops), np.array(yields), tuple(tracks)),
                  robot=Robot(start=start, drive=drive, footprint=footprint), grid=grid,
                  goals=np.array(goals).reshape(-1, 3), source=str(path), people=people)
    for where, point in [("robot.start", start), *((f"goals[{i}]", g) for i, g in enumerate(goals))]:
        if world.outside(point[:2]):
            keys.fail(where, f"({point[0]}, {point[1]}) lies outside the bounds {world.extent}")
    return world


WORLDS_DIR = Path(__file__).resolve().parent / "worlds"


def world_path(name_or_path: str | Path) -> Path:
    """A shipped world by name ('room') or any world file by path."""
    candidate = Path(name_or_path)
    if candidate.suffix in (".yaml", ".yml", BARN_SUFFIX) or candidate.exists():
        return candidate
    return WORLDS_DIR / f"{name_or_path}.yaml"


def shipped_worlds() -> list[str]:
    return sorted(p.stem for p in WORLDS_DIR.glob("*.yaml"))
