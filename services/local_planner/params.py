"""Local planning parameters: one frozen dataclass per core, with ROS names and defaults.

DwaParams holds base_local_planner's TrajectoryPlannerROS names (the ones the mecanum paper's table
lists) and dwa_local_planner's where base_local_planner has none. Defaults are the ROS wiki's:
base_local_planner for acc_lim_*, max/min_vel_x, max/min_vel_theta, min_in_place_vel_theta,
escape_vel, holonomic_robot, y_vels, sim_granularity, vx_samples, vtheta_samples,
controller_frequency, dwa; dwa_local_planner for max/min_vel_y, vy_samples,
sim_time (1.7), path_distance_bias (32), goal_distance_bias (24), occdist_scale (0.01),
forward_point_distance (0.325). The biases weigh metres as DWA does (DWA multiplies them by the
costmap resolution and measures distances in cells, which is the same thing).
The goal tolerances are the local planner node's (its final approach): DWA itself never reads them.
FollowerParams has no ROS counterpart (the omni-wheel paper's follower).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

from ..runtime.params import require_at_least, require_nonnegative, require_positive

DRIVE_MODES = ("holonomic", "diff")


@dataclass(frozen=True)
class DwaParams:
    # robot configuration
    acc_lim_x: float = 2.5               # m/s²
    acc_lim_y: float = 2.5               # m/s²
    acc_lim_theta: float = 3.2           # rad/s²
    max_vel_x: float = 0.5               # m/s
    min_vel_x: float = 0.1               # m/s (negative allows reversing)
    max_vel_y: float = 0.1               # m/s (dwa_local_planner)
    min_vel_y: float = -0.1              # m/s (dwa_local_planner)
    max_vel_theta: float = 1.0           # rad/s
    min_vel_theta: float = -1.0          # rad/s
    min_in_place_vel_theta: float = 0.4  # rad/s: slower turns on the spot are not sampled
    escape_vel: float = -0.1             # m/s: backing up when no trajectory is legal
    holonomic_robot: bool = True         # false: differential drive, vy is always 0
    y_vels: tuple[float, ...] = (-0.3, -0.1, 0.1, 0.3)   # m/s: extra strafe samples (within the window)
    # forward simulation
    sim_time: float = 1.7                # s (dwa_local_planner; base_local_planner: 1.0)
    sim_granularity: float = 0.025       # m between simulated poses
    vx_samples: int = 3
    vy_samples: int = 10                 # (dwa_local_planner)
    vtheta_samples: int = 20
    controller_frequency: float = 20.0   # Hz: with dwa, the window spans one control period
    dwa: bool = True                     # false: trajectory rollout (window over sim_time, ramped rollouts)
    # scoring
    path_distance_bias: float = 32.0     # per m from the local path
    goal_distance_bias: float = 24.0     # per m from the local goal
    occdist_scale: float = 0.01          # per unit of the highest cost met
    forward_point_distance: float = 0.325  # m: the point ahead of the robot scored for heading
    # moving obstacles (the tracker's tracks, predicted along each rollout; dynamic.py): no ROS names
    dynamic_obstacle_margin: float = 0.1   # m kept between the footprint and a track's circle ...
    dynamic_obstacle_sigmas: float = 2.0   # ... plus this many standard deviations of its predicted position
    dynamic_obstacle_scale: float = 20.0   # per unit of intrusion into dynamic_influence_distance
    dynamic_influence_distance: float = 0.8  # m beyond the kept distance within which a track costs
    dynamic_min_speed: float = 0.1         # m/s: slower tracks are left to the costmap (a standing person is in it)

    def __post_init__(self):
        require_positive(self, "acc_lim_x", "acc_lim_theta", "max_vel_theta", "min_in_place_vel_theta", "sim_time",
                         "sim_granularity", "controller_frequency")
        require_nonnegative(self, "acc_lim_y", "path_distance_bias", "goal_distance_bias", "occdist_scale",
                            "forward_point_distance",
                            "dynamic_obstacle_margin", "dynamic_obstacle_sigmas", "dynamic_obstacle_scale",
                            "dynamic_min_speed")
        require_positive(self, "dynamic_influence_distance")
        require_at_least(self, 1, "vx_samples", "vy_samples", "vtheta_samples")
        for low, high in (("min_vel_x", "max_vel_x"), ("min_vel_y", "max_vel_y"),
                          ("min_vel_theta", "max_vel_theta")):
            if not getattr(self, low) <= getattr(self, high):
                raise ValueError(f"{low} ({getattr(self, low)}) must not exceed {high} ({getattr(self, high)})")
        if not all(math.isfinite(v) for v in self.y_vels):
            raise ValueError(f"y_vels must be finite numbers, got {self.y_vels}")


@dataclass(frozen=True)
class FollowerParams:
    """The omni-wheel paper's follower: cruise speed along the path, PID on cross-track and heading
    error, and V = ((l − s)/l)^a · V0 over the last l metres."""
    drive: str = "holonomic"             # holonomic | diff
    cruise_speed: float = 0.5            # m/s: V0
    acc_lim: float = 2.5                 # m/s²: speed-up along the path
    decel_distance: float = 0.6          # m: l, the final approach
    decel_exponent: float = 0.5          # a; below 1 the approach ends in finite time
    kp_cross: float = 4.5                # per s: m of cross-track error → m/s (holonomic) or rad/s per m (diff);
                                         # with kp_heading 3 a diff drive at V0 = 0.5 is critically damped
    ki_cross: float = 0.0
    kd_cross: float = 0.0
    kp_heading: float = 3.0              # per s: rad of heading error → rad/s
    ki_heading: float = 0.0
    kd_heading: float = 0.0
    integral_limit: float = 0.5          # bound on each PID's integral term (its units × s)
    max_vel_theta: float = 1.0           # rad/s
    goal_tolerance: float = 0.002        # m: done when this close to the end along the path

    def __post_init__(self):
        if self.drive not in DRIVE_MODES:
            raise ValueError(f"drive must be one of {DRIVE_MODES}, got {self.drive!r}")
        require_positive(self, "cruise_speed", "acc_lim", "decel_distance", "decel_exponent", "max_vel_theta")
        require_nonnegative(self, "kp_cross", "ki_cross", "kd_cross", "kp_heading", "ki_heading", "kd_heading",
                            "integral_limit", "goal_tolerance")


@dataclass(frozen=True)
class ElasticBandParams:
    """teb_local_planner's names and defaults (ROS wiki / TebConfig); holonomic_robot and
    controller_frequency are base_local_planner's (TEB infers holonomy from max_vel_y > 0)."""
    # robot
    max_vel_x: float = 0.4                  # m/s
    max_vel_x_backwards: float = 0.2        # m/s (a magnitude)
    max_vel_y: float = 0.0                  # m/s: strafing, holonomic robots only
    max_vel_theta: float = 0.3              # rad/s
    acc_lim_x: float = 0.5                  # m/s²
    acc_lim_y: float = 0.5                  # m/s²
    acc_lim_theta: float = 0.5              # rad/s²
    holonomic_robot: bool = False           # false: differential drive, vy ≡ 0 and the band keeps to arcs
    controller_frequency: float = 20.0      # Hz: the command's acceleration window is one period
    # trajectory
    dt_ref: float = 0.3                     # s: desired time interval between band poses
    dt_hysteresis: float = 0.1              # s: intervals outside dt_ref ± this are split or merged
    min_samples: int = 3                    # band poses, at least
    max_samples: int = 500                  # band poses, at most
    max_global_plan_lookahead_dist: float = 3.0   # m of the global path the band spans
    force_reinit_new_goal_dist: float = 1.0       # m: a local goal moved further restarts the band
    force_reinit_new_goal_angular: float = 0.5 * math.pi   # rad: likewise for its heading
    free_goal_vel: bool = False             # false: the band stops at the path's final goal
    feasibility_check_no_poses: int = 5     # band poses (from the robot) that must be collision-free
    # obstacles
    min_obstacle_dist: float = 0.5          # m between the footprint and an obstacle
    inflation_dist: float = 0.6             # m: a small extra penalty within this distance
    # optimisation
    no_inner_iterations: int = 5            # solver iterations per outer iteration
    no_outer_iterations: int = 4            # resize + solve rounds per cycle
    penalty_epsilon: float = 0.1            # safety margin inside the soft limits
    weight_max_vel_x: float = 2.0
    weight_max_vel_y: float = 2.0
    weight_max_vel_theta: float = 1.0
    weight_acc_lim_x: float = 1.0
    weight_acc_lim_y: float = 1.0
    weight_acc_lim_theta: float = 1.0
    weight_kinematics_nh: float = 1000.0
    weight_kinematics_forward_drive: float = 1.0
    weight_optimaltime: float = 1.0
    weight_obstacle: float = 50.0
    weight_inflation: float = 0.1
    weight_adapt_factor: float = 2.0        # weight_obstacle grows by this factor every outer iteration

    def __post_init__(self):
        require_positive(self, "max_vel_x", "max_vel_theta", "acc_lim_x", "acc_lim_theta", "controller_frequency",
                         "dt_ref", "max_global_plan_lookahead_dist")
        require_nonnegative(self, "max_vel_x_backwards", "max_vel_y", "acc_lim_y", "dt_hysteresis",
                            "force_reinit_new_goal_dist", "force_reinit_new_goal_angular", "min_obstacle_dist",
                            "inflation_dist", "penalty_epsilon", "weight_max_vel_x", "weight_max_vel_y",
                            "weight_max_vel_theta", "weight_acc_lim_x", "weight_acc_lim_y", "weight_acc_lim_theta",
                            "weight_kinematics_nh", "weight_kinematics_forward_drive", "weight_optimaltime",
                            "weight_obstacle", "weight_inflation")
        require_at_least(self, 1.0, "weight_adapt_factor")
        require_at_least(self, 1, "no_inner_iterations", "no_outer_iterations", "feasibility_check_no_poses")
        if self.holonomic_robot and not (self.max_vel_y > 0 and self.acc_lim_y > 0):
            raise ValueError("holonomic_robot needs max_vel_y and acc_lim_y > 0 "
                             f"(got {self.max_vel_y}, {self.acc_lim_y})")
        if self.dt_hysteresis >= self.dt_ref:
            raise ValueError(f"dt_hysteresis ({self.dt_hysteresis}) must be below dt_ref ({self.dt_ref})")
        if self.inflation_dist < self.min_obstacle_dist:
            raise ValueError(f"inflation_dist ({self.inflation_dist}) must be at least min_obstacle_dist "
                             f"({self.min_obstacle_dist})")
        if not 3 <= self.min_samples <= self.max_samples:
            raise ValueError(f"need 3 ≤ min_samples ≤ max_samples, got {self.min_samples} and {self.max_samples}")
