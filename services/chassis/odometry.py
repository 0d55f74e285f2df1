"""Odometry: encoder increments (and a gyro) integrated exactly into a pose (SE(2) algebra: ../se2.py)."""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ...geometry.se2 import compose, se2_exp
from .kinematics import ChassisParams, Kinematics


@dataclass(frozen=True)
class OdomEstimate:
    stamp_ns: int
    pose: np.ndarray               # (3,) x, y, theta in the odom frame
    twist: np.ndarray              # (3,) vx, vy, wz in the robot frame
    pose_covariance: np.ndarray    # (3, 3) over (x, y, theta)
    twist_covariance: np.ndarray   # (3, 3)
    distance: float                # m driven since the start (path length)
    rotation: float                # rad turned since the start (sum of |dtheta|)


class EncoderOdometry:
    """Dead reckoning from any sensor set that maps linearly to body motion.

    Each step, the encoder increments (n values, rad or ticks) and the gyro's heading change
    (gyro_z * dt: the rate sent with a reading is the mean rate since the previous reading, as
    an integrating IMU or a fixed-step simulation reports it) form a vector s, and
    `sensor_matrix` (3, n + 1) maps s to the motion (vx*dt, vy*dt, wz*dt), integrated exactly.
    The same matrix maps sensor rates to the twist, so the twist covariance is
    sensor_matrix diag(sensor_std^2) sensor_matrix'.

    The pose covariance follows the usual first-order propagation P <- F P F' + G Q G', with the
    step's own noise Q = diag(kt d, kt d, kr |dtheta| + krd d) in the robot frame, d the path
    length of the step: variances grow linearly with distance and turn (a random walk), so the
    update rate hardly changes the result.
    """

    def __init__(self, sensor_matrix, sensor_std, params: ChassisParams, pose=(0.0, 0.0, 0.0)):
        self.sensor_matrix = np.asarray(sensor_matrix, dtype=float)
        self.n_encoders = self.sensor_matrix.shape[1] - 1
        self.params = params
        self.pose = compose(pose, np.zeros(3))      # a copy, heading wrapped
        self.pose_covariance = np.zeros((3, 3))
        sensor_var = np.asarray(sensor_std, dtype=float) ** 2
        self.twist_covariance = (self.sensor_matrix * sensor_var) @ self.sensor_matrix.T
        self.twist = np.zeros(3)
        self.distance = 0.0
        self.rotation = 0.0
        self._last: tuple[int, np.ndarray] | None = None

    def update(self, stamp_ns: int, positions, gyro_z: float = 0.0) -> OdomEstimate:
        """Advance to the encoder positions (cumulative, not wrapped) at stamp_ns.

        The first call only sets the starting readings. Raises ValueError on a wrong number of
        positions, a non-finite value, or a stamp earlier than the previous one.
        """
        positions = np.asarray(positions, dtype=float)
        if positions.shape != (self.n_encoders,):
            raise ValueError(f"expected {self.n_encoders} encoder positions, got shape {positions.shape}")
        if not (np.all(np.isfinite(positions)) and np.isfinite(gyro_z)):
            raise ValueError("encoder positions and gyro rate must be finite")
        if self._last is not None:
            last_stamp, last_positions = self._last
            if stamp_ns < last_stamp:
                raise ValueError(f"stamp {stamp_ns} ns is earlier than the previous {last_stamp} ns")
            dt = (stamp_ns - last_stamp) * 1e-9
            sensed = np.append(positions - last_positions, gyro_z * dt)
            self._advance(self.sensor_matrix @ sensed, dt)
        self._last = (stamp_ns, positions.copy())
        return OdomEstimate(stamp_ns, self.pose.copy(), self.twist.copy(), self.pose_covariance.copy(),
                            self.twist_covariance.copy(), self.distance, self.rotation)

    def state(self) -> tuple[int, np.ndarray, np.ndarray] | None:
        """(stamp_ns, pose, encoder positions) of the last update, or None before the first: what
        resume() needs to carry on from there."""
        if self._last is None:
            return None
        return self._last[0], self.pose.copy(), self._last[1].copy()

    def resume(self, stamp_ns: int, pose, positions) -> None:
        """Carry on from a saved state(): the next update integrates the encoders' whole change since
        then as one step (the gyro's part is its rate then times the gap, so a heading taken from the
        gyro misses a turn made meanwhile). The covariance starts again from zero."""
        positions = np.asarray(positions, dtype=float)
        if positions.shape != (self.n_encoders,):
            raise ValueError(f"expected {self.n_encoders} encoder positions, got shape {positions.shape}")
        self.pose = compose(np.asarray(pose, dtype=float), np.zeros(3))
        self._last = (int(stamp_ns), positions.copy())

    def _advance(self, motion: np.ndarray, dt: float) -> None:
        p = self.params
        step = se2_exp(motion)
        dx, dy = step[0].item(), step[1].item()     # floats: numpy scalars cost more than the arithmetic
        path = float(np.hypot(motion[0], motion[1]))
        turn = abs(float(motion[2]))
        heading = self.pose[2].item()
        c, s = math.cos(heading), math.sin(heading)
        jac_pose = np.array([[1.0, 0.0, -s * dx - c * dy],
                             [0.0, 1.0, c * dx - s * dy],
                             [0.0, 0.0, 1.0]])
        jac_step = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
        noise = np.diag([p.odom_trans_var_per_m * path, p.odom_trans_var_per_m * path,
                         p.odom_rot_var_per_rad * turn + p.odom_rot_var_per_m * path])
        self.pose_covariance = (jac_pose @ self.pose_covariance @ jac_pose.T
                                + jac_step @ noise @ jac_step.T)
        self.pose = compose(self.pose, step)
        self.distance += path
        self.rotation += turn
        if dt > 0:
            self.twist = motion / dt


def wheel_odometry(params: ChassisParams, pose=(0.0, 0.0, 0.0)) -> EncoderOdometry:
    """Odometry from the drive wheels' encoders (rad), in the order of Kinematics.wheel_names.

    Forward kinematics of the angle increments gives the motion; its heading part is blended
    with the gyro's by odom_gyro_weight (0: wheels only, 1: gyro only — wheels of a mecanum
    robot slip most when it turns).
    """
    fk = Kinematics(params).fk_matrix
    weight = params.odom_gyro_weight
    matrix = np.zeros((3, fk.shape[1] + 1))
    matrix[:2, :-1] = fk[:2]
    matrix[2, :-1] = (1.0 - weight) * fk[2]
    matrix[2, -1] = weight
    std = np.append(np.full(fk.shape[1], params.odom_encoder_rate_std), params.odom_gyro_std)
    return EncoderOdometry(matrix, std, params, pose)
