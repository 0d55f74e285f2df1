"""Laser odometry as a pure core: each scan matched to a LOCAL map, hector mapping's grids and
Gauss-Newton matcher (services/slam/hector.py, hector_match.py) in a window that follows the robot,
so that a push or a slip the wheels never see shows in the pose, and memory stays bounded.

The frame is the odometry's: at the first scan the pose is the wheel odometry's pose there and the
local map starts around it; from then on it moves as the scans say. Each match starts from the last
laser pose carried by the wheels' motion since the last scan (so ordinary driving is easy), and
also from the last laser pose and from the last laser motion repeated (hector's starts: a push the
wheels did not see, and one that goes on); the match of the lowest cost is kept.

Only end points that fall inside the local map's window (at the wheels' guess, a coarsest cell in
from its edge) are matched: off the grid a point reads "free" and would count against every pose alike (in
an open arena the far walls lie beyond the window). A match is refused — flagged, the pose carried
by the wheels' motion, the map left alone — when the scan has fewer than min_scan_points such end
points, when its cost per end point (the mean of (1 − M)², 0 on certainly occupied cells) exceeds
max_mismatch, or when it moved the pose more than max_correction_xy / max_correction_yaw away from
the wheels' guess (diverged: wheels are not that wrong within one scan). A refused match says
nothing of where the robot is (the node publishes nothing for it: the wheels' pose again, however
large its covariance, would be fused at every scan and pull a fusion back to the wheels it doubts).
After restart_after_refusals refusals in a row the map no longer describes the world around the
robot (obstacles that moved, a robot carried off): it starts afresh at the wheels' guess.

Moving bodies (people, DynaBARN's cylinders) are kept out of the match, or the pose is dragged along
with them: a cylinder walking ahead is matched against the outline it left in the map where it
stood, and in an open arena, where only far walls hold the pose along the way, the laser lagged the
truth by 1 m in 1.4 s. So a cell hit by fewer than confirmed_hits scans (net) that a later scan's
beams cross is free again at once (hector clears it only after a dozen such scans), and an end point
on a cell the map has seen free (moving_free_updates scans more than hit) lies on something that
moved there: it is neither matched nor mapped. A wall, hit at every update, is not touched.

The covariance is Gauss-Newton's, of the match against the local map: hector's H with each end
point's map gradient replaced by the ideal one of the surface under it (its normal from its
neighbours in the scan, over map_resolution; only points on occupied map cells), over
covariance_scale × the cost per end point, with the weak prior of unmatched_std_* added
(Σ = (H / (s·cost·res²) + diag(1/σ₀²))⁻¹): a direction no wall fixes (along a featureless
corridor) has about σ₀², one the walls fix what they say. Along a direction the match fixes worse
than degenerate_std the pose keeps the wheels' guess (solution remapping): there the matcher would
only snap back to the map's own texture.

The map is hector's, updated from the matched pose (each scan's outline filled between neighbouring
end points, so a wall beams graze is whole) once the robot has moved
map_update_distance_thresh or turned map_update_angle_thresh since the last update, and rolled
(HectorMapper.recentre) by whole coarsest cells when the robot is more than map_recentre_distance
from its centre: a room smaller than the window stays whole (no drift while the robot stays in it),
a long way forgets what it left behind.
"""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np

from ...geometry.se2 import compose, relative
from ...parameters.declare import Parameters, Rule, param
from ..slam.hector import HectorMapper, HectorParams
from ..slam.hector_match import interpolate, mismatch

# why a match was refused (LaserOdometryResult.failure; the node counts each)
TOO_FEW_POINTS, COST_TOO_HIGH, DIVERGED = "too_few_points", "cost_too_high", "diverged"
FIRST_SCAN = "first_scan"     # not a failure: nothing to match yet, the scan starts the map


