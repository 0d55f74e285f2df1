"""The simulated 2-D lidar: ray casting against a World, then the sensor model.

Rays are cast against the world's segments and circles (the movers are passed per call as more
circles) and, for a world with a map, through its occupancy grid by grid traversal (Amanatides &
Woo): the range is where the ray enters the first obstacle cell. Beam i points at
angle_min + i·angle_increment, counter-clockwise in the laser frame, as in sensor_msgs/LaserScan.
Ranges follow REP 117: +inf for no return within range_max (and for dropouts), −inf for an
obstacle closer than range_min.

The sensor model (every effect but the constant noise is off by default): mixed pixels, where a
beam's footprint straddles an edge; Gaussian noise whose σ grows with range; dropouts, more likely
beyond a rated range and at grazing incidence.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..schemas.messages import Header, LaserScan
from ..geometry.frames import LASER_MOUNT
from ..geometry.grid import grid_coords
from ..geometry.raycast import cast_grid_incidence, cast_shapes
from .world import World
from ..parameters.declare import Parameters, Rule, param

FULL_CIRCLE = 2.0 * math.pi


@dataclass(frozen=True)
class LidarParams(Parameters):
    """A scanner like an RPLIDAR-class 2-D lidar. angle_min None means a centred field of view
    (−fov/2). A full-circle scan spaces its beams fov/beams apart (no beam twice at ±π); a partial
    one fov/(beams − 1), so its last beam lies at angle_min + fov. The sensor model's parameters
    are described in sensor_model."""

    beams: int = param(360, ge=1)
    fov: float = param(FULL_CIRCLE, gt=0, le=FULL_CIRCLE + 1e-9)  # rad
    angle_min: float | None = None                              # rad, laser frame
    range_min: float = param(0.15, ge=0)                        # m
    range_max: float = param(12.0, finite=True)                 # m
    noise_std: float = param(0.01, ge=0)                        # m, Gaussian range noise: σ at range 0
    noise_std_per_m: float = param(0.0, ge=0)                   # σ's growth per m of range
    dropout_prob: float = param(0.0, ge=0, le=1)                # chance that a beam returns nothing
    range_dropout_start: float = param(0.0, ge=0)               # m, the rated range: farther, returns thin out
    range_dropout_prob: float = param(0.0, ge=0, le=1)          # extra chance of none at range_max
    incidence_dropout_start: float = param(0.0, ge=0, lt=math.pi / 2)  # rad off the surface normal
    incidence_dropout_prob: float = param(0.0, ge=0, le=1)      # extra chance of none at grazing (90°)
    beam_divergence: float = param(0.0, ge=0)                   # rad, the footprint's full width
    mixed_pixel_threshold: float = param(0.1, gt=0)             # m, a depth step the footprint straddles
    mixed_pixel_prob: float = param(0.0, ge=0, le=1)            # chance a straddling beam returns between
    mount_x: float = LASER_MOUNT[0]                             # laser pose in the robot frame (m, m, rad)
    mount_y: float = LASER_MOUNT[1]
    mount_yaw: float = LASER_MOUNT[2]
    rate_hz: float = param(10.0, gt=0)

    def __post_init__(self):
        super().__post_init__()
        if self.angle_min is None:
            object.__setattr__(self, "angle_min", -self.fov / 2)

    rules = (Rule("range_max", lambda p: p.range_max > p.range_min, "> range_min ({p.range_min})"),
             Rule("range_dropout_start", lambda p: p.range_dropout_start < p.range_max, "< range_max ({p.range_max})"))

    @property
    def angle_increment(self) -> float:
        if self.fov >= FULL_CIRCLE - 1e-9:
            return self.fov / self.beams
        return self.fov / (self.beams - 1) if self.beams > 1 else 0.0

    @property
    def angle_max(self) -> float:
        return self.angle_min + (self.beams - 1) * self.angle_increment

    def angles(self) -> np.ndarray:
        """Beam angles in the laser frame."""
        return self.angle_min + np.arange(self.beams) * self.angle_increment

    @property
    def noisy(self) -> bool:
        return self.noise_std > 0 or self.noise_std_per_m > 0

    @property
    def drops(self) -> bool:
        return self.dropout_prob > 0 or self.range_dropout_prob > 0 or self.incidence_dropout_prob > 0

    @property
    def mixes(self) -> bool:
        return self.mixed_pixel_prob > 0 and self.beam_divergence > 0


def laser_pose(pose, params: LidarParams) -> tuple[float, float, float]:
    """The laser's world pose for a robot pose (x, y, yaw)."""
    x, y, yaw = (float(v) for v in pose)
    c, s = math.cos(yaw), math.sin(yaw)
    return (x + c * params.mount_x - s * params.mount_y, y + s * params.mount_x + c * params.mount_y,
            yaw + params.mount_yaw)


