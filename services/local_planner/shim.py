"""The rotation shim (Nav2's RotationShimController) in front of the primary controller.

DWA samples only forward speeds from min_vel_x and small strafes, so a robot facing away from a new
path drives off on an arc the wrong way (office exploration, seed 0: a path straight east behind a
robot facing west took it south through a door and along the wrong room for 85 s). On a new path
the shim first turns the robot on the spot towards the path point forward_sampling_distance along
it (from the point nearest the robot), while that point lies more than angular_dist_threshold off
the robot's heading; then it hands the path to the primary controller until the next new path
(Nav2's behaviour: it checks once per path). A turn whose swept footprint over simulate_ahead_time
would touch an obstacle is not commanded: the primary controller gets the path at once.

The turn: ω towards the target heading at rotate_to_heading_angular_vel, at most the rate from
which braking at max_angular_accel stops it on the target heading (sqrt(2 · max_angular_accel ·
error), for discrete control periods), so it slows down near alignment instead of overshooting,
and within max_angular_accel · dt of the current turn rate. With the defaults the shim hands over
before it slows down (1 rad/s brakes within 0.16 rad, far inside angular_dist_threshold); the
primary controller brakes the turn within its own window. Poses are (x, y, yaw), twists (vx, vy, wz) in the
robot frame; `path` (N, 3) in the pose's frame.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable

import numpy as np

from ...geometry.se2 import wrap_angle
from .path_ahead import ahead_of
from ...parameters.declare import Parameters, param

SWEEP_STEP = 0.05    # rad between the swept poses checked: a footprint corner 0.55 m out moves half a 5 cm cell


@dataclass(frozen=True)
class RotationShimParams(Parameters):
    """Nav2 RotationShimController's names and defaults."""
    angular_dist_threshold: float = param(0.785, gt=0)       # rad: turn on the spot first while the path is further off
    forward_sampling_distance: float = param(0.5, gt=0)      # m along the path to the point the robot should face
    rotate_to_heading_angular_vel: float = param(1.8, gt=0)  # rad/s
    max_angular_accel: float = param(3.2, gt=0)              # rad/s²
    simulate_ahead_time: float = param(1.0, gt=0)            # s of the turn checked for collisions


@dataclass(frozen=True)
class ShimCommand:
    phase: str               # rotate | aligned (handed over) | blocked (handed over) | off (not armed)
    twist: np.ndarray        # (3,): a turn on the spot while rotating, else zeros
    poses: np.ndarray        # (K, 3) the swept poses checked (rotate, blocked); (0, 3) otherwise


def sampled_point(path: np.ndarray, pose, distance: float) -> np.ndarray:
    """The path point `distance` metres along the path from the point nearest `pose` (the path's end
    when it is shorter)."""
    ahead, along = ahead_of(np.asarray(path, np.float64).reshape(-1, 3), pose)
    return ahead[min(int(np.searchsorted(along, distance)), len(ahead) - 1)]


def heading_error(path: np.ndarray, pose, distance: float) -> float:
    """Signed angle from the robot's heading to the direction of the sampled path point."""
    point = sampled_point(path, pose, distance)
    return float(wrap_angle(math.atan2(point[1] - pose[1], point[0] - pose[0]) - pose[2]))


def turn_rate(params: RotationShimParams, error: float, wz: float, dt: float) -> float:
    """The turn rate towards a heading `error` radians away, from the current rate wz."""
    step = params.max_angular_accel * dt
    # the fastest rate from which braking by `step` per period stops on the target (the discrete
    # sqrt(2 · accel · error)), and no further than the target within this period
    braking = math.sqrt(2.0 * params.max_angular_accel * abs(error) + (step / 2) ** 2) - step / 2
    top = min(params.rotate_to_heading_angular_vel, braking, abs(error) / dt)
    return float(np.clip(math.copysign(top, error), wz - step, wz + step))


def swept_poses(params: RotationShimParams, pose, error: float, wz: float, dt: float) -> np.ndarray:
    """(K, 3) the poses of the turn on the spot that the shim would command over simulate_ahead_time
    (or until it faces the target), at most SWEEP_STEP apart."""
    x, y, yaw = (float(v) for v in pose)
    yaws = [yaw]
    for _ in range(max(1, math.ceil(params.simulate_ahead_time / dt - 1e-9))):
        wz = turn_rate(params, error, wz, dt)
        turn = wz * dt
        if turn * error > 0.0 and abs(turn) >= abs(error):
            turn = error               # the target is reached within this period
        n = max(1, math.ceil(abs(turn) / SWEEP_STEP))
        yaws += list(yaws[-1] + turn * np.arange(1, n + 1) / n)
        error -= turn
        if error == 0.0:
            break
    return np.column_stack([np.full(len(yaws), x), np.full(len(yaws), y), wrap_angle(np.array(yaws))])


class RotationShim:
    """Armed by `new_path`; `step` answers each control tick until it hands over (aligned or blocked)."""

    def __init__(self, params: RotationShimParams, dt: float):
        self.params, self.dt = params, dt
        self.armed = False

    def new_path(self) -> None:
        self.armed = True

    def step(self, pose, velocity, path: np.ndarray,
             legal_poses: Callable[[np.ndarray], np.ndarray]) -> ShimCommand:
        """The answer for the robot at `pose` turning at velocity[2]; `legal_poses` says for poses
        (K, 3) whether the robot may stand at each (the costmap's test)."""
        none = np.zeros((0, 3))
        if not self.armed:
            return ShimCommand("off", np.zeros(3), none)
        error = heading_error(path, pose, self.params.forward_sampling_distance)
        if abs(error) <= self.params.angular_dist_threshold:
            self.armed = False
            return ShimCommand("aligned", np.zeros(3), none)
        poses = swept_poses(self.params, pose, error, float(velocity[2]), self.dt)
        if not np.all(legal_poses(poses)):
            self.armed = False
            return ShimCommand("blocked", np.zeros(3), poses)
        return ShimCommand("rotate", np.array([0.0, 0.0, turn_rate(self.params, error, float(velocity[2]), self.dt)]),
                           poses)
