"""Laser models of ROS amcl (amcl_laser.cpp): beam, likelihood_field, likelihood_field_prob.

The map is read as amcl reads it: occupancy 100 is an obstacle, 0 is free, anything else is
unknown. The likelihood field is the distance from each cell to the nearest obstacle cell
(scipy's exact Euclidean distance transform), clipped at laser_likelihood_max_dist, turned into
the hit term exp(−d²/2σ_hit²) once per map. An end point off the map counts as max distance.

Weights, per particle, over the used beams (amcl's "ad-hoc" combination, kept for equal behaviour):
- likelihood_field: pz = z_hit·exp(−d²/2σ²) + z_rand/range_max, weight ×= 1 + Σ pz³; max-range
  and NaN readings are ignored.
- likelihood_field_prob: the same pz, weight ×= Π pz; with do_beamskip (only once the filter has
  converged) a beam counts only where more than beam_skip_threshold of the particles see its end
  point within beam_skip_distance of an obstacle — unless at least beam_skip_error_threshold of
  the beams would go, which means the filter converged wrongly, and then all beams count.
- beam: the expected range is cast through the map (unknown cells block, as in amcl), and
  pz = z_hit·exp(−(z−ẑ)²/2σ²) + z_short·λe^{−λz} (z < ẑ) + z_max (z = range_max) + z_rand/range_max
  (z < range_max); weight ×= 1 + Σ pz³.

Beams are picked as amcl picks them: every ((count − 1) // (laser_max_beams − 1))-th beam, or for
likelihood_field_prob every ceil(count / laser_max_beams)-th. Readings at or below the minimum
range become range_max (amcl has no notion of too-close); readings beyond range_max are ignored.

Particle poses are mapped into grid coordinates by an affine map derived from geometry.grid.grid_coords,
so maps with a yawed origin (the Stata basement) work without special cases.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit

from ...schemas.messages import LaserScan, OccupancyGrid
from ...geometry.distance import distances_to
from ...geometry.raycast import cast_grid
from ...geometry.grid import grid_coords
from .params import AmclParams, BeamModelParams, LikelihoodFieldProbParams

OCCUPIED, FREE = 100, 0  # amcl's map conversion: everything else is unknown


@dataclass(frozen=True)
class GridFrame:
    """World (map-frame) metres to continuous grid coordinates (u along columns, v along rows)."""

    affine: np.ndarray   # (2, 3): (u, v) = affine @ (x, y, 1)
    yaw: float           # direction of the grid's u axis in the map frame

    @classmethod
    def of(cls, grid: OccupancyGrid) -> GridFrame:
        u, v = grid_coords(grid.info, np.array([0.0, 1.0, 0.0]), np.array([0.0, 0.0, 1.0]))
        affine = np.array([[u[1] - u[0], u[2] - u[0], u[0]], [v[1] - v[0], v[2] - v[0], v[0]]])
        return cls(affine=affine, yaw=float(grid.info.origin.theta))


@dataclass(frozen=True)
class ScanBeams:
    """The beams of one scan that the model uses, in the robot's base frame."""

    ranges: np.ndarray     # (B,) m: short readings set to range_max, NaN kept (ignored)
    bearings: np.ndarray   # (B,) rad, beam directions in the base frame
    origin: tuple[float, float]  # the laser's position in the base frame
    range_max: float

    def end_points(self) -> tuple[np.ndarray, np.ndarray]:
        """Base-frame end points of the beams the likelihood field uses (range below range_max)."""
        use = self.ranges < self.range_max  # False for NaN too
        r, a = self.ranges[use], self.bearings[use]
        return self.origin[0] + r * np.cos(a), self.origin[1] + r * np.sin(a)


