"""Hector mapping (Kohlbrecher et al. 2011) as a pure core: occupancy grids at several resolutions,
each scan matched to them coarse to fine (hector_match.py) without odometry, and the grids updated
from the matched pose once the robot has moved map_update_distance_thresh or turned
map_update_angle_thresh since the last update (hector_mapping's parameter names and defaults).

hector_mapping starts each match from the last pose, which fails once the robot turns more
between scans than Gauss-Newton's reach on the coarsest grid (a few cells at the far walls): on
the MIT CSAIL log, a 5 Hz laser turning up to 0.45 rad a scan, that lost the track for good. So
the matcher also starts from the last pose turned by ±search_angle, from the last motion repeated
and from odometry's guess when there is one, and keeps the match with the lowest cost (ours, as
is the optional pull towards odometry's guess, guess_weight_*).

Each grid holds log-odds: as in hector_mapping a cell changes at most once a scan, the cells a
beam crosses by log(update_factor_free / (1 − update_factor_free)), the cell it ends in by
log(update_factor_occupied / (1 − …)), which wins over the free. Clipped to ±LOG_ODDS_LIMIT so a
cell seen wrong can still change. Pure: numpy, numba and the slam service's cell traversal
(particle_grids.segment_cells).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit

from ...geometry.grid import grid_coords
from ...geometry.se2 import compose, inverse, relative, wrap_angle
from ...parameters.declare import Parameters, param
from ...schemas.messages import Header, MapMetaData, OccupancyGrid, Pose2D
from .hector_match import match, mismatch, pose_covariance
from .particle_grids import occupancy_data, segment_cells

LOG_ODDS_LIMIT = 10.0


@dataclass(frozen=True)
class HectorParams(Parameters):
    """hector_mapping's names and defaults, then ours."""
    map_resolution: float = param(0.025, gt=0)               # m, the finest grid
    map_size: int = param(1024, ge=16)                       # cells a side of the finest grid
    map_start_x: float = param(0.5, ge=0, le=1)              # where the start lies, as a fraction of the map
    map_start_y: float = param(0.5, ge=0, le=1)
    map_multi_res_levels: int = param(3, ge=1)               # grids, each half the resolution of the one before
    update_factor_free: float = param(0.4, gt=0, lt=0.5)
    update_factor_occupied: float = param(0.9, gt=0.5, lt=1)
    map_update_distance_thresh: float = param(0.4, ge=0)     # m moved before the grids take a scan
    map_update_angle_thresh: float = param(0.9, ge=0)        # rad turned before the grids take a scan
    laser_min_dist: float = param(0.4, ge=0)                 # m: nearer returns are dropped
    laser_max_dist: float = param(30.0, gt=0)                # m: farther returns are dropped
    # how firmly odometry's guess holds the match: weights per m² and rad² beside the scan's sum of
    # squared (1 − occupancy). Off: on MIT CSAIL, odometry's glitches made 100 / 400 cost 0.28 m
    guess_weight_xy: float = param(0.0, ge=0)
    guess_weight_yaw: float = param(0.0, ge=0)
    predict_motion: bool = True                              # start from the last motion repeated (hector: the last pose)
    search_angle: float = param(0.3, ge=0)                   # rad: also start turned by ± this, keep the best match