def cast_with_incidence(world: World, x: float, y: float, angles: np.ndarray,
                        mover_circles: np.ndarray | None = None,
                        max_range: float = np.inf) -> tuple[np.ndarray, np.ndarray]:
    """Exact distances from (x, y) along world-frame `angles` to the first obstacle (inf: none
    within max_range), and the cosine between each ray and the normal of the surface it hits."""
    angles = np.ascontiguousarray(angles, np.float64)
    segments = np.ascontiguousarray(world.segments, np.float64).reshape(-1, 4)
    circles = np.ascontiguousarray(world.obstacle_circles(mover_circles), np.float64).reshape(-1, 3)
    ranges, cosines = cast_shapes(float(x), float(y), angles, segments, circles, float(max_range))
    if world.grid_occupied is not None:
        info = world.grid.info
        u0, v0 = grid_coords(info, x, y)
        cells, cell_cosines = cast_grid_incidence(float(u0), float(v0), angles - info.origin.theta,
                                                  np.ascontiguousarray(world.grid_occupied),
                                                  float(max_range) / info.resolution)
        nearer = cells * info.resolution < ranges
        ranges = np.where(nearer, cells * info.resolution, ranges)
        cosines = np.where(nearer, cell_cosines, cosines)
    return ranges, cosines


def cast(world: World, x: float, y: float, angles: np.ndarray, mover_circles: np.ndarray | None = None,
         max_range: float = np.inf) -> np.ndarray:
    """Exact distances from (x, y) along world-frame `angles` to the first obstacle (inf: none
    within max_range)."""
    return cast_with_incidence(world, x, y, angles, mover_circles, max_range)[0]


def sensor_model(true_ranges: np.ndarray, params: LidarParams, rng: np.random.Generator | None,
                 cos_incidence: np.ndarray | None = None, footprint: np.ndarray | None = None) -> np.ndarray:
    """Measured ranges from true ones, each effect in turn:

    - mixed pixels (`footprint`: the true ranges along the footprint's two edges, shape (2, beams)):
      where the nearest and the farthest of a beam's three ranges differ by more than
      mixed_pixel_threshold, with chance mixed_pixel_prob the beam returns a range uniformly
      between them, as a pulse lit partly near and partly far does;
    - Gaussian noise of σ = noise_std + noise_std_per_m·range, kept within [range_min, range_max];
    - −inf where the range is below range_min;
    - dropouts as +inf, by independent causes: dropout_prob on every beam, a chance rising linearly
      from 0 at range_dropout_start to range_dropout_prob at range_max (a weak echo from far), and
      one rising linearly from 0 at incidence_dropout_start to incidence_dropout_prob at 90° off the
      surface normal (`cos_incidence`: a grazing beam scatters away from the receiver).

    Every effect that is on draws one full batch from `rng`, whatever the ranges, in the order noise,
    dropouts, mixed pixels: a scan takes a fixed number of draws, so a replay reproduces it."""
    if rng is None and (params.noisy or params.drops or params.mixes):
        raise ValueError("noise, dropouts or mixed pixels need a numpy Generator")
    if params.mixes and footprint is None:
        raise ValueError("mixed pixels need the ranges along the footprint's edges")
    if params.incidence_dropout_prob > 0 and cos_incidence is None:
        raise ValueError("incidence dropouts need the incidence cosines")
    true = np.array(true_ranges, np.float64)
    normal = rng.standard_normal(true.shape) if params.noisy else None
    uniform = rng.random(true.shape) if params.drops else None
    mixing = rng.random((2,) + true.shape) if params.mixes else None
    if mixing is not None:
        true = mixed_pixels(true, footprint, mixing, params)
    ranges = true.copy()
    hit = np.isfinite(ranges)
    if normal is not None:
        sigma = params.noise_std + params.noise_std_per_m * ranges[hit]
        ranges[hit] = np.clip(ranges[hit] + sigma * normal[hit], params.range_min, params.range_max)
    ranges[hit & (true < params.range_min)] = -np.inf
    if uniform is not None:
        ranges[uniform < dropout_chance(true, cos_incidence, params)] = np.inf
    return ranges