@dataclass(frozen=True)
class LaserOdometryParams(Parameters):
    """hector_mapping's names where they apply, then the local map's and the match's judgement."""
    map_resolution: float = param(0.05, gt=0)                # m, the finest grid
    map_size: int = param(512, ge=16)                        # cells a side of the finest grid (the window)
    map_multi_res_levels: int = param(3, ge=1)               # grids, each half the resolution of the one before
    update_factor_free: float = param(0.4, gt=0, lt=0.5)
    update_factor_occupied: float = param(0.9, gt=0.5, lt=1)
    map_update_distance_thresh: float = param(0.4, ge=0)     # m moved before the map takes a scan
    map_update_angle_thresh: float = param(0.9, ge=0)        # rad turned before the map takes a scan
    laser_min_dist: float = param(0.4, ge=0)                 # m: nearer returns are dropped
    laser_max_dist: float = param(30.0, gt=0)                # m: farther returns are dropped
    # the wheels' guess holds the match where no wall does (along a corridor): weights per m², rad²
    # beside the scan's sum of squared (1 − occupancy), a few hundredths of a wall's pull
    guess_weight_xy: float = param(100.0, ge=0)
    guess_weight_yaw: float = param(100.0, ge=0)
    search_angle: float = param(0.0, ge=0)                   # rad: also start turned by ± this (hector's; 0: not)
    # the local map: rolled so the robot is at its centre again when it is farther than this from it
    map_recentre_distance: float = param(4.0, gt=0)          # m
    # when a match is refused
    min_scan_points: int = param(20, ge=3)                   # end points in range
    max_mismatch: float = param(0.2, gt=0)                   # cost per end point (0 perfect, 1 every point on free space)
    max_correction_xy: float = param(0.6, gt=0)              # m from the wheels' guess
    max_correction_yaw: float = param(0.5, gt=0)             # rad from the wheels' guess
    restart_after_refusals: int = param(10, ge=1)            # refused matches in a row before the map starts afresh
    # moving bodies (people, DynaBARN's cylinders) kept out of the match: a cell hit by fewer scans
    # than confirmed_hits (net) that a later scan's beams cross is free again at once (0: hector's
    # slow clearing); an end point on a cell the map has taken as free in moving_free_updates scans
    # more than as hit lies on something that moved there, and is neither matched nor mapped (0: off)
    confirmed_hits: float = param(1.5, ge=0)
    moving_free_updates: float = param(1.0, ge=0)
    # the covariance
    covariance_scale: float = param(20.0, gt=0)              # × Gauss-Newton's cost · H⁻¹ (end points are not independent)
    normal_neighbour_dist: float = param(0.5, gt=0)          # m: end points this near lie on one surface
    normal_baseline: float = param(0.15, gt=0)               # m along the outline each side: the chord of a normal
    degenerate_std: float = param(0.03, gt=0)                # m: a direction the match fixes worse keeps the wheels' guess
    unmatched_std_xy: float = param(1.0, gt=0)               # m: what a scan tells of a direction no wall fixes;
    unmatched_std_yaw: float = param(0.5, gt=0)              # rad  the std published for a refused match

    rules = (Rule("laser_max_dist", lambda p: p.laser_max_dist > p.laser_min_dist, "> laser_min_dist ({p.laser_min_dist})"),
             Rule("map_multi_res_levels", lambda p: p.map_size // 2 ** (p.map_multi_res_levels - 1) >= 4,
                  "few enough that the coarsest grid keeps 4 cells a side (map_size {p.map_size})"),
             Rule("map_recentre_distance", lambda p: p.map_recentre_distance < p.map_size * p.map_resolution / 2,
                  "< half the map's side ({p.map_size} × {p.map_resolution} m / 2)"))

    def hector_params(self) -> HectorParams:
        """The grids' and matcher's parameters: hector's names this class shares, the local map
        centred on the robot, each match also started from the last motion repeated."""
        shared = {f.name: getattr(self, f.name) for f in dataclasses.fields(HectorParams) if hasattr(self, f.name)}
        return HectorParams(**shared, map_start_x=0.5, map_start_y=0.5, predict_motion=True)