class HectorMapper:
    """`step(points)` matches a scan's end points (N, 2, robot frame) and updates the grids; `pose`
    is the robot's in the map frame, where the first scan is taken at `start` (the grids centred
    there as map_start_x / map_start_y say)."""

    def __init__(self, params: HectorParams = HectorParams(), start=(0.0, 0.0, 0.0)):
        self.params = params
        self.pose = np.asarray(start, np.float64)[:3].copy()
        self.infos, self.log_odds, self._probability, self._marks = [], [], [], []
        for level in range(params.map_multi_res_levels):
            resolution, size = params.map_resolution * 2 ** level, params.map_size // 2 ** level
            origin = Pose2D(self.pose[0] - params.map_start_x * size * resolution,
                            self.pose[1] - params.map_start_y * size * resolution, 0.0)
            self.infos.append(MapMetaData(resolution=resolution, width=size, height=size, origin=origin))
            self.log_odds.append(np.zeros((size, size), np.float32))
            self._probability.append(np.full((size, size), 0.5, np.float32))
            self._marks.append(np.zeros((size, size), np.int32))
        self._updated_at: np.ndarray | None = None
        self._scans_integrated = 0
        self._previous: np.ndarray | None = None
        self._matched: np.ndarray | None = None     # the end points of the last scan matched
        p = params
        self.free_update = math.log(p.update_factor_free / (1 - p.update_factor_free))     # what a beam passing a cell adds to it (< 0)
        self.occupied_update = math.log(p.update_factor_occupied / (1 - p.update_factor_occupied))

    @property
    def updates(self) -> int:
        """Scans the grids have taken."""
        return self._scans_integrated

    def probabilities(self) -> list[tuple[np.ndarray, MapMetaData]]:
        """The grids as occupancy probabilities, finest first."""
        return list(zip(self._probability, self.infos))

    def step(self, points: np.ndarray, guess=None) -> np.ndarray:
        """Match a scan (end points (N, 2) in the robot frame; `guess` a pose from odometry, or None)
        and update the grids when the robot has moved enough."""
        points = self.in_range(points)
        if self._updated_at is not None:
            self.place(self.best_match(points, guess), points)
        if self.moved():
            self.integrate(points)
        return self.pose

    def in_range(self, points: np.ndarray) -> np.ndarray:
        """The end points (N, 2, robot frame) between laser_min_dist and laser_max_dist of the robot."""
        p = self.params
        points = np.asarray(points, np.float64).reshape(-1, 2)
        reach = np.hypot(points[:, 0], points[:, 1])
        return points[(reach >= p.laser_min_dist) & (reach <= p.laser_max_dist)]

    def best_match(self, points: np.ndarray, guess=None) -> np.ndarray:
        """The pose of the lowest cost among the matches from each start (`_starts`) of end points
        already in range; changes nothing."""
        p = self.params
        levels = self.probabilities()
        weights = (p.guess_weight_xy, p.guess_weight_xy, p.guess_weight_yaw)
        matches = [match(levels, points, start, prior=guess, prior_weights=weights) for start in self._starts(guess)]
        return min(matches, key=lambda pose: mismatch(*levels[0], points, pose))

    def place(self, pose, matched: np.ndarray | None = None) -> None:
        """The robot is at `pose` now: the match of the end points `matched`, or None when it was
        not matched (then covariance() is zeros until the next match)."""
        self._previous, self.pose = self.pose, np.asarray(pose, np.float64)[:3].copy()
        self._matched = matched

    def integrate(self, points: np.ndarray) -> None:
        """The end points (in range) into the grids, from the current pose."""
        self._update(points)
        self._updated_at = self.pose.copy()

    def clear_unconfirmed(self, confirmed: float) -> int:
        """Cells the last scan's beams crossed and ended in none of that held less than `confirmed` of
        log-odds: free, one free update's worth, as if they had never been hit. What a moving body
        left in the map goes at the next scan, not after the dozen scans hector's slow clearing
        takes; a wall hit by enough scans is kept. Returns the cells cleared, every grid."""
        crossed_mark = 2 * self._scans_integrated - 1      # _integrate's mark − 1: freed in that scan
        free_probability = 1.0 / (1.0 + math.exp(-self.free_update))
        cleared = 0
        for log_odds, probability, marks in zip(self.log_odds, self._probability, self._marks):
            ghost = (marks == crossed_mark) & (log_odds > self.free_update) & (log_odds < confirmed)
            log_odds[ghost], probability[ghost] = self.free_update, free_probability
            cleared += int(np.count_nonzero(ghost))
        return cleared

    def moved(self) -> bool:
        """Whether the robot has moved map_update_distance_thresh or turned map_update_angle_thresh
        since the grids last took a scan (True before any)."""
        p, last = self.params, self._updated_at
        if last is None:
            return True
        return (math.hypot(*(self.pose[:2] - last[:2])) > p.map_update_distance_thresh
                or abs(float(wrap_angle(self.pose[2] - last[2]))) > p.map_update_angle_thresh)

    def recentre(self, x: float, y: float) -> bool:
        """Roll the grids, a window that follows the robot: shift them by whole cells of the coarsest
        grid (so every level stays aligned with the others) until (x, y) lies where map_start_x /
        map_start_y put the start. What leaves the window is forgotten, what enters is unknown.
        False when (x, y) is already within a coarsest cell of that place."""
        p, coarsest = self.params, self.infos[-1]
        shift = [round((x - coarsest.origin.x) / coarsest.resolution - p.map_start_x * coarsest.width),
                 round((y - coarsest.origin.y) / coarsest.resolution - p.map_start_y * coarsest.height)]
        if shift == [0, 0]:
            return False
        for level, info in enumerate(self.infos):
            cells = 2 ** (len(self.infos) - 1 - level)
            cols, rows = shift[0] * cells, shift[1] * cells
            self.log_odds[level] = _shifted(self.log_odds[level], rows, cols, 0.0)
            self._probability[level] = _shifted(self._probability[level], rows, cols, 0.5)
            self._marks[level] = _shifted(self._marks[level], rows, cols, 0)
            origin = Pose2D(info.origin.x + cols * info.resolution, info.origin.y + rows * info.resolution, 0.0)
            self.infos[level] = MapMetaData(resolution=info.resolution, width=info.width, height=info.height,
                                            origin=origin)
        return True

    def occupancy_grid(self, occ_thresh: float) -> OccupancyGrid:
        """The finest grid, cropped to the cells beams have reached (OccupancyGrid values as the
        filter's maps)."""
        rows, cols = np.nonzero(self._marks[0])
        r0, r1, c0, c1 = (rows.min(), rows.max() + 1, cols.min(), cols.max() + 1) if len(rows) else (0, 1, 0, 1)
        info = self.infos[0]
        data = occupancy_data(self.log_odds[0][r0:r1, c0:c1], occ_thresh)
        origin = Pose2D(info.origin.x + c0 * info.resolution, info.origin.y + r0 * info.resolution, 0.0)
        return OccupancyGrid(header=Header(frame_id="map"), info=MapMetaData(
            resolution=info.resolution, width=data.shape[1], height=data.shape[0], origin=origin), data=data)

    def covariance(self) -> np.ndarray:
        """The last match's pose covariance, Gauss-Newton's: the cost per end point times H⁻¹ at the
        finest grid (zeros before the first match or where H is singular)."""
        if self._matched is None:
            return np.zeros((3, 3))
        return pose_covariance(*self.probabilities()[0], self._matched, self.pose)

    def _starts(self, guess) -> list[np.ndarray]:
        """Where matches start: the last pose (hector_mapping's only start) and it turned by
        ±search_angle, the last motion repeated from it, and odometry's guess."""
        turn = self.params.search_angle
        starts = [self.pose] + ([self.pose + (0.0, 0.0, turn), self.pose - (0.0, 0.0, turn)] if turn > 0 else [])
        if self.params.predict_motion and self._previous is not None:
            starts.append(compose(self.pose, relative(self._previous, self.pose)))
        if guess is not None:
            starts.append(np.asarray(guess, np.float64)[:3])
        return starts

    def _update(self, points: np.ndarray) -> None:
        x, y, th = self.pose
        c, s = math.cos(th), math.sin(th)
        ends_x, ends_y = x + c * points[:, 0] - s * points[:, 1], y + s * points[:, 0] + c * points[:, 1]
        self._scans_integrated += 1
        for log_odds, probability, marks, info in zip(self.log_odds, self._probability, self._marks, self.infos):
            u0, v0 = grid_coords(info, x, y)
            us, vs = grid_coords(info, ends_x, ends_y)
            longest = int(np.max(np.abs(us - u0) + np.abs(vs - v0), initial=0.0)) + 3
            _integrate(log_odds, probability, marks, 2 * self._scans_integrated, float(u0), float(v0),
                       np.ascontiguousarray(us), np.ascontiguousarray(vs), self.free_update, self.occupied_update,
                       np.empty(longest, np.int64), np.empty(longest, np.int64))


