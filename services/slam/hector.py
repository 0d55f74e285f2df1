"""Hector mapping (Kohlbrecher et al. 2011) as a pure core: occupancy grids at several resolutions,
each scan matched to them coarse to fine (hector_match.py) without odometry — a pose from
odometry, when given, is the first guess and a weak prior that holds the match along corridors — and the grids updated from the matched pose once
the robot has moved map_update_distance_thresh or turned map_update_angle_thresh since the last
update (hector_mapping's parameter names and defaults).

Each grid holds log-odds: the cells a beam crosses take log(update_factor_free / (1 −
update_factor_free)), the cell it ends in log(update_factor_occupied / (1 − …)), clipped to
±LOG_ODDS_LIMIT so a cell seen wrong can still change. Pure: numpy and the slam service's cell
traversal (particle_grids.segment_cells).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ...geometry.grid import grid_coords
from ...geometry.se2 import wrap_angle
from ...parameters.declare import Parameters, param
from ...schemas.messages import MapMetaData, Pose2D
from .hector_match import match
from .particle_grids import segment_cells

LOG_ODDS_LIMIT = 10.0


@dataclass(frozen=True)
class HectorParams(Parameters):
    """hector_mapping's names; its defaults, but for map_size, kept to what a room needs."""
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
    iterations: int = param(10, ge=1)                        # Gauss-Newton steps a level
    # how firmly a guess (odometry's) holds the match: weights per m² and rad² beside the scan's
    # sum of squared (1 − occupancy); ours, hector has none
    guess_weight_xy: float = param(100.0, ge=0)
    guess_weight_yaw: float = param(400.0, ge=0)


class HectorMapper:
    """`step(points)` matches a scan's end points (N, 2, robot frame) and updates the grids; `pose`
    is the robot's in the map frame, which starts at the first scan's pose (0, 0, 0)."""

    def __init__(self, params: HectorParams = HectorParams()):
        self.params = params
        self.infos, self.log_odds = [], []
        for level in range(params.map_multi_res_levels):
            resolution, size = params.map_resolution * 2 ** level, params.map_size // 2 ** level
            origin = Pose2D(-params.map_start_x * size * resolution, -params.map_start_y * size * resolution, 0.0)
            self.infos.append(MapMetaData(resolution=resolution, width=size, height=size, origin=origin))
            self.log_odds.append(np.zeros((size, size)))
        self.pose = np.zeros(3)
        self._updated_at: np.ndarray | None = None
        p = params
        self._free = math.log(p.update_factor_free / (1 - p.update_factor_free))
        self._occupied = math.log(p.update_factor_occupied / (1 - p.update_factor_occupied))

    def probabilities(self) -> list[tuple[np.ndarray, MapMetaData]]:
        """The grids as occupancy probabilities, finest first."""
        return [(1.0 / (1.0 + np.exp(-grid)), info) for grid, info in zip(self.log_odds, self.infos)]

    def step(self, points: np.ndarray, guess=None) -> np.ndarray:
        """Match a scan (end points (N, 2) in the robot frame; `guess` a first guess of the pose,
        the last pose when None) and update the grids when the robot has moved enough."""
        points = np.asarray(points, np.float64).reshape(-1, 2)
        reach = np.hypot(points[:, 0], points[:, 1])
        points = points[(reach >= self.params.laser_min_dist) & (reach <= self.params.laser_max_dist)]
        if self._updated_at is not None:
            p = self.params
            self.pose = match(self.probabilities(), points, self.pose if guess is None else guess, p.iterations,
                              guess, (p.guess_weight_xy, p.guess_weight_xy, p.guess_weight_yaw))
        if self._updated_at is None or self._moved():
            self._update(points)
            self._updated_at = self.pose.copy()
        return self.pose

    def _moved(self) -> bool:
        p, last = self.params, self._updated_at
        return (math.hypot(*(self.pose[:2] - last[:2])) > p.map_update_distance_thresh
                or abs(float(wrap_angle(self.pose[2] - last[2]))) > p.map_update_angle_thresh)

    def _update(self, points: np.ndarray) -> None:
        x, y, th = self.pose
        c, s = math.cos(th), math.sin(th)
        ends_x, ends_y = x + c * points[:, 0] - s * points[:, 1], y + s * points[:, 0] + c * points[:, 1]
        for grid, info in zip(self.log_odds, self.infos):
            u0, v0 = grid_coords(info, x, y)
            us, vs = grid_coords(info, ends_x, ends_y)
            longest = int(np.max(np.abs(us - u0) + np.abs(vs - v0), initial=0.0)) + 3
            rows, cols = np.empty(longest, np.int64), np.empty(longest, np.int64)
            height, width = grid.shape
            for u1, v1 in zip(us, vs):
                n = segment_cells(float(u0), float(v0), float(u1), float(v1), rows, cols)
                inside = (rows[:n] >= 0) & (rows[:n] < height) & (cols[:n] >= 0) & (cols[:n] < width)
                free = inside.copy()
                free[n - 1] = False
                grid[rows[:n][free], cols[:n][free]] += self._free
                if inside[n - 1]:
                    grid[rows[n - 1], cols[n - 1]] += self._occupied
            np.clip(grid, -LOG_ODDS_LIMIT, LOG_ODDS_LIMIT, out=grid)