@dataclass(frozen=True)
class LaserOdometryResult:
    pose: np.ndarray            # (x, y, yaw), the odom frame
    covariance: np.ndarray      # (3, 3) of the pose (m², rad²)
    ok: bool                    # the scan was matched (False: the pose is the wheels' guess)
    failure: str = ""           # why not: TOO_FEW_POINTS, COST_TOO_HIGH, DIVERGED, or FIRST_SCAN
    cost: float = 0.0           # the match's cost per end point (mismatch)
    points: int = 0             # end points in range
    recentred: bool = False     # the local map rolled after this scan


class LaserOdometry:
    """`step(stamp_ns, points, odometry_pose)` for each scan, in stamp order: its end points (N, 2)
    in the robot frame and the wheel odometry's pose at its stamp; returns a LaserOdometryResult."""

    def __init__(self, params: LaserOdometryParams = LaserOdometryParams()):
        self.params = params
        self.mapper: HectorMapper | None = None
        self.pose: np.ndarray | None = None
        self.refusals = 0                                # refused matches in a row
        self.restarts = 0                                # maps started afresh after refusals
        self.ghosts_cleared = 0                          # cells a moving body left, cleared (clear_unconfirmed)
        self._odometry: np.ndarray | None = None         # the wheels' pose at the last scan
        self._prior = np.diag([params.unmatched_std_xy ** -2, params.unmatched_std_xy ** -2, params.unmatched_std_yaw ** -2])
        self.unmatched = np.diag([params.unmatched_std_xy ** 2, params.unmatched_std_xy ** 2, params.unmatched_std_yaw ** 2])

    def step(self, stamp_ns: int, points: np.ndarray, odometry_pose) -> LaserOdometryResult:
        """One scan (`stamp_ns` unused: the core keeps no time; the node's twist does)."""
        odometry = np.asarray(odometry_pose, np.float64)[:3].copy()
        guess = odometry if self._odometry is None else compose(self.pose, relative(self._odometry, odometry))
        self._odometry = odometry
        if self.mapper is None or self.refusals >= self.params.restart_after_refusals:
            self.restarts += self.mapper is not None
            self.mapper, self.refusals = HectorMapper(self.params.hector_params(), start=guess), 0
        mapper = self.mapper
        points = self.matchable(mapper.in_range(points), guess)
        if len(points) < self.params.min_scan_points:
            return self._refuse(guess, TOO_FEW_POINTS, len(points))
        if mapper.updates == 0:                          # the first scan with enough points starts the map
            result = self._accept(guess, points, self.unmatched.copy(), 0.0)
            return dataclasses.replace(result, ok=False, failure=FIRST_SCAN)
        matched = mapper.best_match(points, guess)
        cost = mismatch(*mapper.probabilities()[0], points, matched)
        off = relative(guess, matched)
        if not np.all(np.isfinite(matched)) or math.hypot(off[0], off[1]) > self.params.max_correction_xy \
                or abs(off[2]) > self.params.max_correction_yaw:
            return self._refuse(guess, DIVERGED, len(points), cost)
        if cost > self.params.max_mismatch:
            return self._refuse(guess, COST_TOO_HIGH, len(points), cost)
        information = self.information(points, matched, cost)
        covariance = np.linalg.inv(information + self._prior)
        correction = matched - guess
        correction[2] = math.remainder(correction[2], math.tau)
        pose = guess + self.constrained(information) @ correction
        return self._accept(pose, points, (covariance + covariance.T) / 2, cost)

    def matchable(self, points: np.ndarray, pose) -> np.ndarray:
        """The end points (robot frame) to match and map, with the robot at `pose`: those inside the
        grids, a coarsest cell in from their edge, and not on a cell the map has seen free
        moving_free_updates scans more than hit.

        Nearer the edge the coarse grids' interpolation reads the nothing beyond it and pulls the
        points inwards: in an open arena, a far wall entering the window dragged the pose 1 m back
        in a second, each map update laying the wall where the pull had put it. A person or a
        cylinder that walked into space the scans saw empty would be matched against the outline it
        left in the map where it stood: the pose is dragged along with it (a DynaBARN obstacle pulled
        the laser 1 m in 2 s where the wheels and the IMU felt nothing)."""
        info = self.mapper.infos[0]
        margin = 2 ** (len(self.mapper.infos) - 1)
        u, v = self._cells(points, pose)
        keep = (u >= margin) & (v >= margin) & (u < info.width - margin) & (v < info.height - margin)
        if self.params.moving_free_updates > 0 and self.mapper.updates > 0:
            seen_free = self.mapper.log_odds[0][v[keep].astype(np.int64), u[keep].astype(np.int64)] \
                <= self.params.moving_free_updates * self.mapper.free_update
            keep[keep] = ~seen_free
        return points[keep]

    def _cells(self, points: np.ndarray, pose) -> tuple[np.ndarray, np.ndarray]:
        """The end points' (robot frame) column and row in the finest grid, with the robot at `pose`."""
        info = self.mapper.infos[0]
        x, y, yaw = (float(v) for v in pose)
        c, s = math.cos(yaw), math.sin(yaw)
        return ((x + c * points[:, 0] - s * points[:, 1] - info.origin.x) / info.resolution,
                (y + s * points[:, 0] + c * points[:, 1] - info.origin.y) / info.resolution)

    def constrained(self, information: np.ndarray) -> np.ndarray:
        """The projection onto the directions of the pose the match fixes better than degenerate_std
        (Zhang, Kaess & Singh 2016, "On degeneracy of optimization-based state estimation problems":
        solution remapping): the match's correction is kept along them and the wheels' guess along
        the others (along a featureless corridor, where the matcher would snap back to the map's
        own texture). A radian of yaw counts as a metre (its arc at 1 m)."""
        eigenvalues, vectors = np.linalg.eigh(information)
        fixed = vectors[:, eigenvalues > self.params.degenerate_std ** -2]
        return fixed @ fixed.T

    def information(self, points: np.ndarray, pose, cost: float) -> np.ndarray:
        """What the match tells of each direction of the pose (3 × 3, per m², m², rad²): hector's H
        with each end point's map gradient ∇M replaced by the ideal one of the surface the point
        lies on, its normal / map_resolution (from its neighbours in the scan), over covariance_scale
        × the cost per end point; only end points on the map's occupied cells count (a wall the
        window has forgotten, or not yet taken, fixes nothing). The map's own gradient along a wall
        is its rasterisation — the dashes grazing beams leave — which in a corridor claims what the
        wall does not hold."""
        p = self.params
        normals, used = surface_normals(points, p.normal_neighbour_dist, p.normal_baseline)
        x, y, yaw = (float(v) for v in pose)
        c, s = math.cos(yaw), math.sin(yaw)
        occupied = interpolate(*self.mapper.probabilities()[0], x + c * points[used, 0] - s * points[used, 1],
                               y + s * points[used, 0] + c * points[used, 1])[0] >= 0.5
        normals, used = normals[occupied], used[occupied]     # only surfaces the map holds too
        sx, sy = points[used, 0], points[used, 1]
        nx, ny = c * normals[:, 0] - s * normals[:, 1], s * normals[:, 0] + c * normals[:, 1]
        rows = np.column_stack([nx, ny, nx * (-s * sx - c * sy) + ny * (c * sx - s * sy)])
        return rows.T @ rows / (p.map_resolution ** 2 * p.covariance_scale * max(cost, 1e-6))

    def _accept(self, pose, points, covariance, cost) -> LaserOdometryResult:
        mapper, self.refusals = self.mapper, 0
        mapper.place(pose, points)
        if mapper.moved():
            mapper.integrate(filled(points, self.params.normal_neighbour_dist, self.params.map_resolution / 2))
            if self.params.confirmed_hits > 0:
                self.ghosts_cleared += mapper.clear_unconfirmed(self.params.confirmed_hits * mapper.occupied_update)
        self.pose = mapper.pose.copy()
        recentred = (math.hypot(*(self.pose[:2] - self._centre())) > self.params.map_recentre_distance
                     and mapper.recentre(self.pose[0], self.pose[1]))
        return LaserOdometryResult(self.pose.copy(), covariance, True, "", float(cost), len(points), recentred)

    def _refuse(self, guess, failure: str, points: int, cost: float = 0.0) -> LaserOdometryResult:
        self.refusals += 1
        self.mapper.place(guess)
        self.pose = self.mapper.pose.copy()
        return LaserOdometryResult(self.pose.copy(), self.unmatched.copy(), False, failure, float(cost), points)

    def _centre(self) -> np.ndarray:
        info = self.mapper.infos[0]
        return np.array([info.origin.x + info.width * info.resolution / 2, info.origin.y + info.height * info.resolution / 2])


