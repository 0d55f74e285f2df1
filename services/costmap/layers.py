"""Costmap layers after ROS costmap_2d: static, obstacle, inflation, keepout (+ speed limits).

Cost values are ROS's: 0 free, 1..252 graded, 253 inscribed, 254 lethal, 255 unknown
(NO_INFORMATION). Each layer but inflation keeps its own uint8 grid in the costmap's geometry
and, per update, reports the box of cells it changed (row0, col0, row1, col1; half-open) so the
costmap recombines and re-inflates only that window.

Inflation is ROS's InflationLayer::computeCost: 254 on a lethal cell, 253 within the inscribed
radius, else (unsigned char)(252·exp(−cost_scaling_factor·(d − inscribed_radius))), for cells at
most ceil(inflation_radius / resolution) cells from a lethal cell (d in metres, measured between
cell centres). ROS finds the nearest lethal cell by a wavefront that carries each cell's source
along; this module uses the exact Euclidean nearest lethal cell, which the wavefront approximates.
"""
from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass

import numpy as np
from numba import njit

from ...schemas.messages import LaserScan, MapMetaData, OccupancyGrid, Pose2D
from ...geometry.grid import cell_to_world, grid_coords, in_grid, world_to_cell
from ...geometry.footprint import cells_inside, transform
from ...geometry.frames import scan_points
from ...geometry.movers import TRACKED_POINT_MARGIN, Movers
from .params import InflationLayerParams, KeepoutLayerParams, ObstacleLayerParams, StaticLayerParams

FREE_SPACE, INSCRIBED_INFLATED_OBSTACLE, LETHAL_OBSTACLE, NO_INFORMATION = 0, 253, 254, 255
EDGE_MARGIN = 0.001      # m: ROS stops a clipped beam this far inside the far map edges

Box = tuple[int, int, int, int]   # row0, col0, row1, col1 (half-open); empty when row0 >= row1


def union(a: Box | None, b: Box | None) -> Box | None:
    if a is None or a[0] >= a[2] or a[1] >= a[3]:
        return b if b is not None and b[0] < b[2] and b[1] < b[3] else None
    if b is None or b[0] >= b[2] or b[1] >= b[3]:
        return a
    return min(a[0], b[0]), min(a[1], b[1]), max(a[2], b[2]), max(a[3], b[3])


def grow(box: Box, cells: int, shape: tuple[int, int]) -> Box:
    return (max(box[0] - cells, 0), max(box[1] - cells, 0),
            min(box[2] + cells, shape[0]), min(box[3] + cells, shape[1]))


def whole(info: MapMetaData) -> Box:
    return 0, 0, info.height, info.width


def same_geometry(a: MapMetaData, b: MapMetaData) -> bool:
    return (a.width, a.height, a.resolution, a.origin.x, a.origin.y, a.origin.theta) == \
           (b.width, b.height, b.resolution, b.origin.x, b.origin.y, b.origin.theta)


def resample(data: np.ndarray, src: MapMetaData, dst: MapMetaData, dst_in_src: Pose2D | None,
             outside) -> np.ndarray:
    """`data` (on grid src) at the centres of grid dst's cells, nearest cell; dst_in_src is the
    pose of dst's frame in src's frame (None: the same frame). Cells off src get `outside`."""
    if dst_in_src is None and same_geometry(src, dst):
        return data.copy()
    rows, cols = np.mgrid[0:dst.height, 0:dst.width]
    x, y = cell_to_world(dst, rows, cols)
    if dst_in_src is not None:
        c, s = math.cos(dst_in_src.theta), math.sin(dst_in_src.theta)
        x, y = dst_in_src.x + c * x - s * y, dst_in_src.y + s * x + c * y
    r, k = world_to_cell(src, x, y)
    inside = in_grid(src, r, k)
    out = np.full((dst.height, dst.width), outside, data.dtype)
    out[inside] = data[r[inside], k[inside]]
    return out