def _shifted(grid: np.ndarray, rows: int, cols: int, fill) -> np.ndarray:
    """The grid moved so that new[r, c] = old[r + rows, c + cols], `fill` where old has no cell."""
    out = np.full_like(grid, fill)
    height, width = grid.shape
    if abs(rows) < height and abs(cols) < width:
        out[max(-rows, 0):height - max(rows, 0), max(-cols, 0):width - max(cols, 0)] = \
            grid[max(rows, 0):height - max(-rows, 0), max(cols, 0):width - max(-cols, 0)]
    return out


@njit(cache=True, _nrt=False)
def _integrate(log_odds, probability, marks, mark, u0, v0, us, vs, free, occupied, rows, cols):
    """One scan into a grid, as hector_mapping does it: every cell changes at most once a scan —
    crossed by beams, it takes `free` once; holding a beam's end, `occupied` once, which undoes a
    `free` it took in the same scan (mark − 1 marks a cell freed in this scan, mark one hit).
    Without that, beams grazing a wall clear the cells other beams of the same scan end in."""
    height, width = log_odds.shape
    for b in range(us.shape[0]):
        n = segment_cells(u0, v0, us[b], vs[b], rows, cols)
        for i in range(n):
            row, col = rows[i], cols[i]
            if row < 0 or col < 0 or row >= height or col >= width:
                continue
            value = log_odds[row, col]
            if i < n - 1 and marks[row, col] < mark - 1:
                value += free
                marks[row, col] = mark - 1
            elif i == n - 1 and marks[row, col] < mark:
                value += occupied - free if marks[row, col] == mark - 1 else occupied
                marks[row, col] = mark
            else:
                continue
            value = min(max(value, -LOG_ODDS_LIMIT), LOG_ODDS_LIMIT)
            log_odds[row, col] = value
            probability[row, col] = 1.0 / (1.0 + math.exp(-value))