def filled(points: np.ndarray, neighbour_dist: float, spacing: float) -> np.ndarray:
    """End points (N, 2, scan order) with points added every `spacing` on the line between neighbours
    within neighbour_dist of each other (one surface), as if more beams had hit it: a wall the
    beams graze is taken whole, not as the dashes where they end, whose edges would give the
    matcher a grip along it that the wall does not have (in a corridor it would snap back to them)."""
    if len(points) < 2:
        return points
    steps = np.diff(points, axis=0)
    gaps = np.hypot(steps[:, 0], steps[:, 1])
    counts = np.where(gaps <= neighbour_dist, np.ceil(gaps / spacing).astype(np.int64), 1)
    starts = np.repeat(np.arange(len(gaps)), counts)
    fractions = np.arange(counts.sum()) - np.repeat(np.cumsum(counts) - counts, counts)
    fractions = fractions / np.repeat(counts, counts)
    return np.concatenate([points[starts] + steps[starts] * fractions[:, None], points[-1:]])


def surface_normals(points: np.ndarray, neighbour_dist: float, baseline: float) -> tuple[np.ndarray, np.ndarray]:
    """Unit normals (M, 2) of the surfaces under end points (N, 2, scan order) and the indices of
    the M points that have one: square to the chord between the points `baseline` before and after
    it along the scan's outline, where no gap between neighbours on the way is over neighbour_dist
    (a chord, not the next point: over a few cm the range noise would turn the normal)."""
    n = len(points)
    gaps = np.hypot(*np.diff(points, axis=0).T) if n > 1 else np.zeros(0)
    piece = np.concatenate([[0], np.cumsum(gaps > neighbour_dist)])       # pieces of unbroken outline
    along = np.concatenate([[0.0], np.cumsum(gaps)])                         # arc length, scan order
    before = np.searchsorted(along, along - baseline, side="right") - 1
    after = np.searchsorted(along, along + baseline, side="left")
    inside = (before >= 0) & (after < n)
    index = np.flatnonzero(inside)
    before, after = before[inside], after[inside]
    same = (piece[before] == piece[index]) & (piece[after] == piece[index])
    index, before, after = index[same], before[same], after[same]
    tangents = points[after] - points[before]
    lengths = np.hypot(tangents[:, 0], tangents[:, 1])
    keep = lengths > 0
    index, tangents, lengths = index[keep], tangents[keep], lengths[keep]
    return np.column_stack([-tangents[:, 1], tangents[:, 0]]) / lengths[:, None], index


def warm_up() -> None:
    """Compile (or load from numba's cache) hector's kernels the way step calls them: a map made and
    a scan matched on a square of end points."""
    side = np.linspace(-2.0, 2.0, 40)
    square = np.concatenate([np.column_stack([side, np.full(40, edge)]) for edge in (-2.0, 2.0)]
                            + [np.column_stack([np.full(40, edge), side]) for edge in (-2.0, 2.0)])
    core = LaserOdometry(LaserOdometryParams(map_size=64, map_recentre_distance=1.0))
    core.step(0, square, (0.0, 0.0, 0.0))
    core.step(1, square, (0.0, 0.0, 0.0))