@dataclass(frozen=True)
class View:
    """What a layer sees of the costmap at an update."""
    info: MapMetaData                # the costmap's geometry in its global frame
    robot_pose: tuple[float, float, float] | None   # robot in the global frame, if known
    frame_in_map: Pose2D | None      # the global frame's pose in the map frame (None: same frame)


def combine_max(master: np.ndarray, layer: np.ndarray, box: Box) -> None:
    """ROS updateWithMax: a known layer cell raises the master cell (or replaces an unknown one)."""
    r0, c0, r1, c1 = box
    m, l = master[r0:r1, c0:c1], layer[r0:r1, c0:c1]
    take = (l != NO_INFORMATION) & ((m == NO_INFORMATION) | (m < l))
    m[take] = l[take]


def combine_overwrite(master: np.ndarray, layer: np.ndarray, box: Box) -> None:
    """ROS updateWithOverwrite: every known layer cell replaces the master cell."""
    r0, c0, r1, c1 = box
    m, l = master[r0:r1, c0:c1], layer[r0:r1, c0:c1]
    known = l != NO_INFORMATION
    m[known] = l[known]


def shift_grid(grid: np.ndarray, dr: int, dc: int, fill) -> None:
    """Move a grid's contents as its origin moves by (dr, dc) cells; uncovered cells get `fill`."""
    height, width = grid.shape
    if abs(dr) >= height or abs(dc) >= width:
        grid[:] = fill
        return
    src = grid[max(dr, 0):height + min(dr, 0), max(dc, 0):width + min(dc, 0)].copy()
    grid[:] = fill
    grid[max(-dr, 0):height + min(-dr, 0), max(-dc, 0):width + min(-dc, 0)] = src


# ---------------------------------------------------------------- static layer

def interpret_map(data: np.ndarray, params: StaticLayerParams) -> np.ndarray:
    """ROS StaticLayer::interpretValue over an OccupancyGrid's int8 data (compared as unsigned
    bytes, as ROS does, so -1 is 255)."""
    value = np.asarray(data).astype(np.int16) & 0xFF
    unknown = params.unknown_cost_value & 0xFF
    if params.trinary_costmap:
        out = np.full(value.shape, FREE_SPACE, np.uint8)
    else:
        scale = np.minimum(value, params.lethal_cost_threshold) / max(params.lethal_cost_threshold, 1)
        out = (scale * LETHAL_OBSTACLE).astype(np.uint8)
    out[value >= params.lethal_cost_threshold] = LETHAL_OBSTACLE
    out[value == unknown] = NO_INFORMATION if params.track_unknown_space else FREE_SPACE
    return out


class StaticLayer:
    """The map, interpreted into costs; overwrites the master (or raises it with use_maximum)."""

    def __init__(self, params: StaticLayerParams):
        self.params = params
        self.name = params.name
        self.map_info: MapMetaData | None = None
        self._map_costs: np.ndarray | None = None
        self.costs: np.ndarray | None = None   # in the costmap's geometry
        self._covered: np.ndarray | None = None
        self._sampled_for: tuple | None = None

    def set_map(self, grid: OccupancyGrid) -> None:
        self.map_info = grid.info
        self._map_costs = interpret_map(grid.data, self.params)
        self._sampled_for = None

    def resize(self, info: MapMetaData) -> None:
        self._sampled_for = None

    def shift(self, dr: int, dc: int) -> None:
        self._sampled_for = None

    def update_bounds(self, view: View) -> Box | None:
        if self._map_costs is None:
            return None
        key = (view.info.origin.x, view.info.origin.y, view.info.width, view.info.height, view.frame_in_map)
        if key == self._sampled_for:
            return None
        # the map frame is the costmap's global frame unless a transform into it is given
        sampled = resample(self._map_costs, self.map_info, view.info, view.frame_in_map, NO_INFORMATION)
        covered = resample(np.ones(self._map_costs.shape, bool), self.map_info, view.info, view.frame_in_map, False)
        self.costs, self._covered = sampled, None if covered.all() else covered
        self._sampled_for = key
        return whole(view.info)

    def update_costs(self, master: np.ndarray, box: Box) -> None:
        if self.costs is None:
            return
        if self.params.use_maximum:
            combine_max(master, self.costs, box)
            return
        r0, c0, r1, c1 = box   # ROS updateWithTrueOverwrite: unknown map cells overwrite too
        if self._covered is None:
            master[r0:r1, c0:c1] = self.costs[r0:r1, c0:c1]
        else:
            covered = self._covered[r0:r1, c0:c1]
            master[r0:r1, c0:c1][covered] = self.costs[r0:r1, c0:c1][covered]


