"""The simulated 2-D lidar: ray casting against a World, then the sensor model (noise, dropouts).

Rays are cast against the world's segments and circles (the movers are passed per call as more
circles) and, for a world with a map, through its occupancy grid by grid traversal (Amanatides &
Woo): the range is where the ray enters the first obstacle cell. Beam i points at
angle_min + i·angle_increment, counter-clockwise in the laser frame, as in sensor_msgs/LaserScan.
Ranges follow REP 117: +inf for no return within range_max (and for dropouts), −inf for an
obstacle closer than range_min.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..schemas.messages import Header, LaserScan
from ..geometry.frames import LASER_MOUNT
from ..geometry.grid import grid_coords
from ..geometry.raycast import cast_grid, cast_shapes
from .world import World
from ..parameters.declare import Parameters, Rule, param

FULL_CIRCLE = 2.0 * math.pi


@dataclass(frozen=True)
class LidarParams(Parameters):
    """A scanner like an RPLIDAR-class 2-D lidar. angle_min None means a centred field of view
    (−fov/2). A full-circle scan spaces its beams fov/beams apart (no beam twice at ±π); a partial
    one fov/(beams − 1), so its last beam lies at angle_min + fov."""

    beams: int = param(360, ge=1)
    fov: float = param(FULL_CIRCLE, gt=0, le=FULL_CIRCLE + 1e-9)  # rad
    angle_min: float | None = None                              # rad, laser frame
    range_min: float = param(0.15, ge=0)                        # m
    range_max: float = param(12.0, finite=True)                 # m
    noise_std: float = param(0.01, ge=0)                        # m, Gaussian range noise
    dropout_prob: float = param(0.0, ge=0, le=1)                # chance that a beam returns nothing
    mount_x: float = LASER_MOUNT[0]                             # laser pose in the robot frame (m, m, rad)
    mount_y: float = LASER_MOUNT[1]
    mount_yaw: float = LASER_MOUNT[2]
    rate_hz: float = param(10.0, gt=0)

    def __post_init__(self):
        super().__post_init__()
        if self.angle_min is None:
            object.__setattr__(self, "angle_min", -self.fov / 2)

    rules = (Rule("range_max", lambda p: p.range_max > p.range_min, "> range_min ({p.range_min})"),)

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


def laser_pose(pose, params: LidarParams) -> tuple[float, float, float]:
    """The laser's world pose for a robot pose (x, y, yaw)."""
    x, y, yaw = (float(v) for v in pose)
    c, s = math.cos(yaw), math.sin(yaw)
    return (x + c * params.mount_x - s * params.mount_y, y + s * params.mount_x + c * params.mount_y,
            yaw + params.mount_yaw)


def cast(world: World, x: float, y: float, angles: np.ndarray, mover_circles: np.ndarray | None = None,
         max_range: float = np.inf) -> np.ndarray:
    """Exact distances from (x, y) along world-frame `angles` to the first obstacle (inf: none
    within max_range)."""
    angles = np.ascontiguousarray(angles, np.float64)
    segments = np.ascontiguousarray(world.segments, np.float64).reshape(-1, 4)
    circles = np.ascontiguousarray(world.obstacle_circles(mover_circles), np.float64).reshape(-1, 3)
    ranges = cast_shapes(float(x), float(y), angles, segments, circles, float(max_range))
    if world.grid_occupied is not None:
        info = world.grid.info
        u0, v0 = grid_coords(info, x, y)
        cells = cast_grid(float(u0), float(v0), angles - info.origin.theta,
                           np.ascontiguousarray(world.grid_occupied), float(max_range) / info.resolution)
        ranges = np.minimum(ranges, cells * info.resolution)
    return ranges


def sensor_model(true_ranges: np.ndarray, params: LidarParams, rng: np.random.Generator | None) -> np.ndarray:
    """Measured ranges from true ones: Gaussian noise (kept within [range_min, range_max]),
    −inf closer than range_min, dropouts as +inf. Draws a full batch from `rng` per effect."""
    if rng is None and (params.noise_std > 0 or params.dropout_prob > 0):
        raise ValueError("noise or dropout needs a numpy Generator")
    ranges = np.array(true_ranges, np.float64)
    hit = np.isfinite(ranges)
    if params.noise_std > 0:
        noise = rng.normal(0.0, params.noise_std, ranges.shape)
        ranges[hit] = np.clip(ranges[hit] + noise[hit], params.range_min, params.range_max)
    ranges[hit & (np.asarray(true_ranges) < params.range_min)] = -np.inf
    if params.dropout_prob > 0:
        ranges[rng.random(ranges.shape) < params.dropout_prob] = np.inf
    return ranges


def scan(world: World, pose, mover_circles: np.ndarray | None, params: LidarParams,
         rng: np.random.Generator | None) -> np.ndarray:
    """One scan's ranges (float64, beam order of `params.angles()`) for a robot at `pose`."""
    x, y, yaw = laser_pose(pose, params)
    true = cast(world, x, y, yaw + params.angles(), mover_circles, params.range_max)
    return sensor_model(true, params, rng)


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
    cast_grid(0.5, 0.5, angles, np.zeros((1, 1), np.bool_), 1.0)
