"""Odometry from two passive follower wheels and a gyro, and the followers' calibration.

Follower A touches the ground at p_A (robot frame) and rolls along u_A = (cos alpha, sin alpha);
its encoder turns by e_A with k_A metres per encoder unit (rad, or ticks). Over a step with body
motion (dx, dy, dtheta) = twist * dt, the contact point moves along u_A by

    k_A de_A = cos(alpha) dx + sin(alpha) dy + c_A dtheta,    c_A = p_A x u_A        (1)
    k_B de_B = cos(beta)  dx + sin(beta)  dy + c_B dtheta,    c_B = p_B x u_B        (2)
    dtheta   = gyro heading change over the step                                     (3)

(the passive rollers let the wheel slide freely across u). With dtheta from the gyro, (1)-(2)
is a 2x2 system for (dx, dy) with determinant sin(beta - alpha); the motion is then integrated
exactly in the odom frame by EncoderOdometry. docs/chassis.md has the solution written out.
"""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np

from ...geometry.se2 import wrap_angle
from .kinematics import ChassisParams
from .odometry import EncoderOdometry


def _geometry(params: ChassisParams) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Rolling directions (2, 2), lever arms c = p x u (2,), scales k (2,) of followers A, B."""
    angles = np.array([params.follower_alpha, params.follower_beta])
    directions = np.stack([np.cos(angles), np.sin(angles)], axis=1)
    offsets = np.array([params.follower_a_offset, params.follower_b_offset], dtype=float)
    lever = offsets[:, 0] * directions[:, 1] - offsets[:, 1] * directions[:, 0]
    scales = np.array([params.follower_ka, params.follower_kb])
    return directions, lever, scales


def follower_readings(params: ChassisParams, motion) -> np.ndarray:
    """Encoder increments (..., 2) of followers A, B for body motions (..., 3): equations (1)-(2)."""
    directions, lever, scales = _geometry(params)
    motion = np.asarray(motion, dtype=float)
    rolled = motion[..., :2] @ directions.T + motion[..., 2:3] * lever
    return rolled / scales


def follower_sensor_matrix(params: ChassisParams) -> np.ndarray:
    """(3, 3) map from (de_A, de_B, dtheta_gyro) to the body motion: (1)-(3) solved."""
    directions, lever, scales = _geometry(params)
    solve = np.linalg.inv(directions)
    matrix = np.zeros((3, 3))
    matrix[:2, :2] = solve * scales          # columns scaled: k_A de_A, k_B de_B
    matrix[:2, 2] = -solve @ lever           # take out what the turn rolled the followers
    matrix[2, 2] = 1.0
    return matrix


def follower_odometry(params: ChassisParams, pose=(0.0, 0.0, 0.0)) -> EncoderOdometry:
    """Odometry from WheelState.follower_positions (A, B) and WheelState.gyro_z."""
    std = [params.odom_encoder_rate_std, params.odom_encoder_rate_std, params.odom_gyro_std]
    return EncoderOdometry(follower_sensor_matrix(params), std, params, pose)


@dataclass(frozen=True)
class FollowerCalibration:
    alpha: float      # rad, rolling direction of follower A
    beta: float       # rad
    ka: float         # m per encoder unit
    kb: float
    residual: float   # rms misfit of the runs, encoder units (0 when exactly two runs)

    def apply(self, params: ChassisParams) -> ChassisParams:
        return dataclasses.replace(params, follower_alpha=self.alpha, follower_beta=self.beta,
                                   follower_ka=self.ka, follower_kb=self.kb)


def calibrate_followers(readings, distances, directions=(0.0, math.pi / 2)) -> FollowerCalibration:
    """Scales and mounting angles of both followers from straight runs of known length.

    Run j drives `distances[j]` metres straight, without turning, along `directions[j]` (rad,
    robot frame; default: one run forward along x, one sideways along y) and reads the change
    `readings[j] = (de_A, de_B)` of the two encoders. By (1) with dtheta = 0,
        de_A = D_j (cos(phi_j), sin(phi_j)) . g_A,    g_A = (cos alpha, sin alpha) / k_A,
    linear in g_A: two runs in different directions fix it, more are fitted by least squares;
    then k_A = 1 / |g_A| and alpha = atan2(g_A). An encoder counting backwards comes out as
    alpha + pi with a positive k_A, which describes the same wheel.
    """
    readings = np.asarray(readings, dtype=float)
    distances = np.asarray(distances, dtype=float)
    directions = np.asarray(directions, dtype=float)
    n = len(distances)
    if readings.shape != (n, 2) or directions.shape != (n,):
        raise ValueError(f"need one (de_A, de_B) pair and one direction per distance: got readings "
                         f"{readings.shape}, distances {distances.shape}, directions {directions.shape}")
    if not (np.all(np.isfinite(readings)) and np.all(np.isfinite(directions))
            and np.all(np.isfinite(distances)) and np.all(distances > 0)):
        raise ValueError("readings and directions must be finite and distances positive")
    unit = np.stack([np.cos(directions), np.sin(directions)], axis=1)
    if n < 2 or np.linalg.svd(unit, compute_uv=False)[-1] < 0.1 * math.sqrt(n):
        raise ValueError("the runs must go in at least two clearly different directions "
                         "(e.g. one along x and one along y)")
    design = distances[:, None] * unit
    inv_scaled, _, _, _ = np.linalg.lstsq(design, readings, rcond=None)   # columns g_A, g_B
    norms = np.linalg.norm(inv_scaled, axis=0)
    if np.any(norms == 0):
        raise ValueError("a follower encoder did not move in any run")
    angles = wrap_angle(np.arctan2(inv_scaled[1], inv_scaled[0]))
    residual = float(np.sqrt(np.mean((design @ inv_scaled - readings) ** 2)))
    return FollowerCalibration(float(angles[0]), float(angles[1]), float(1 / norms[0]),
                               float(1 / norms[1]), residual)