# ---------------------------------------------------------------- obstacle layer

@njit(cache=True)
def _raytrace(grid, u0, v0, us, vs, max_cells, edge, value):
    """ROS ObstacleLayer::raytraceFreespace in grid coordinates: clip each beam to the grid, then
    Bresenham from the sensor's cell for at most max_cells steps along the dominant axis, the end
    cell included. Returns the box of cells whose value changed."""
    height, width = grid.shape
    x0, y0 = int(math.floor(u0)), int(math.floor(v0))
    r0, c0, r1, c1 = height, width, 0, 0
    for k in range(us.shape[0]):
        wu, wv = us[k], vs[k]
        a, b = wu - u0, wv - v0
        if wu < 0.0:
            t = -u0 / a
            wu, wv = 0.0, v0 + b * t
        if wv < 0.0:
            t = -v0 / b
            wu, wv = u0 + a * t, 0.0
        if wu > width:
            t = (width - u0) / a
            wu, wv = width - edge, v0 + b * t
        if wv > height:
            t = (height - v0) / b
            wu, wv = u0 + a * t, height - edge
        if not (0.0 <= wu < width and 0.0 <= wv < height):
            continue
        x1, y1 = int(wu), int(wv)
        dx, dy = x1 - x0, y1 - y0
        adx, ady = abs(dx), abs(dy)
        sx = 1 if dx > 0 else (-1 if dx < 0 else 0)
        sy = 1 if dy > 0 else (-1 if dy < 0 else 0)
        dist = math.hypot(dx, dy)
        scale = 1.0 if dist == 0.0 else min(1.0, max_cells / dist)
        if adx >= ady:
            steps, da, db, error = min(int(scale * adx), adx), adx, ady, adx // 2
        else:
            steps, da, db, error = min(int(scale * ady), ady), ady, adx, ady // 2
        x, y = x0, y0
        for i in range(steps + 1):
            if grid[y, x] != value:
                grid[y, x] = value
                r0, c0, r1, c1 = min(r0, y), min(c0, x), max(r1, y + 1), max(c1, x + 1)
            if i == steps:
                break
            error += db
            if adx >= ady:
                x += sx
                if error >= da:
                    y += sy
                    error -= da
            else:
                y += sy
                if error >= da:
                    x += sx
                    error -= da
    return r0, c0, r1, c1


@dataclass(frozen=True)
class Observation:
    """One scan's points in the costmap's global frame, with where they came from."""
    source: str
    stamp_ns: int
    origin: tuple[float, float]      # sensor position in the global frame
    points: np.ndarray               # (N, 2) endpoints, m


