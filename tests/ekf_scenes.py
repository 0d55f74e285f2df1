"""Synthetic wheel odometry, IMU and laser odometry for the odometry fusion's tests: a true motion,
what the wheels claim of it (a push they miss, a skid they overstate), the IMU's reading of the
truth and laser odometry poses of the truth, late, as the node would get them."""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from omninav.geometry.se2 import integrate
from omninav.schemas.messages import Header, Imu, Odometry, Pose2D, Twist
from omninav.sim.imu import body_acceleration

DT = 0.01
STEP_NS = 10_000_000
WHEEL_STD = np.array([0.0019, 0.0019, 0.0035])        # the mecanum chassis's twist std
GYRO_STD, ACCEL_STD = 0.0024, 0.017                    # the sim's BMI088 at 100 Hz
LASER_PERIOD = 10                                      # steps: 10 Hz
LASER_STD = np.array([0.01, 0.01, 0.005])


@dataclass
class Scene:
    wheels: list[Odometry] = field(default_factory=list)
    imus: list[Imu] = field(default_factory=list)
    lasers: list[Odometry] = field(default_factory=list)
    truth: list[np.ndarray] = field(default_factory=list)     # pose at each wheel step
    wheel_poses: list[np.ndarray] = field(default_factory=list)


def odometry(t_ns: int, seq: int, pose, twist, pose_cov, twist_cov) -> Odometry:
    return Odometry(header=Header(stamp_ns=t_ns, frame_id="odom", seq=seq), child_frame_id="base_link",
                    pose=Pose2D(*map(float, pose)),
                    twist=Twist(header=Header(stamp_ns=t_ns, frame_id="base_link"),
                                linear_x=float(twist[0]), linear_y=float(twist[1]), angular_z=float(twist[2])),
                    pose_covariance=np.asarray(pose_cov, "<f8"), twist_covariance=np.asarray(twist_cov, "<f8"))


def scene(seconds: float, true_twist: Callable[[float], np.ndarray],
          wheel_twist: Callable[[float, np.ndarray], np.ndarray] = lambda t, v: v, *,
          laser_std=LASER_STD, laser_cov=None, seed: int = 0) -> Scene:
    """Every DT: the true body twist at t (mean over the step), the wheels' claim of it."""
    rng = np.random.default_rng(seed)
    out = Scene()
    truth, wheel_pose, previous = np.zeros(3), np.zeros(3), np.zeros(3)
    laser_cov = np.diag(np.asarray(laser_std) ** 2) if laser_cov is None else np.asarray(laser_cov)
    for k in range(round(seconds / DT) + 1):
        t = k * DT
        t_ns = k * STEP_NS
        v = np.asarray(true_twist(t), float) if k else np.zeros(3)
        w = np.asarray(wheel_twist(t, v), float) if k else np.zeros(3)
        truth = integrate(truth, v, DT) if k else truth
        wheel_pose = integrate(wheel_pose, w, DT) if k else wheel_pose
        accel = body_acceleration(previous, v, DT)
        previous = v
        out.imus.append(Imu(header=Header(stamp_ns=t_ns, frame_id="base_link", seq=k + 1),
                            angular_velocity_z=float(v[2] + GYRO_STD * rng.standard_normal()),
                            linear_acceleration_x=float(accel[0] + ACCEL_STD * rng.standard_normal()),
                            linear_acceleration_y=float(accel[1] + ACCEL_STD * rng.standard_normal()),
                            angular_velocity_z_variance=GYRO_STD ** 2,
                            linear_acceleration_x_variance=ACCEL_STD ** 2, linear_acceleration_y_variance=ACCEL_STD ** 2))
        noisy = w + WHEEL_STD * rng.standard_normal(3) if k else w
        out.wheels.append(odometry(t_ns, k + 1, wheel_pose, noisy, np.zeros((3, 3)), np.diag(WHEEL_STD ** 2)))
        out.truth.append(truth.copy())
        out.wheel_poses.append(wheel_pose.copy())
        if k % LASER_PERIOD == 0:
            measured = truth + np.asarray(laser_std) * rng.standard_normal(3)
            out.lasers.append(odometry(t_ns, len(out.lasers) + 1, measured, np.zeros(3), laser_cov, np.zeros((3, 3))))
    return out


def run_core(fusion, s: Scene, delay_s: float = 0.25, on_step=None):
    """Feed a fusion core as the node does: each wheel step with the IMU at its stamp, the laser
    poses once a wheel step is stamped after their stamp + delay."""
    delay_ns = round(delay_s * 1e9)
    pending = list(s.lasers)
    verdicts = []
    for k, (wheels, imu) in enumerate(zip(s.wheels, s.imus)):
        t = wheels.header.stamp_ns
        while pending and pending[0].header.stamp_ns + delay_ns < t:
            fusion.laser(pending.pop(0))
        verdicts.append(fusion.step(wheels, [imu]))
        if on_step is not None:
            on_step(k, fusion)
    for laser in pending:       # those still held at the end (a node would fuse them at its next step)
        fusion.laser(laser)
    return verdicts
