"""Wheel kinematics of the three drives, wheel-speed saturation and acceleration limits.

Frames follow REP 103: x forward, y left, angles counter-clockwise. A twist is (vx, vy, wz) in
the robot frame. Every drive is described the same way: wheel i touches the ground at p_i and,
turning at w_i rad/s, pushes its contact point so that r * w_i = a_i . (v + wz x p_i), where a_i
is the wheel's "drive vector" (for a mecanum wheel not a unit vector: its free rollers absorb part
of the motion). Stacking those rows gives the inverse-kinematics matrix; forward kinematics is its
pseudo-inverse. docs/chassis.md derives the rows and writes the matrices out.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ...geometry.command_response import limit_acceleration
from ...parameters.declare import Parameters, Rule, param


DRIVES = ("mecanum", "omni3", "diff")
# rounds of scaling to the wheel limit and clipping to the acceleration limits that slide a
# command along the wheel limit; each round shrinks its excess over the limit several times over
SLIDE_ROUNDS = 30

WHEEL_NAMES = {
    "mecanum": ("front_left", "front_right", "rear_left", "rear_right"),
    "omni3": ("wheel1", "wheel2", "wheel3"),
    "diff": ("left", "right"),
}


@dataclass(frozen=True)
class ChassisParams(Parameters):
    """Everything the chassis service needs, flat as a ROS parameter file.

    Geometry defaults fit the mecanum paper's robot (footprint 0.832 x 0.636 m): 152 mm wheels
    (r = 0.076 m) at x = +-0.30 m (the wheels, r included, stay 4 cm inside the 0.416 m half
    length) and y = +-0.25 m (a 5 cm wide wheel ends 2 cm inside the 0.318 m half width).
    Mecanum kinematics only depend on l1 + l2; diff uses l2 alone.
    """
    drive: str = param("mecanum", choices=DRIVES)               # mecanum | omni3 | diff
    wheel_radius: float = param(0.076, gt=0)                    # m
    l1: float = param(0.30, gt=0)                               # m, half wheelbase: wheel contact x (mecanum)
    l2: float = param(0.25, gt=0)                               # m, half track: wheel contact |y| (mecanum and diff)
    omni_wheel_distance: float = param(0.28, gt=0)              # m, centre to each omni3 wheel's contact point
    omni_main_direction: float = param(math.pi / 3, finite=True)  # rad, direction of omni3 wheel 1 from the centre
    max_wheel_speed: float = param(13.0, gt=0)                  # rad/s (about 124 rpm, 0.99 m/s at the rim)
    acc_lim_x: float = param(2.5, gt=0)                         # m/s^2 (ROS base_local_planner default)
    acc_lim_y: float = param(2.5, gt=0)                         # m/s^2
    acc_lim_theta: float = param(3.2, gt=0)                     # rad/s^2
    # odometry (odometry.py): heading source and how the covariance grows
    odom_gyro_weight: float = param(0.0, ge=0.0, le=1.0)        # 0: heading from the wheels, 1: from the gyro
    odom_trans_var_per_m: float = param(1e-4, ge=0)             # m^2 of x and y variance per m driven
    odom_rot_var_per_rad: float = param(3e-4, ge=0)             # rad^2 of heading variance per rad turned
    odom_rot_var_per_m: float = param(1e-4, ge=0)               # rad^2 of heading variance per m driven
    odom_encoder_rate_std: float = param(0.05, ge=0)            # rad/s, noise of a wheel or follower encoder rate
    odom_gyro_std: float = param(0.01, ge=0)                    # rad/s, noise of the gyro rate
    # passive follower wheels (follower.py): rolling direction, scale, contact point
    follower_alpha: float = param(0.0, finite=True)             # rad, rolling direction of follower A in the robot frame
    follower_beta: float = param(math.pi / 2, finite=True)      # rad, rolling direction of follower B
    follower_ka: float = param(0.025, gt=0)                     # m per encoder unit (rad) of follower A
    follower_kb: float = param(0.025, gt=0)                     # m per encoder unit (rad) of follower B
    follower_a_offset: tuple[float, float] = param((0.10, 0.0), items=2, finite=True)  # m, contact point of A
    follower_b_offset: tuple[float, float] = param((0.0, 0.10), items=2, finite=True)  # m, contact point of B

    @property
    def acc_limits(self) -> np.ndarray:
        return np.array([self.acc_lim_x, self.acc_lim_y, self.acc_lim_theta])

    # parallel followers measure one direction twice and the other not at all
    rules = (Rule("follower_beta", lambda p: abs(math.sin(p.follower_beta - p.follower_alpha)) >= 0.1,
                  "more than about 6 degrees (mod 180) from follower_alpha ({p.follower_alpha})"),)


def _wheel_rows(params: ChassisParams) -> np.ndarray:
    """(n_wheels, 3): rows [a_x, a_y, a_y*p_x - a_x*p_y] / r of r*w = a . (v + wz x p)."""
    if params.drive == "mecanum":
        l1, l2 = params.l1, params.l2
        positions = np.array([[l1, l2], [l1, -l2], [-l1, l2], [-l1, -l2]])
        # "O" layout (upper rollers form an O seen from above): the free roller on the ground
        # runs along (1, 1) under FL and RR, along (1, -1) under FR and RL; the wheel supplies
        # what that roller cannot, so a = (1, -cot(roller angle)).
        drive_vectors = np.array([[1.0, -1.0], [1.0, 1.0], [1.0, 1.0], [1.0, -1.0]])
    elif params.drive == "omni3":
        angles = params.omni_main_direction + np.arange(3) * (2 * np.pi / 3)
        radial = np.stack([np.cos(angles), np.sin(angles)], axis=1)
        positions = params.omni_wheel_distance * radial
        drive_vectors = np.stack([-radial[:, 1], radial[:, 0]], axis=1)   # tangential, CCW
    else:
        positions = np.array([[0.0, params.l2], [0.0, -params.l2]])
        drive_vectors = np.array([[1.0, 0.0], [1.0, 0.0]])
    lever = drive_vectors[:, 1] * positions[:, 0] - drive_vectors[:, 0] * positions[:, 1]
    return np.column_stack([drive_vectors, lever]) / params.wheel_radius


@dataclass(frozen=True)
class LimitedCommand:
    """A velocity command after the drive's limits, with what was changed and why."""
    twist: np.ndarray         # (3,) vx, vy, wz actually commanded
    wheels: np.ndarray        # (n_wheels,) rad/s
    dropped_vy: bool          # the request asked for sideways motion this drive cannot make
    saturation: float         # factor the request was scaled by so no wheel exceeds its limit
    accel_limited: bool       # the change from the previous command was clipped