class ObstacleLayer:
    """Marks scan hits nearer than obstacle_range as lethal and clears each beam's cells out to
    raytrace_range, per source as its marking / clearing flags say; clearing runs first (all
    sources), then marking, then the footprint is cleared, as in ROS — but the robot's own
    footprint (`body`, without footprint_padding), where nothing else can be: ROS clears the padded
    one, which erased an obstacle within the padding, and a footprint check of the padded
    footprint then found it clear (BARN world 7: the Jackal, padded by 0.1 m, drove into a
    cylinder 3.5 cm ahead of its bumper). With skip_tracked, a hit within TRACKED_POINT_MARGIN of
    a tracked mover (where its track puts it at the scan's stamp) is not marked: marked where it
    stood, a cylinder walking past closed the way behind it for the rollouts and, beside the robot,
    walled it in while it pushed (DynaBARN easy-38); the local planner meets the tracks where they
    will be. Its beams still clear."""

    def __init__(self, params: ObstacleLayerParams, track_unknown_space: bool, body: np.ndarray):
        self.params = params
        self.name = params.name
        tracking = params.track_unknown_space if params.track_unknown_space is not None else track_unknown_space
        self.default = NO_INFORMATION if tracking else FREE_SPACE
        self.body = body
        self.sources = {s.name: s for s in params.observation_sources}
        self._buffers: dict[str, deque[Observation]] = {name: deque() for name in self.sources}
        self.costs: np.ndarray | None = None
        self._movers: tuple[Movers, int] | None = None    # the moving tracks and the instant they are at (ns)

    def set_movers(self, movers: Movers | None, stamp_ns: int) -> None:
        """The tracks at stamp_ns in the costmap's frame, for skip_tracked (None: none); only those
        moving at skip_tracked_min_speed or faster are kept."""
        self._movers = None if movers is None else (movers.moving_at_least(self.params.skip_tracked_min_speed), stamp_ns)

    def resize(self, info: MapMetaData) -> None:
        self.costs = np.full((info.height, info.width), self.default, np.uint8)

    def shift(self, dr: int, dc: int) -> None:
        shift_grid(self.costs, dr, dc, self.default)

    def reset(self) -> None:
        """Forget everything seen (ROS: clear costmaps)."""
        self.costs[:] = self.default
        for buffer in self._buffers.values():
            buffer.clear()

    def add_scan(self, source: str, scan: LaserScan, sensor_pose) -> None:
        """Buffer a scan of `source` taken from sensor_pose (x, y, yaw in the costmap's frame)."""
        if source not in self.sources:
            raise KeyError(f"{self.name}: no observation source {source!r}; known: {sorted(self.sources)}")
        spec = self.sources[source]
        points = scan_points(scan, sensor_pose, spec.inf_is_valid)
        self._buffers[source].append(Observation(source, scan.header.stamp_ns, (float(sensor_pose[0]),
                                                 float(sensor_pose[1])), points))

    def _current(self) -> list[Observation]:
        """ROS ObservationBuffer: persistence 0 keeps the latest scan of a source, else those at
        most observation_persistence older than the latest."""
        out = []
        for name, buffer in self._buffers.items():
            keep_ns = round(self.sources[name].observation_persistence * 1e9)
            while len(buffer) > 1 and (keep_ns == 0 or buffer[0].stamp_ns < buffer[-1].stamp_ns - keep_ns):
                buffer.popleft()
            out.extend(buffer)
        return out

    def update_bounds(self, view: View) -> Box | None:
        info, box = view.info, None
        observations = self._current()
        for obs in observations:
            spec = self.sources[obs.source]
            if not spec.clearing:
                continue
            u0, v0 = (float(t) for t in grid_coords(info, *obs.origin))
            if not (0.0 <= u0 < info.width and 0.0 <= v0 < info.height):
                continue   # ROS: a sensor off the map cannot raytrace
            us, vs = grid_coords(info, obs.points[:, 0], obs.points[:, 1])
            max_cells = float(max(0, math.ceil(spec.raytrace_range / info.resolution)))   # float: as warm_up's
            changed = _raytrace(self.costs, u0, v0, np.ascontiguousarray(us), np.ascontiguousarray(vs),
                                max_cells, EDGE_MARGIN / info.resolution, FREE_SPACE)
            box = union(box, changed)
        for obs in observations:
            spec = self.sources[obs.source]
            if not spec.marking:
                continue
            d2 = ((obs.points - np.asarray(obs.origin)) ** 2).sum(axis=1)
            near = obs.points[d2 < spec.obstacle_range ** 2]
            if self.params.skip_tracked and self._movers is not None:
                moving, stamp_ns = self._movers
                near = near[~moving.on_movers(near, TRACKED_POINT_MARGIN, (obs.stamp_ns - stamp_ns) / 1e9)]
            box = union(box, self._set(info, *world_to_cell(info, near[:, 0], near[:, 1]), LETHAL_OBSTACLE))
        if self.params.footprint_clearing_enabled and view.robot_pose is not None:
            rows, cols = cells_inside(info, transform(self.body, view.robot_pose))
            box = union(box, self._set(info, rows, cols, FREE_SPACE))
        return box

    def _set(self, info: MapMetaData, rows: np.ndarray, cols: np.ndarray, value: int) -> Box | None:
        inside = in_grid(info, rows, cols)
        rows, cols = rows[inside], cols[inside]
        differ = self.costs[rows, cols] != value
        rows, cols = rows[differ], cols[differ]
        if rows.size == 0:
            return None
        self.costs[rows, cols] = value
        return int(rows.min()), int(cols.min()), int(rows.max()) + 1, int(cols.max()) + 1

    def update_costs(self, master: np.ndarray, box: Box) -> None:
        (combine_max if self.params.combination_method == 1 else combine_overwrite)(master, self.costs, box)