class HectorSlam:
    """HectorMapper behind the slam node's core interface (Rbpf's): `process` takes a scan's ranges
    and, when odometry is used, the odometry pose at its stamp — only for the first guess."""

    def __init__(self, params: HectorParams, angles, range_max: float, laser=(0.0, 0.0, 0.0), start=(0.0, 0.0, 0.0)):
        self.mapper = HectorMapper(params, start)
        self.laser = np.asarray(laser, np.float64)
        self.angles = np.asarray(angles, np.float64) + self.laser[2]
        self.max_range = float(range_max) - 0.01      # a return at range_max is no return (the filter's rule)
        self._odom: np.ndarray | None = None

    @property
    def updates(self) -> int:
        return self.mapper.updates

    def process(self, stamp_ns: int, odom_pose, ranges) -> None:
        """One scan (`stamp_ns` unused: hector keeps no time), with the odometry pose at its stamp or None."""
        ranges = np.asarray(ranges, np.float64)
        seen = np.isfinite(ranges) & (ranges < self.max_range)
        r, a = ranges[seen], self.angles[seen]
        points = np.column_stack([self.laser[0] + r * np.cos(a), self.laser[1] + r * np.sin(a)])
        odom = None if odom_pose is None else np.asarray(odom_pose, np.float64)
        guess = None if odom is None or self._odom is None else compose(self.mapper.pose, relative(self._odom, odom))
        self.mapper.step(points, guess)
        self._odom = odom

    def pose(self) -> np.ndarray:
        return self.mapper.pose.copy()

    def map_to_odom(self) -> np.ndarray | None:
        """The map → odom transform, None without odometry."""
        return None if self._odom is None else compose(self.mapper.pose, inverse(self._odom))

    def covariance(self) -> np.ndarray:
        return self.mapper.covariance()

    def occupancy_grid(self, occ_thresh: float) -> OccupancyGrid:
        return self.mapper.occupancy_grid(occ_thresh)