class Kinematics:
    """Inverse and forward kinematics of one drive; matrices built once, batches welcome.

    `ik` maps twists (..., 3) to wheel speeds (..., n_wheels); `fk` maps back by least squares,
    which for a mecanum robot also averages out wheel disagreement (slip).
    """

    def __init__(self, params: ChassisParams):
        self.params = params
        self.wheel_names = WHEEL_NAMES[params.drive]
        self.ik_matrix = _wheel_rows(params)
        self.fk_matrix = np.linalg.pinv(self.ik_matrix)
        self.ik_matrix.setflags(write=False)
        self.fk_matrix.setflags(write=False)
        self.holonomic = params.drive != "diff"    # a diff drive cannot move along y

    @property
    def n_wheels(self) -> int:
        return len(self.wheel_names)

    def ik(self, twist) -> np.ndarray:
        """Wheel speeds (rad/s) for twists (..., 3). A differential drive ignores vy."""
        return np.asarray(twist, dtype=float) @ self.ik_matrix.T

    def fk(self, wheels) -> np.ndarray:
        """Twists (..., 3) from wheel speeds (..., n_wheels); also maps wheel angle increments
        to the body motion (vx*dt, vy*dt, wz*dt) since the map is linear."""
        return np.asarray(wheels, dtype=float) @ self.fk_matrix.T

    def saturation_scale(self, twist) -> np.ndarray:
        """(...,) factor in (0, 1] that brings the fastest wheel of each twist to the limit."""
        peak = np.max(np.abs(self.ik(twist)), axis=-1)
        limit = self.params.max_wheel_speed
        return limit / np.maximum(peak, limit)

    def saturate(self, twist) -> np.ndarray:
        """Scale every wheel of a too-fast twist by one factor, so the direction is kept."""
        twist = np.asarray(twist, dtype=float)
        return twist * self.saturation_scale(twist)[..., None]

    def limit(self, requested, previous, dt: float) -> LimitedCommand:
        """The command to drive now, given the previous one sent `dt` seconds ago.

        Order: drop what the drive cannot make, scale to the wheel limit (direction kept), clip
        the change per axis to the acceleration limits. Per-axis clipping can leave the wheel
        limits' polytope; then the command slides along the limit (scaled and clipped by turns
        until it keeps both), else stops where the straight line from the previous command leaves
        it. The line alone never moves a command that already has a wheel at its limit off it:
        a Jackal at full speed in a turn kept turning at 0.9 rad/s for a second while its
        planner asked for 0.3, and drove into a door's jamb (bench buildings, jackal-112).
        """
        requested = np.asarray(requested, dtype=float)
        previous = np.asarray(previous, dtype=float)
        target = requested.copy()
        dropped_vy = not self.holonomic and target[1] != 0.0
        if not self.holonomic:
            target[1] = 0.0
        scale = float(self.saturation_scale(target))
        if scale < 1.0:
            target = target * scale
        stepped = limit_acceleration(target, previous, dt, self.params.acc_limits)
        accel_limited = not np.array_equal(stepped, target)
        if accel_limited:
            stepped = self._slide(previous, stepped, dt)
        return LimitedCommand(stepped, self.ik(stepped), dropped_vy, scale, accel_limited)

    def _slide(self, previous: np.ndarray, stepped: np.ndarray, dt: float) -> np.ndarray:
        """A command within both the wheel and the acceleration limits near `stepped`."""
        slid = stepped
        for _ in range(SLIDE_ROUNDS):
            if self.saturation_scale(slid) == 1.0:
                return slid
            slid = limit_acceleration(self.saturate(slid), previous, dt, self.params.acc_limits)
        slid = self.saturate(slid)
        if np.all(np.abs(slid - previous) <= self.params.acc_limits * dt * (1 + 1e-12)):
            return slid
        return self._back_off(previous, stepped)

    def _back_off(self, previous: np.ndarray, stepped: np.ndarray) -> np.ndarray:
        limit = self.params.max_wheel_speed
        w_prev = self.ik(previous)
        if np.max(np.abs(w_prev)) > limit * (1 + 1e-9):   # sent under other limits: no line to use
            return self.saturate(stepped)
        w_step = self.ik(stepped) - w_prev
        moving = np.abs(w_step) > 1e-12 * limit      # a vanishing change cannot leave the limits
        reach = (np.sign(w_step[moving]) * limit - w_prev[moving]) / w_step[moving]
        if reach.size == 0 or reach.min() >= 1.0:
            return stepped
        return previous + max(0.0, float(reach.min())) * (stepped - previous)