# ---------------------------------------------------------------- inflation layer

def inflation_cost(distance_m: float, inscribed_radius: float, cost_scaling_factor: float) -> int:
    """ROS InflationLayer::computeCost for a distance in metres (0 means on the obstacle)."""
    if distance_m == 0:
        return LETHAL_OBSTACLE
    if distance_m <= inscribed_radius:
        return INSCRIBED_INFLATED_OBSTACLE
    factor = math.exp(-1.0 * cost_scaling_factor * (distance_m - inscribed_radius))
    return int((INSCRIBED_INFLATED_OBSTACLE - 1) * factor)


@njit(cache=True)
def _inflate(composed, master, r0, c0, r1, c1, radius, dr, dc, d2, lut, inflate_unknown):
    """master[r0:r1, c0:c1] = composed there, raised by the inflation of every lethal cell within
    `radius` cells (offsets dr/dc with squared lengths d2, nearest first is not required)."""
    height, width = composed.shape
    h, w = r1 - r0, c1 - c0
    big = radius * radius + 1
    best = np.full((h, w), big, np.int64)
    for r in range(max(r0 - radius, 0), min(r1 + radius, height)):
        for c in range(max(c0 - radius, 0), min(c1 + radius, width)):
            if composed[r, c] != 254:
                continue
            # a lethal cell whose four neighbours are lethal (or off the grid) is never the
            # nearest lethal cell of a free cell: a neighbour towards that cell is nearer
            if ((r == 0 or composed[r - 1, c] == 254) and (r == height - 1 or composed[r + 1, c] == 254)
                    and (c == 0 or composed[r, c - 1] == 254) and (c == width - 1 or composed[r, c + 1] == 254)):
                if r0 <= r < r1 and c0 <= c < c1:
                    best[r - r0, c - c0] = 0
                continue
            for k in range(dr.shape[0]):
                rr, cc = r + dr[k] - r0, c + dc[k] - c0
                if 0 <= rr < h and 0 <= cc < w and d2[k] < best[rr, cc]:
                    best[rr, cc] = d2[k]
    for i in range(h):
        for j in range(w):
            old = composed[r0 + i, c0 + j]
            cost = lut[best[i, j]] if best[i, j] < big else 0
            if old == 255 and (cost > 0 if inflate_unknown else cost >= 253):
                master[r0 + i, c0 + j] = cost
            else:
                master[r0 + i, c0 + j] = max(old, cost)


