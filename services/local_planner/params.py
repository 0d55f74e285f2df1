"""Local planning parameters: one frozen dataclass per core, with ROS names and defaults.

DwaParams holds base_local_planner's TrajectoryPlannerROS names (the ones the mecanum paper's table
lists) and dwa_local_planner's where base_local_planner has none. Defaults are the ROS wiki's:
base_local_planner for acc_lim_*, max/min_vel_x, max/min_vel_theta, min_in_place_vel_theta,
escape_vel, escape_reset_dist, escape_reset_theta, holonomic_robot, y_vels, sim_granularity, vx_samples, vtheta_samples,
controller_frequency, dwa; dwa_local_planner for max/min_vel_y, vy_samples,
sim_time (1.7), path_distance_bias (32), goal_distance_bias (24), occdist_scale (0.01),
forward_point_distance (0.325). The biases weigh metres as DWA does (DWA multiplies them by the
costmap resolution and measures distances in cells, which is the same thing).
FollowerParams has no ROS counterpart (the omni-wheel paper's follower).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

from ...parameters.declare import Parameters, Rule, param

DRIVE_MODES = ("holonomic", "diff")


@dataclass(frozen=True)
class DwaParams(Parameters):
    # robot configuration
    acc_lim_x: float = param(2.5, gt=0)                         # m/s²
    acc_lim_y: float = param(2.5, ge=0)                         # m/s²
    acc_lim_theta: float = param(3.2, gt=0)                     # rad/s²
    max_vel_x: float = 0.5                                      # m/s
    min_vel_x: float = 0.1                                      # m/s (negative allows reversing)
    max_vel_y: float = 0.1                                      # m/s (dwa_local_planner)
    min_vel_y: float = -0.1                                     # m/s (dwa_local_planner)
    max_vel_theta: float = param(1.0, gt=0)                     # rad/s
    min_vel_theta: float = -1.0                                 # rad/s
    min_in_place_vel_theta: float = param(0.4, gt=0)            # rad/s: slower turns on the spot are not sampled
    escape_vel: float = -0.1                                    # m/s: backing up when no trajectory is legal
    escape_reset_dist: float = param(0.10, ge=0)                # m backed (or moved) before forward samples come back
    escape_reset_theta: float = param(math.pi / 4, ge=0)        # rad turned before forward samples come back
    holonomic_robot: bool = True                                # false: differential drive, vy is always 0
    y_vels: tuple[float, ...] = param((-0.3, -0.1, 0.1, 0.3), finite=True)  # m/s: extra strafe samples (within the window)
    # forward simulation
    sim_time: float = param(1.7, gt=0)                          # s (dwa_local_planner; base_local_planner: 1.0)
    sim_granularity: float = param(0.025, gt=0)                 # m between simulated poses
    vx_samples: int = param(3, ge=1)
    vy_samples: int = param(10, ge=1)                           # (dwa_local_planner)
    vtheta_samples: int = param(20, ge=1)
    controller_frequency: float = param(20.0, gt=0)             # Hz: with dwa, the window spans one control period
    dwa: bool = True                                            # false: trajectory rollout (window over sim_time, ramped rollouts)
    # scoring
    path_distance_bias: float = param(32.0, ge=0)               # per m from the local path
    goal_distance_bias: float = param(24.0, ge=0)               # per m from the local goal
    occdist_scale: float = param(0.01, ge=0)                    # per unit of the highest cost met
    forward_point_distance: float = param(0.325, ge=0)          # m: the point ahead of the robot scored for heading
    # moving obstacles (the tracker's tracks, predicted along each rollout; dynamic.py): no ROS names
    dynamic_obstacle_margin: float = param(0.1, ge=0)           # m kept between the footprint and a track's circle ...
    dynamic_obstacle_sigmas: float = param(2.0, ge=0)           # ... plus this many standard deviations of its predicted position
    dynamic_obstacle_scale: float = param(20.0, ge=0)           # per unit of intrusion into dynamic_influence_distance
    dynamic_influence_distance: float = param(0.8, gt=0)        # m beyond the kept distance within which a track costs
    dynamic_horizon: float = param(0.0, ge=0)                   # s over which rollouts are held against movers (carried on past sim_time; 0: sim_time)
    evade_movers: bool = False                                  # no way of the window clear of movers: ramp towards the one meeting them latest (dwa.py)
    dynamic_min_speed: float = param(0.1, ge=0)                 # m/s: slower tracks are left to the costmap (a standing person is in it)
    wedged_mover_distance: float = param(1.0, ge=0)             # m: a robot wedged on an obstacle's cells drives off them only with no track's edge nearer

    rules = tuple(Rule(high, lambda p, low=low, high=high: getattr(p, low) <= getattr(p, high),
                       f"≥ {low} ({{p.{low}}})")
                  for low, high in (("min_vel_x", "max_vel_x"), ("min_vel_y", "max_vel_y"),
                                    ("min_vel_theta", "max_vel_theta")))


@dataclass(frozen=True)
class FollowerParams(Parameters):
    """The omni-wheel paper's follower: cruise speed along the path, PID on cross-track and heading
    error, and V = ((l − s)/l)^a · V0 over the last l metres."""
    drive: str = param("holonomic", choices=DRIVE_MODES)  # holonomic | diff
    cruise_speed: float = param(0.5, gt=0)                # m/s: V0
    acc_lim: float = param(2.5, gt=0)                     # m/s²: speed-up along the path
    decel_distance: float = param(0.6, gt=0)              # m: l, the final approach
    decel_exponent: float = param(0.5, gt=0)              # a; below 1 the approach ends in finite time
    kp_cross: float = param(4.5, ge=0)                    # per s: m of cross-track error → m/s (holonomic) or rad/s per m (diff);
                                                          # with kp_heading 3 a diff drive at V0 = 0.5 is critically damped
    ki_cross: float = param(0.0, ge=0)
    kd_cross: float = param(0.0, ge=0)
    kp_heading: float = param(3.0, ge=0)                  # per s: rad of heading error → rad/s
    ki_heading: float = param(0.0, ge=0)
    kd_heading: float = param(0.0, ge=0)
    integral_limit: float = param(0.5, ge=0)              # bound on each PID's integral term (its units × s)
    max_vel_theta: float = param(1.0, gt=0)               # rad/s
    goal_tolerance: float = param(0.002, ge=0)            # m: done when this close to the end along the path


@dataclass(frozen=True)
class ElasticBandParams(Parameters):
    """teb_local_planner's names and defaults (ROS wiki / TebConfig); holonomic_robot and
    controller_frequency are base_local_planner's (TEB infers holonomy from max_vel_y > 0)."""
    # robot
    max_vel_x: float = param(0.4, gt=0)                         # m/s
    max_vel_x_backwards: float = param(0.2, ge=0)               # m/s (a magnitude)
    max_vel_y: float = param(0.0, ge=0)                         # m/s: strafing, holonomic robots only
    max_vel_theta: float = param(0.3, gt=0)                     # rad/s
    acc_lim_x: float = param(0.5, gt=0)                         # m/s²
    acc_lim_y: float = param(0.5, ge=0)                         # m/s²
    acc_lim_theta: float = param(0.5, gt=0)                     # rad/s²
    holonomic_robot: bool = False                               # false: differential drive, vy ≡ 0 and the band keeps to arcs
    controller_frequency: float = param(20.0, gt=0)             # Hz: the command's acceleration window is one period
    # trajectory
    dt_ref: float = param(0.3, gt=0)                            # s: desired time interval between band poses
    dt_hysteresis: float = param(0.1, ge=0)                     # s: intervals outside dt_ref ± this are split or merged
    min_samples: int = param(3, ge=3)                           # band poses, at least
    max_samples: int = 500                                      # band poses, at most
    max_global_plan_lookahead_dist: float = param(3.0, gt=0)    # m of the global path the band spans
    force_reinit_new_goal_dist: float = param(1.0, ge=0)        # m: a local goal moved further restarts the band
    force_reinit_new_goal_angular: float = param(0.5 * math.pi, ge=0)  # rad: likewise for its heading
    free_goal_vel: bool = False                                 # false: the band stops at the path's final goal
    feasibility_check_no_poses: int = param(5, ge=1)            # band poses (from the robot) that must be collision-free
    # obstacles
    min_obstacle_dist: float = param(0.5, ge=0)                 # m between the footprint and an obstacle
    inflation_dist: float = param(0.6, ge=0)                    # m: a small extra penalty within this distance
    include_dynamic_obstacles: bool = False                     # the tracker's movers, each pose held clear of where they will be
    dynamic_obstacle_inflation_dist: float = param(0.6, ge=0)   # m: likewise for the movers
    dynamic_obstacle_sigmas: float = param(0.0, ge=0)           # a mover's radius grows by this many σ of its predicted position (ours; TEB: none)
    # optimisation
    no_inner_iterations: int = param(5, ge=1)                   # solver iterations per outer iteration
    no_outer_iterations: int = param(4, ge=1)                   # resize + solve rounds per cycle
    penalty_epsilon: float = param(0.1, ge=0)                   # safety margin inside the soft limits
    weight_max_vel_x: float = param(2.0, ge=0)
    weight_max_vel_y: float = param(2.0, ge=0)
    weight_max_vel_theta: float = param(1.0, ge=0)
    weight_acc_lim_x: float = param(1.0, ge=0)
    weight_acc_lim_y: float = param(1.0, ge=0)
    weight_acc_lim_theta: float = param(1.0, ge=0)
    weight_kinematics_nh: float = param(1000.0, ge=0)
    weight_kinematics_forward_drive: float = param(1.0, ge=0)
    weight_optimaltime: float = param(1.0, ge=0)
    weight_obstacle: float = param(50.0, ge=0)
    weight_inflation: float = param(0.1, ge=0)
    weight_dynamic_obstacle: float = param(50.0, ge=0)
    weight_dynamic_obstacle_inflation: float = param(0.1, ge=0)
    weight_strafe: float = param(0.0, ge=0)                     # holonomic: per (m/s)² sideways (ours; TEB: none)
    weight_adapt_factor: float = param(2.0, ge=1.0)             # weight_obstacle grows by this factor every outer iteration

    rules = (Rule("max_vel_y", lambda p: not p.holonomic_robot or (p.max_vel_y > 0 and p.acc_lim_y > 0),
                  "> 0, with acc_lim_y ({p.acc_lim_y}) > 0, on a holonomic robot"),
             Rule("dt_hysteresis", lambda p: p.dt_hysteresis < p.dt_ref, "below dt_ref ({p.dt_ref})"),
             Rule("inflation_dist", lambda p: p.inflation_dist >= p.min_obstacle_dist,
                  "at least min_obstacle_dist ({p.min_obstacle_dist})"),
             Rule("dynamic_obstacle_inflation_dist", lambda p: p.dynamic_obstacle_inflation_dist >= p.min_obstacle_dist,
                  "at least min_obstacle_dist ({p.min_obstacle_dist})"),
             Rule("max_samples", lambda p: p.max_samples >= p.min_samples, "at least min_samples ({p.min_samples})"))
