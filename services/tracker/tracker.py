"""Moving-obstacle tracking from a 2-D scan, in the odom frame (the local planner's).

One scan (`MoverTracker.update`):
1. static points are flagged: those within `map_obstacle_distance` of an occupied cell of the
   static map (when one is served, placed by map→odom), and those on or next to a cell of the
   rolling evidence grid that has been hit without a break for `static_after_s` — a wall, a shelf,
   a BARN cylinder, also without a map (SLAM, BARN). A cell's streak ends when a beam passes
   through it (its free space is seen), so a person who walks on frees the cells behind them and
   one who stands still long enough becomes part of the static world;
2. the points are clustered (PCL's Euclidean cluster extraction: points within
   `cluster_tolerance` of each other join, clusters of `min_cluster_size` points up to
   `max_cluster_radius` are kept, larger ones are walls not yet known to be static) and a cluster
   of which more than `max_static_share` is static is part of the static world;
3. each cluster is a measurement of a circle's centre: the centroid of the seen arc pushed away
   from the sensor by (2/π)·radius, where an arc of a quarter circle on each side has its centroid;
4. tracks (constant-velocity Kalman filters, state x y vx vy, white-acceleration process noise)
   are predicted to the scan's time and associated with the measurements by the Hungarian method
   (scipy's linear_sum_assignment) on the squared Mahalanobis distance, gated by `gate_chi2` and by
   `max_association_distance`; matched tracks are corrected, unmatched measurements start tentative
   tracks, and a track is confirmed after `confirm_hits` hits and deleted after `max_misses` scans
   in a row without one (`tentative_max_misses` while still tentative). Only tracks that have
   moved `min_travel` from where they were first seen are confirmed: before the evidence grid
   knows the walls (the first static_after_s, or a wall piece first seen), a piece of wall cut
   off by a shadow is a cluster like a person, but it stays where it is; and once the walls first
   seen are static, the tracks begun before are dropped (pieces of them coming out of a shadow
   made moving clusters).
Deterministic: no randomness, ties broken by the order of the inputs (the scan's beam order).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from numba import njit
from scipy.optimize import linear_sum_assignment
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from ...schemas.messages import OccupancyGrid
from ...geometry.distance import distances_to
from ...geometry.se2 import compose, inverse
from ...parameters.declare import Parameters, Rule, param

ARC_CENTROID = 2.0 / math.pi   # a half circle's points have their centroid this many radii from its centre
UNSET = -1.0                   # an evidence cell without a streak
FIT_MIN_POINTS = 8             # points of a cluster before a circle is fitted to it
FIT_MIN_ARC = math.pi / 4      # rad of the fitted circle the points must span
FIT_MAX_RMS = 0.03             # m: points further off the fitted circle (rms) are no circle's


@dataclass(frozen=True)
class TrackerParams(Parameters):
    """Names after PCL's EuclideanClusterExtraction (cluster_tolerance, min/max_cluster_size) and the
    usual multi-target tracker's; no ROS package sets the others' defaults."""
    cluster_tolerance: float = param(0.2, gt=0)         # m: points this close belong to one cluster
    min_cluster_size: int = param(3, ge=1)              # points: fewer are noise
    max_cluster_size: int = param(400, ge=1)            # points
    max_cluster_radius: float = param(0.6, gt=0)        # m: a wider cluster is a wall, not a mover
    max_static_share: float = param(0.3, ge=0, le=1)    # of a cluster's points static: more, and it is part of the static world
    map_obstacle_distance: float = param(0.15, ge=0)    # m from an occupied map cell within which a point is static
    map_occupied_thresh: int = param(65, ge=0, le=100)  # map value (percent) from which a cell is occupied (map_server's 0.65)
    evidence_resolution: float = param(0.1, gt=0)       # m: cells of the rolling evidence grid
    evidence_size: float = param(24.0, gt=0)            # m: side of the evidence grid, centred on the robot
    static_after_s: float = param(2.0, gt=0)            # s of cell hits without a break after which the cell is static
    evidence_clear_margin: float = param(0.2, ge=0)     # m short of a hit in which a beam does not end a cell's streak
    measurement_noise: float = param(0.05, gt=0)        # m: std of a cluster centre
    process_noise: float = param(1.0, gt=0)             # m/s²: std of the white acceleration of a mover
    initial_velocity_std: float = param(1.0, gt=0)      # m/s: of a new track
    gate_chi2: float = param(13.8, gt=0)                # squared Mahalanobis distance (χ², 2 dof, 99.9 %)
    max_association_distance: float = param(1.0, gt=0)  # m between a predicted track and a measurement
    confirm_hits: int = param(4, ge=1)                  # hits before a track is confirmed (published) ...
    min_travel: float = param(0.3, ge=0)                # m ... and how far it must have gone from where it was first seen:
                                                        # what never moved is the static world (the costmap's), not a mover
    max_misses: int = param(10, ge=1)                   # scans without a hit before a confirmed track is deleted
    tentative_max_misses: int = param(1, ge=0)          # the same for a tentative track
    radius_smoothing: float = param(0.3, gt=0, le=1)    # weight of a new cluster's radius in the track's estimate
    min_radius: float = param(0.1, gt=0)                # m: a track is at least this wide
    carve_by_tracks: bool = False                       # a cluster too wide, or claimed by two tracks, is cut along the tracks'
                                                        # circles (unless one circle fits it); a track inside another's circle is dropped
    fit_circles: bool = False                           # an arc is measured by a fitted circle where one fits

    rules = (Rule("max_cluster_size", lambda p: p.max_cluster_size >= p.min_cluster_size,
                  "at least min_cluster_size ({p.min_cluster_size})"),)


@dataclass
class Track:
    id: int
    state: np.ndarray          # (4,) x, y, vx, vy
    covariance: np.ndarray     # (4, 4)
    radius: float
    start: np.ndarray = field(default_factory=lambda: np.zeros(2))   # where it was first seen
    hits: int = 1
    misses: int = 0
    moved: bool = False        # has been min_travel from its start

    def confirmed(self, params: TrackerParams) -> bool:
        return self.hits >= params.confirm_hits and self.moved


@dataclass(frozen=True)
class TrackSet:
    """The confirmed tracks after a scan, as arrays (the Tracks message's fields)."""
    ids: np.ndarray            # (N,) int64
    states: np.ndarray         # (N, 4)
    covariances: np.ndarray    # (N, 4, 4)
    radii: np.ndarray          # (N,)


@dataclass(frozen=True)
class Cluster:
    centre: np.ndarray         # (2,) the circle's centre as measured
    radius: float
    points: np.ndarray         # (K, 2)
    fitted: bool = False       # measured by a circle fitted to the points (fit_circles)


# ---------------------------------------------------------------- static world

@njit(cache=True)
def _evidence_update(since, now, origin_u, origin_v, us, vs, clear_cells):
    """Each beam from the sensor (grid coordinates, cells) to its hit: the cells it passes more than
    clear_cells short of the hit lose their streak; the hit's cell starts one (or keeps it)."""
    height, width = since.shape
    for k in range(us.shape[0]):
        du, dv = us[k] - origin_u, vs[k] - origin_v
        length = math.sqrt(du * du + dv * dv)
        steps = int((length - clear_cells) * 2.0)      # half-cell steps
        for i in range(steps):
            t = i * 0.5 / length
            col, row = int(math.floor(origin_u + du * t)), int(math.floor(origin_v + dv * t))
            if 0 <= row < height and 0 <= col < width:
                since[row, col] = -1.0
    for k in range(us.shape[0]):
        col, row = int(math.floor(us[k])), int(math.floor(vs[k]))
        if 0 <= row < height and 0 <= col < width and since[row, col] < 0.0:
            since[row, col] = now


_NEIGHBOURS = np.indices((3, 3)).reshape(2, -1) - 1    # (row, col) offsets of the 9 cells of a 3 × 3 block


class EvidenceGrid:
    """Since when each cell (odom frame) has been hit without a break; a square that follows the
    robot, shifted by whole cells so that a cell keeps its place in the odom frame."""

    def __init__(self, params: TrackerParams):
        self.params = params
        self.resolution = params.evidence_resolution
        self.cells = max(3, int(round(params.evidence_size / self.resolution)))
        self.since = np.full((self.cells, self.cells), UNSET)
        self.origin: np.ndarray | None = None    # (col, row) of cell (0, 0) in whole cells of the odom frame

    def _follow(self, robot_xy: np.ndarray) -> None:
        centre = np.floor(robot_xy / self.resolution).astype(np.int64) - self.cells // 2
        if self.origin is None:
            self.origin = centre
            return
        shift = centre - self.origin
        if np.all(np.abs(shift) < self.cells // 4):
            return
        moved = np.full_like(self.since, UNSET)
        dc, dr = (int(v) for v in shift)
        if max(abs(dc), abs(dr)) < self.cells:      # else nothing of the old window is in the new one
            src = self.since[max(dr, 0):self.cells + min(dr, 0), max(dc, 0):self.cells + min(dc, 0)]
            moved[max(-dr, 0):max(-dr, 0) + src.shape[0], max(-dc, 0):max(-dc, 0) + src.shape[1]] = src
        self.since, self.origin = moved, centre

    def grid_coords(self, points: np.ndarray) -> np.ndarray:
        """(N, 2) points in cells (u along x, v along y) of the grid."""
        return points / self.resolution - self.origin

    def update(self, now_s: float, sensor_xy: np.ndarray, points: np.ndarray) -> None:
        self._follow(np.asarray(sensor_xy, np.float64))
        uv = self.grid_coords(np.asarray(points, np.float64).reshape(-1, 2))
        su, sv = self.grid_coords(np.asarray(sensor_xy, np.float64).reshape(1, 2))[0]
        _evidence_update(self.since, now_s, su, sv, np.ascontiguousarray(uv[:, 0]), np.ascontiguousarray(uv[:, 1]),
                         self.params.evidence_clear_margin / self.resolution)

    def static(self, now_s: float, points: np.ndarray) -> np.ndarray:
        """(N,) whether each point lies on or next to a cell hit without a break for static_after_s."""
        # the 3 × 3 neighbourhood of each point's cell, looked up for the points only (dilating the
        # whole grid each scan cost more than the rest of the tracker)
        cols, rows = np.floor(self.grid_coords(points)).astype(np.int64).T
        inside = (rows >= 0) & (rows < self.cells) & (cols >= 0) & (cols < self.cells)
        near_rows, near_cols = rows[inside, None] + _NEIGHBOURS[0], cols[inside, None] + _NEIGHBOURS[1]
        on_grid = (near_rows >= 0) & (near_rows < self.cells) & (near_cols >= 0) & (near_cols < self.cells)
        since = self.since[np.clip(near_rows, 0, self.cells - 1), np.clip(near_cols, 0, self.cells - 1)]
        old = on_grid & (since >= 0) & (now_s - since >= self.params.static_after_s)
        result = np.zeros(len(points), bool)
        result[inside] = old.any(axis=1)
        return result


class StaticMap:
    """Distances (m) to the static map's occupied cells, for points in the odom frame."""

    def __init__(self, grid: OccupancyGrid, params: TrackerParams):
        info = grid.info
        if info.width == 0 or info.height == 0 or info.resolution <= 0:
            raise ValueError(f"a map of {info.width} x {info.height} cells at {info.resolution} m cannot be used")
        occupied = np.asarray(grid.data) >= params.map_occupied_thresh
        self.info = info
        self.distance = distances_to(occupied) * info.resolution if occupied.any() \
            else np.full(occupied.shape, np.inf)
        self.origin = np.array([info.origin.x, info.origin.y, info.origin.theta])

    def static(self, points_in_map: np.ndarray, within: float) -> np.ndarray:
        """(N,) whether each point (map frame) lies within `within` of an occupied cell's centre
        plus half a cell (the cell's edge, nearly)."""
        local = compose(inverse(self.origin), np.column_stack([points_in_map, np.zeros(len(points_in_map))]))
        cols, rows = np.floor(local[:, :2] / self.info.resolution).astype(np.int64).T
        inside = (rows >= 0) & (rows < self.info.height) & (cols >= 0) & (cols < self.info.width)
        result = np.zeros(len(points_in_map), bool)
        result[inside] = self.distance[rows[inside], cols[inside]] <= within + self.info.resolution / 2
        return result


# ---------------------------------------------------------------- clusters

def euclidean_clusters(points: np.ndarray, sensor_xy, params: TrackerParams,
                       static: np.ndarray | None = None, priors: np.ndarray | None = None) -> list[Cluster]:
    """Clusters of points within cluster_tolerance of each other, of min_cluster_size up to
    max_cluster_size points and max_cluster_radius, in the order of their first point. With
    `static` (N,) flags, a cluster more than max_static_share static is part of the static world:
    the piece of a wall coming out of a mover's shadow is new to the evidence grid, but it hangs
    together with the wall seen before (clustering only the new points made it a false mover
    sliding along the wall with the shadow's edge). With `priors` (K, 3) — circles x, y, radius
    where tracks are expected — a cluster refused whole, or claimed by two circles, is carved:
    the points within cluster_tolerance of each circle's edge are a cluster of their own, and the
    rest is clustered again (two cylinders passing each other touch in the scan, a 0.9 m cluster,
    "a wall": both tracks were lost and the robot ran into one; DynaBARN easy-25)."""
    points = np.asarray(points, np.float64).reshape(-1, 2)
    static = np.zeros(len(points), bool) if static is None else np.asarray(static, bool)
    if len(points) < params.min_cluster_size:
        return []
    pairs = cKDTree(points).query_pairs(params.cluster_tolerance, output_type="ndarray")
    graph = coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(len(points),) * 2)
    _, labels = connected_components(graph, directed=False)
    clusters = []
    _, first = np.unique(labels, return_index=True)
    priors = np.zeros((0, 3)) if priors is None else np.asarray(priors, np.float64).reshape(-1, 3)
    for label in labels[np.sort(first)]:
        member = labels == label
        owners = _owners(points[member], priors, params)
        claims = _claims(owners, params)
        cluster = _cluster(points[member], static[member], sensor_xy, params)
        if len(claims) >= 2 and not (cluster is not None and cluster.fitted):
            # claimed by two tracks and the arc of no one circle: movers side by side. One circle
            # fits: one cylinder that two tracks had split, carved along them scan after scan and
            # kept split (DynaBARN hard-20: three tracks of 0.22-0.28 m on a 0.5 m cylinder, their
            # velocities 50° apart)
            cluster = None
        if cluster is not None:
            clusters.append(cluster)
        elif len(claims):
            clusters.extend(_carved(points[member], static[member], owners, sensor_xy, params))
    return clusters


def _owners(members: np.ndarray, priors: np.ndarray, params: TrackerParams) -> np.ndarray:
    """(K,) the index of the circle whose edge each point is nearest, if within cluster_tolerance
    of it; -1 where none."""
    if not len(priors):
        return np.full(len(members), -1)
    gaps = np.hypot(members[:, None, 0] - priors[None, :, 0], members[:, None, 1] - priors[None, :, 1]) \
        - priors[None, :, 2]
    nearest = np.argmin(gaps, axis=1)
    return np.where(gaps[np.arange(len(members)), nearest] <= params.cluster_tolerance, nearest, -1)


def _claims(owners: np.ndarray, params: TrackerParams) -> np.ndarray:
    """The circles that own (_owners) at least min_cluster_size of the points: two or more, and the
    cluster is two movers side by side (measured as one, one of two people crossing got the pair's
    centre and was lost)."""
    circles, counts = np.unique(owners, return_counts=True)
    return circles[(circles >= 0) & (counts >= params.min_cluster_size)]


def _cluster(members: np.ndarray, static: np.ndarray, sensor_xy, params: TrackerParams) -> Cluster | None:
    """The circle measured by one cluster's points, or None when they are no mover's."""
    if not params.min_cluster_size <= len(members) <= params.max_cluster_size \
            or np.mean(static) > params.max_static_share:
        return None
    centroid = members.mean(axis=0)
    radius = max(params.min_radius, float(np.max(np.hypot(*(members - centroid).T))))
    if radius > params.max_cluster_radius:
        return None
    away = centroid - np.asarray(sensor_xy, np.float64)
    away /= max(float(np.hypot(*away)), 1e-9)
    fitted = _circle_fit(members, away, params) if params.fit_circles else None
    if fitted is not None:
        return Cluster(fitted[:2], max(params.min_radius, fitted[2]), members, fitted=True)
    return Cluster(centroid + away * ARC_CENTROID * radius, radius, members)


def _circle_fit(members: np.ndarray, away: np.ndarray, params: TrackerParams) -> np.ndarray | None:
    """(x, y, radius) of the circle fitted to an arc (Kasa's algebraic fit), or None where the points
    do not make one: too few, an arc under FIT_MIN_ARC, a centre on the sensor's side, a radius
    outside the movers', or points off the circle by more than FIT_MAX_RMS. A cylinder coming out
    from behind another shows a sliver that grows: measured by the half-circle rule, its centre
    slid along the sliver and the track's velocity pointed 70° off the cylinder's (DynaBARN easy-25)."""
    if len(members) < FIT_MIN_POINTS:
        return None
    mean = members.mean(axis=0)
    local = members - mean
    design = np.column_stack([local, np.ones(len(local))])
    (a, b, c), *_ = np.linalg.lstsq(design, (local ** 2).sum(axis=1), rcond=None)
    centre = np.array([a / 2, b / 2])
    radius_sq = c + centre @ centre
    if radius_sq <= 0:
        return None
    radius = math.sqrt(radius_sq)
    gaps = np.hypot(*(local - centre).T) - radius
    bearings = np.arctan2(local[:, 1] - centre[1], local[:, 0] - centre[0])
    spread = np.ptp(np.unwrap(bearings[np.argsort(bearings)]))
    if not (params.min_radius <= radius <= params.max_cluster_radius and centre @ away > 0
            and spread >= FIT_MIN_ARC and math.sqrt(np.mean(gaps ** 2)) <= FIT_MAX_RMS):
        return None
    return np.array([*(mean + centre), radius])


def _carved(members: np.ndarray, static: np.ndarray, owners: np.ndarray, sensor_xy,
            params: TrackerParams) -> list[Cluster]:
    """A cluster cut along the expected circles: each point goes to the circle that owns it
    (_owners); what no circle takes is clustered again."""
    pieces = [_cluster(members[owners == k], static[owners == k], sensor_xy, params) for k in np.unique(owners[owners >= 0])]
    rest = owners < 0
    return [c for c in pieces if c is not None] + \
        (euclidean_clusters(members[rest], sensor_xy, params, static[rest]) if rest.any() else [])


# ---------------------------------------------------------------- the tracker

MEASURE = np.array([[1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0]])


def predicted(state: np.ndarray, covariance: np.ndarray, dt: float, accel_std: float) -> tuple[np.ndarray, np.ndarray]:
    """A constant-velocity filter's state and covariance dt seconds on (white acceleration noise)."""
    f = np.eye(4)
    f[0, 2] = f[1, 3] = dt
    g = np.array([[dt * dt / 2, 0.0], [0.0, dt * dt / 2], [dt, 0.0], [0.0, dt]])
    return f @ state, f @ covariance @ f.T + (accel_std ** 2) * (g @ g.T)


@dataclass
class MoverTracker:
    params: TrackerParams = field(default_factory=TrackerParams)

    def __post_init__(self) -> None:
        self.evidence = EvidenceGrid(self.params)
        self.static_map: StaticMap | None = None
        self.tracks: list[Track] = []
        self.next_id = 1
        self.stamp_s: float | None = None
        self.warm_until_s: float | None = None    # the evidence grid knows the walls seen first from then

    def set_map(self, grid: OccupancyGrid | None) -> None:
        """The static map (ValueError for one that cannot be used), or None to track without one."""
        self.static_map = None if grid is None else StaticMap(grid, self.params)

    def static_points(self, now_s: float, sensor_xy, points: np.ndarray, odom_in_map=None) -> np.ndarray:
        """(N,) whether each point (odom frame) is explained by the static world; updates the
        evidence grid."""
        points = np.asarray(points, np.float64).reshape(-1, 2)
        self.evidence.update(now_s, np.asarray(sensor_xy, np.float64), points)
        static = self.evidence.static(now_s, points)
        if self.static_map is not None and odom_in_map is not None and len(points):
            in_map = compose(np.asarray(odom_in_map, np.float64), np.column_stack([points, np.zeros(len(points))]))
            static |= self.static_map.static(in_map[:, :2], self.params.map_obstacle_distance)
        return static

    def update(self, now_s: float, sensor_xy, points: np.ndarray, odom_in_map=None) -> TrackSet:
        """One scan: its endpoints (N, 2) and the sensor's position in the odom frame at now_s (s);
        odom_in_map is the odom frame's pose in the map (the static map's frame) when a map is set."""
        if self.stamp_s is not None and now_s < self.stamp_s:
            raise ValueError(f"scan at {now_s} s is older than the last one at {self.stamp_s} s")
        dt = 0.0 if self.stamp_s is None else now_s - self.stamp_s
        self.stamp_s = now_s
        if self.warm_until_s is None:
            self.warm_until_s = now_s + self.params.static_after_s
        elif self.warm_until_s <= now_s:
            # until the walls seen first are static, pieces of them coming out of a shadow make
            # moving clusters: begin again from scratch once, when they are
            self.tracks, self.warm_until_s = [], np.inf
        points = np.asarray(points, np.float64).reshape(-1, 2)
        static = self.static_points(now_s, sensor_xy, points, odom_in_map)
        for track in self.tracks:
            track.state, track.covariance = predicted(track.state, track.covariance, dt, self.params.process_noise)
        priors = np.array([[*t.state[:2], t.radius] for t in self.tracks], np.float64).reshape(-1, 3) \
            if self.params.carve_by_tracks else None
        clusters = euclidean_clusters(points, sensor_xy, self.params, static, priors)
        matches = self._associate(clusters)
        matched = set()
        for t, c in matches:
            self._correct(self.tracks[t], clusters[c])
            matched.add(t)
        for t, track in enumerate(self.tracks):
            if t not in matched:
                track.misses += 1
        self.tracks = [t for t in self.tracks if t.misses <= (self.params.max_misses if t.confirmed(self.params)
                                                             else self.params.tentative_max_misses)]
        if self.params.carve_by_tracks:
            self.tracks = _without_doubles(self.tracks)
        used = {c for _, c in matches}
        for c, cluster in enumerate(clusters):
            if c not in used:
                self._start(cluster)
        return self.confirmed()

    def _associate(self, clusters: list[Cluster]) -> list[tuple[int, int]]:
        """(track, cluster) pairs: the assignment of least total squared Mahalanobis distance among
        the pairs inside both gates."""
        if not self.tracks or not clusters:
            return []
        p = self.params
        centres = np.array([c.centre for c in clusters])
        cost = np.empty((len(self.tracks), len(clusters)))
        for t, track in enumerate(self.tracks):
            innovation = centres - track.state[:2]
            s = track.covariance[:2, :2] + np.eye(2) * p.measurement_noise ** 2
            d2 = np.einsum("ki,ij,kj->k", innovation, np.linalg.inv(s), innovation)
            far = np.hypot(innovation[:, 0], innovation[:, 1]) > p.max_association_distance
            cost[t] = np.where((d2 > p.gate_chi2) | far, np.inf, d2)
        gated = np.isfinite(cost)
        rows, cols = linear_sum_assignment(np.where(gated, cost, p.gate_chi2 * 1e3))
        return [(int(r), int(c)) for r, c in zip(rows, cols) if gated[r, c]]

    def _correct(self, track: Track, cluster: Cluster) -> None:
        p = self.params
        s = MEASURE @ track.covariance @ MEASURE.T + np.eye(2) * p.measurement_noise ** 2
        gain = track.covariance @ MEASURE.T @ np.linalg.inv(s)
        track.state = track.state + gain @ (cluster.centre - track.state[:2])
        joseph = np.eye(4) - gain @ MEASURE
        track.covariance = joseph @ track.covariance @ joseph.T + gain @ (np.eye(2) * p.measurement_noise ** 2) @ gain.T
        track.radius += p.radius_smoothing * (cluster.radius - track.radius)
        track.hits += 1
        track.misses = 0
        track.moved |= bool(np.hypot(*(track.state[:2] - track.start)) >= p.min_travel)

    def _start(self, cluster: Cluster) -> None:
        p = self.params
        covariance = np.diag([p.measurement_noise ** 2] * 2 + [p.initial_velocity_std ** 2] * 2)
        self.tracks.append(Track(self.next_id, np.array([*cluster.centre, 0.0, 0.0]), covariance, cluster.radius,
                                 cluster.centre.copy()))
        self.next_id += 1

    def confirmed(self) -> TrackSet:
        tracks = [t for t in self.tracks if t.confirmed(self.params)]
        return TrackSet(np.array([t.id for t in tracks], np.int64).reshape(-1),
                        np.array([t.state for t in tracks], np.float64).reshape(-1, 4),
                        np.array([t.covariance for t in tracks], np.float64).reshape(-1, 4, 4),
                        np.array([t.radius for t in tracks], np.float64).reshape(-1))


def _without_doubles(tracks: list[Track]) -> list[Track]:
    """The tracks without those whose centre lies inside the circle of a track with more hits (the
    earlier on a tie): two solid movers cannot overlap, so they are one mover tracked twice."""
    order = sorted(range(len(tracks)), key=lambda k: (-tracks[k].hits, k))
    kept: list[int] = []
    for k in order:
        x, y = tracks[k].state[:2]
        if all(math.hypot(x - tracks[j].state[0], y - tracks[j].state[1]) >= max(tracks[j].radius, tracks[k].radius)
               for j in kept):
            kept.append(k)
    return [tracks[k] for k in sorted(kept)]


def warm_up() -> None:
    """Compile (or load from cache) the evidence kernel and the map's distance transform outside any scan."""
    params = TrackerParams(evidence_size=1.0)
    EvidenceGrid(params).update(0.0, np.zeros(2), np.array([[0.3, 0.2]]))
    grid = OccupancyGrid()
    grid.data = np.full((2, 2), 100, np.int8)
    grid.info.width = grid.info.height = 2
    StaticMap(grid, params)