class InflationLayer:
    """Inflates every lethal cell of the composed master out to inflation_radius."""

    def __init__(self, params: InflationLayerParams, inscribed_radius: float, resolution: float):
        self.params = params
        self.name = params.name
        self.inscribed_radius = inscribed_radius
        self.cell_radius = int(max(0.0, math.ceil(params.inflation_radius / resolution)))  # ROS cellDistance
        n = self.cell_radius
        dr, dc = np.mgrid[-n:n + 1, -n:n + 1]
        d2 = dr * dr + dc * dc
        disc = d2 <= n * n
        self._dr, self._dc, self._d2 = dr[disc].astype(np.int64), dc[disc].astype(np.int64), d2[disc].astype(np.int64)
        self.lut = np.array([inflation_cost(math.sqrt(k) * resolution, inscribed_radius, params.cost_scaling_factor)
                             for k in range(n * n + 1)], np.uint8)

    def inflate(self, composed: np.ndarray, master: np.ndarray, box: Box) -> None:
        r0, c0, r1, c1 = box
        if self.cell_radius == 0:   # ROS: no inflation at all (not even 253)
            master[r0:r1, c0:c1] = composed[r0:r1, c0:c1]
            return
        _inflate(composed, master, r0, c0, r1, c1, self.cell_radius, self._dr, self._dc, self._d2, self.lut,
                 self.params.inflate_unknown)


# ---------------------------------------------------------------- keepout layer

def speed_limits(mask: np.ndarray, params: KeepoutLayerParams) -> np.ndarray:
    """Per-cell speed limit from speed-mask values (inf: no limit), after Nav2's speed filter."""
    values = np.asarray(mask, np.float64)
    limits = params.speed_limit_base + params.speed_limit_multiplier * values
    return np.where(values > 0, limits, np.inf).astype(np.float32)


class KeepoutLayer:
    """Lethal cells where the keepout mask is occupied; a speed-limit map alongside the costs.
    Both masks live in the map frame and are resampled into the costmap's geometry."""

    def __init__(self, params: KeepoutLayerParams, keepout: OccupancyGrid | None = None,
                 speed: OccupancyGrid | None = None):
        self.params = params
        self.name = params.name
        self.keepout = keepout
        self.speed = speed
        self.costs: np.ndarray | None = None
        self.speed_limits: np.ndarray | None = None   # m/s or percent; inf = no limit
        self._sampled_for: tuple | None = None

    def set_masks(self, keepout: OccupancyGrid | None, speed: OccupancyGrid | None) -> None:
        self.keepout, self.speed, self._sampled_for = keepout, speed, None

    def resize(self, info: MapMetaData) -> None:
        self._sampled_for = None

    def shift(self, dr: int, dc: int) -> None:
        self._sampled_for = None

    def update_bounds(self, view: View) -> Box | None:
        key = (view.info.origin.x, view.info.origin.y, view.info.width, view.info.height, view.frame_in_map)
        if key == self._sampled_for:
            return None
        info = view.info
        self.costs = np.full((info.height, info.width), NO_INFORMATION, np.uint8)
        if self.keepout is not None:
            data = resample(np.asarray(self.keepout.data), self.keepout.info, info, view.frame_in_map, -1)
            self.costs[data >= 100] = LETHAL_OBSTACLE
        self.speed_limits = np.full((info.height, info.width), np.inf, np.float32)
        if self.speed is not None:
            data = resample(np.asarray(self.speed.data), self.speed.info, info, view.frame_in_map, -1)
            self.speed_limits = speed_limits(data, self.params)
        self._sampled_for = key
        return whole(info)

    def update_costs(self, master: np.ndarray, box: Box) -> None:
        combine_max(master, self.costs, box)


def warm_up() -> None:
    """Compile (or load from cache) the numba kernels."""
    grid = np.zeros((3, 3), np.uint8)
    _raytrace(grid, 1.5, 1.5, np.array([2.5]), np.array([2.5]), 5.0, 0.01, 0)
    one = np.zeros(1, np.int64)
    _inflate(grid, grid.copy(), 0, 0, 3, 3, 1, one, one, one, np.zeros(2, np.uint8), False)