def beam_step(count: int, params: AmclParams) -> int:
    if params.laser_model_type == "likelihood_field_prob":
        return max(1, math.ceil(count / params.laser_max_beams))
    return max(1, (count - 1) // (params.laser_max_beams - 1))


def prepare_scan(ranges, angle_min: float, angle_increment: float, range_min: float, range_max: float,
                 params: AmclParams, laser_pose=(0.0, 0.0, 0.0)) -> ScanBeams:
    """The used beams of a scan taken by a laser at `laser_pose` (x, y, yaw) in the base frame."""
    ranges = np.asarray(ranges, np.float64)
    if params.laser_max_range > 0:
        range_max = min(range_max, params.laser_max_range)
    if params.laser_min_range > 0:
        range_min = max(range_min, params.laser_min_range)
    if not range_max > 0 or range_min < 0:
        raise ValueError(f"scan range_min {range_min} / range_max {range_max}: need 0 ≤ range_min, 0 < range_max")
    picked = np.arange(0, ranges.size, beam_step(ranges.size, params))
    used = ranges[picked]
    with np.errstate(invalid="ignore"):
        used = np.where(used <= range_min, range_max, used)
        used = np.where(used > range_max, np.inf, used)
    x, y, yaw = (float(v) for v in laser_pose)
    bearings = yaw + angle_min + picked * angle_increment
    return ScanBeams(ranges=used, bearings=bearings, origin=(x, y), range_max=float(range_max))


def scan_beams(scan: LaserScan, params: AmclParams, laser_pose=(0.0, 0.0, 0.0)) -> ScanBeams:
    return prepare_scan(scan.ranges, scan.angle_min, scan.angle_increment, scan.range_min, scan.range_max,
                        params, laser_pose)


def share_near_obstacles(distance: np.ndarray, affine: np.ndarray, pose, end_x: np.ndarray, end_y: np.ndarray,
                         near_m: float) -> float:
    """The share of base-frame end points that lie, for a robot at `pose`, on a cell whose `distance`
    (m to the nearest obstacle) is at most near_m; off the map counts as not near. NaN without points."""
    if len(end_x) == 0:
        return float("nan")
    x, y, theta = pose
    c, s = math.cos(theta), math.sin(theta)
    wx, wy = x + c * end_x - s * end_y, y + s * end_x + c * end_y
    col = np.floor(affine[0, 0] * wx + affine[0, 1] * wy + affine[0, 2]).astype(np.int64)
    row = np.floor(affine[1, 0] * wx + affine[1, 1] * wy + affine[1, 2]).astype(np.int64)
    height, width = distance.shape
    inside = (row >= 0) & (row < height) & (col >= 0) & (col < width)
    near = distance[np.clip(row, 0, height - 1), np.clip(col, 0, width - 1)] <= near_m
    return float(np.mean(near & inside))


# ---------------------------------------------------------------- kernels

@njit(cache=True)
def _grid_pose(affine, x, y, theta):
    """Grid position of a particle and the 2×2 map taking base-frame metres to grid cells."""
    u = affine[0, 0] * x + affine[0, 1] * y + affine[0, 2]
    v = affine[1, 0] * x + affine[1, 1] * y + affine[1, 2]
    c, s = math.cos(theta), math.sin(theta)
    # affine's linear part times the particle's rotation
    m00 = affine[0, 0] * c + affine[0, 1] * s
    m01 = -affine[0, 0] * s + affine[0, 1] * c
    m10 = affine[1, 0] * c + affine[1, 1] * s
    m11 = -affine[1, 0] * s + affine[1, 1] * c
    return u, v, m00, m01, m10, m11


@njit(cache=True)
def _likelihood_field(poses, n, affine, end_x, end_y, hit, off_map_hit, z_hit, z_rand_term, weights):
    height, width = hit.shape
    total = 0.0
    for i in range(n):
        u, v, m00, m01, m10, m11 = _grid_pose(affine, poses[i, 0], poses[i, 1], poses[i, 2])
        p = 1.0
        for b in range(end_x.shape[0]):
            col = int(math.floor(u + m00 * end_x[b] + m01 * end_y[b]))
            row = int(math.floor(v + m10 * end_x[b] + m11 * end_y[b]))
            if 0 <= row < height and 0 <= col < width:
                g = hit[row, col]
            else:
                g = off_map_hit
            pz = z_hit * g + z_rand_term
            p += pz * pz * pz
        weights[i] *= p
        total += weights[i]
    return total


@njit(cache=True)
def _likelihood_field_prob(poses, n, affine, end_x, end_y, hit, off_map_hit, z_hit, z_rand_term,
                           beamskip, agree_hit, skip_threshold, skip_error_threshold, scratch, weights):
    """Product of pz over beams; with `beamskip`, per-beam agreement decides which beams count.

    `agree_hit` is the hit term at beam_skip_distance: an in-map end point with a larger hit term
    lies closer than that to an obstacle. `scratch` (≥ n × beams) keeps pz between the two passes.
    Returns (total weight, beams skipped)."""
    height, width = hit.shape
    beams = end_x.shape[0]
    agree = np.zeros(beams, np.int64)
    total = 0.0
    for i in range(n):
        u, v, m00, m01, m10, m11 = _grid_pose(affine, poses[i, 0], poses[i, 1], poses[i, 2])
        log_p = 0.0
        for b in range(beams):
            col = int(math.floor(u + m00 * end_x[b] + m01 * end_y[b]))
            row = int(math.floor(v + m10 * end_x[b] + m11 * end_y[b]))
            if 0 <= row < height and 0 <= col < width:
                g = hit[row, col]
                if g > agree_hit:
                    agree[b] += 1
            else:
                g = off_map_hit
            pz = z_hit * g + z_rand_term
            if beamskip:
                scratch[i * beams + b] = pz
            else:
                log_p += math.log(pz)
        if not beamskip:
            weights[i] *= math.exp(log_p)
            total += weights[i]
    if not beamskip:
        return total, 0
    skipped = 0
    keep = np.empty(beams, np.bool_)
    for b in range(beams):
        keep[b] = agree[b] > skip_threshold * n
        if not keep[b]:
            skipped += 1
    if skipped >= skip_error_threshold * beams:  # most beams disagree: the filter is lost, use all
        keep[:] = True
        skipped = 0
    for i in range(n):
        log_p = 0.0
        for b in range(beams):
            if keep[b]:
                log_p += math.log(scratch[i * beams + b])
        weights[i] *= math.exp(log_p)
        total += weights[i]
    return total, skipped


@njit(cache=True)
def _beam(poses, n, affine, yaw, blocked, resolution, origin_x, origin_y, ranges, bearings, range_max,
          z_hit, z_short, z_max, z_rand, sigma_hit, lambda_short, weights):
    denom = 2.0 * sigma_hit * sigma_hit
    angles = np.empty(bearings.shape[0])
    total = 0.0
    for i in range(n):
        x, y, theta = poses[i, 0], poses[i, 1], poses[i, 2]
        c, s = math.cos(theta), math.sin(theta)
        lx = x + c * origin_x - s * origin_y
        ly = y + s * origin_x + c * origin_y
        u0 = affine[0, 0] * lx + affine[0, 1] * ly + affine[0, 2]
        v0 = affine[1, 0] * lx + affine[1, 1] * ly + affine[1, 2]
        for b in range(bearings.shape[0]):
            angles[b] = theta - yaw + bearings[b]
        expected = cast_grid(u0, v0, angles, blocked, range_max / resolution)
        p = 1.0
        for b in range(bearings.shape[0]):
            z = ranges[b]
            if not z <= range_max:  # beyond range_max, or NaN: amcl adds nothing for it
                continue
            map_range = min(expected[b] * resolution, range_max)
            pz = z_hit * math.exp(-(z - map_range) ** 2 / denom)
            if z < map_range:
                pz += z_short * lambda_short * math.exp(-lambda_short * z)
            if z == range_max:
                pz += z_max
            else:
                pz += z_rand / range_max
            p += pz * pz * pz
        weights[i] *= p
        total += weights[i]
    return total


# ---------------------------------------------------------------- the model

class LaserModel:
    """The laser model of `params.laser_model_type` on one map; the field is built once here."""

    def __init__(self, grid: OccupancyGrid, params: AmclParams):
        self.params = params
        self.model = params.laser_params()    # the model's own group (BeamModelParams, LikelihoodField*Params)
        self.frame = GridFrame.of(grid)
        self.resolution = float(grid.info.resolution)
        data = np.asarray(grid.data)
        occupied = data == OCCUPIED
        if occupied.any():
            cells = distances_to(occupied)
            distance = np.minimum(cells * self.resolution, params.laser_likelihood_max_dist)
        else:
            distance = np.full(data.shape, params.laser_likelihood_max_dist)
        self.distance = distance.astype(np.float32)       # m to the nearest obstacle, clipped
        self.hit = np.ascontiguousarray(self._hit_term(distance), np.float32)
        self.off_map_hit = float(self._hit_term(params.laser_likelihood_max_dist))
        self.agree_hit = float(self._hit_term(params.beam_skip_distance))
        self.blocked = np.ascontiguousarray(data != FREE)   # what stops a cast ray (beam model)
        self._scratch = np.empty(0)
        self.beams_skipped = 0   # by the last likelihood_field_prob update with beam skipping

    def beam_fit(self, pose, scan: ScanBeams) -> tuple[float, int]:
        """The share of the scan's end points within beam_fit_distance of an obstacle, seen from `pose`
        (how well the scan agrees with the map there; NaN when no beam returned), and their count."""
        end_x, end_y = scan.end_points()
        return (share_near_obstacles(self.distance, self.frame.affine, pose, end_x, end_y,
                                     self.params.beam_fit_distance), len(end_x))

    def _hit_term(self, distance):
        return np.exp(-np.square(distance) / (2.0 * self.params.laser_sigma_hit ** 2))

    def weigh(self, poses: np.ndarray, n: int, scan: ScanBeams, weights: np.ndarray, converged: bool = False) -> float:
        """Multiply weights[:n] by each particle's scan likelihood; returns their new sum."""
        m, frame = self.model, self.frame
        if isinstance(m, BeamModelParams):
            return _beam(poses, n, frame.affine, frame.yaw, self.blocked, self.resolution, scan.origin[0],
                         scan.origin[1], scan.ranges, scan.bearings, scan.range_max, m.laser_z_hit,
                         m.laser_z_short, m.laser_z_max, m.laser_z_rand, m.laser_sigma_hit,
                         m.laser_lambda_short, weights)
        end_x, end_y = scan.end_points()
        z_rand_term = m.laser_z_rand / scan.range_max
        if not isinstance(m, LikelihoodFieldProbParams):
            return _likelihood_field(poses, n, frame.affine, end_x, end_y, self.hit, self.off_map_hit,
                                     m.laser_z_hit, z_rand_term, weights)
        beamskip = m.do_beamskip and converged
        if beamskip and self._scratch.size < n * end_x.size:
            self._scratch = np.empty(n * end_x.size)
        total, self.beams_skipped = _likelihood_field_prob(
            poses, n, frame.affine, end_x, end_y, self.hit, self.off_map_hit, m.laser_z_hit,
            z_rand_term, beamskip, self.agree_hit, m.beam_skip_threshold, m.beam_skip_error_threshold,
            self._scratch, weights)
        return total


def warm_up() -> None:
    """Compile (or load from cache) every laser kernel."""
    params = AmclParams()
    grid = OccupancyGrid()
    grid.data = np.zeros((2, 2), np.int8)
    grid.data[0, 0] = OCCUPIED      # so the field's distance transform is loaded too
    grid.info.width = grid.info.height = 2
    scan = prepare_scan(np.ones(3), -1.0, 1.0, 0.1, 5.0, params)
    poses, weights = np.zeros((1, 3)), np.ones(1)
    for model in ("beam", "likelihood_field", "likelihood_field_prob"):
        for beamskip in (False, True):
            laser = LaserModel(grid, AmclParams(laser_model_type=model, do_beamskip=beamskip))
            laser.weigh(poses, 1, scan, weights, converged=True)