def mixed_pixels(true: np.ndarray, footprint: np.ndarray, draws: np.ndarray, params: LidarParams) -> np.ndarray:
    """`true` with the mixed returns of sensor_model; draws (2, beams) uniform: which beams, where between."""
    near = np.minimum(true, footprint.min(axis=0))
    far = np.maximum(true, footprint.max(axis=0))
    with np.errstate(invalid="ignore"):   # inf − inf where no edge returns: not straddling
        mixed = np.isfinite(far) & (far - near > params.mixed_pixel_threshold) & (draws[0] < params.mixed_pixel_prob)
    out = true.copy()
    out[mixed] = near[mixed] + draws[1][mixed] * (far[mixed] - near[mixed])
    return out


def dropout_chance(true: np.ndarray, cos_incidence: np.ndarray | None, params: LidarParams) -> np.ndarray:
    """Each beam's chance of no return (see sensor_model)."""
    far = np.clip((true - params.range_dropout_start) / (params.range_max - params.range_dropout_start), 0.0, 1.0)
    returns = 1.0 - params.range_dropout_prob * far
    if params.incidence_dropout_prob > 0:
        off_normal = np.arccos(np.clip(cos_incidence, 0.0, 1.0))
        grazing = np.clip((off_normal - params.incidence_dropout_start) / (math.pi / 2 - params.incidence_dropout_start),
                          0.0, 1.0)
        returns = returns * (1.0 - params.incidence_dropout_prob * grazing)
    # dropout_prob + (1 − dropout_prob)·(the other causes): exactly dropout_prob when they are off
    return params.dropout_prob + (1.0 - params.dropout_prob) * (1.0 - returns)


def scan(world: World, pose, mover_circles: np.ndarray | None, params: LidarParams,
         rng: np.random.Generator | None) -> np.ndarray:
    """One scan's ranges (float64, beam order of `params.angles()`) for a robot at `pose`."""
    x, y, yaw = laser_pose(pose, params)
    angles = yaw + params.angles()
    true, cosines = cast_with_incidence(world, x, y, angles, mover_circles, params.range_max)
    footprint = None
    if params.mixes:
        half = params.beam_divergence / 2
        footprint = np.stack([cast(world, x, y, angles + side * half, mover_circles, params.range_max)
                              for side in (-1.0, 1.0)])
    return sensor_model(true, params, rng, cosines, footprint)


def make_scan(params: LidarParams, ranges: np.ndarray, stamp_ns: int, frame_id: str = "laser") -> LaserScan:
    """The LaserScan message for ranges cast at one instant (time_increment 0)."""
    return LaserScan(header=Header(stamp_ns=stamp_ns, frame_id=frame_id), angle_min=params.angle_min,
                     angle_max=params.angle_max, angle_increment=params.angle_increment,
                     time_increment=0.0, scan_time=1.0 / params.rate_hz, range_min=params.range_min,
                     range_max=params.range_max, ranges=np.asarray(ranges, np.float32))


def warm_up() -> None:
    """Compile (or load from cache) the casting kernels, so the first real scan is not slow."""
    angles = np.zeros(1)
    cast_shapes(0.0, 0.0, angles, np.zeros((1, 4)), np.zeros((1, 3)), 1.0)
    cast_grid_incidence(0.5, 0.5, angles, np.zeros((1, 1), np.bool_), 1.0)
