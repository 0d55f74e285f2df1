"""Elastic-band local planner after teb_local_planner (Rösmann et al., "timed elastic band").

One control cycle (`ElasticBandPlanner.compute`):
1. the local part of the global path — from the robot to max_global_plan_lookahead_dist along it,
   inside the costmap — is the band's span; its end is the local goal (the path's own heading at
   the path's final pose, else the path's direction there, as TEB's
   global_plan_overwrite_orientation);
2. the band: poses from the robot's pose to the local goal about dt_ref·max_vel_x apart with the
   time intervals between them; warm-started from the previous cycle's band when the path is the
   same (point for point within a cell: frame corrections between cycles are allowed) and the
   local goal moved less than force_reinit_new_goal_dist / _angular — poses behind the robot
   pruned, the ends moved to the robot and the new local goal;
3. no_outer_iterations times: the band is resized (intervals longer than dt_ref + dt_hysteresis
   split, shorter than dt_ref − dt_hysteresis merged) and its inner poses and the logarithms of
   its intervals are optimised by no_inner_iterations Levenberg–Marquardt steps, weight_obstacle
   growing by weight_adapt_factor each time. The residuals are TEB's edges, each squared error
   weighed by its weight: velocity and acceleration beyond the limits (shrunk by penalty_epsilon;
   the first acceleration from the robot's velocity, the last to standing still at the final
   goal unless free_goal_vel), each interval's length (time optimality), clearance below
   min_obstacle_dist + penalty_epsilon and below inflation_dist, and for a differential drive
   the non-holonomic arc condition and forward driving; start and end poses are fixed. The
   intervals are then stretched where a velocity limit is still exceeded (the penalties are soft);
4. the band, interpolated every half cell, is checked in the costmap by the local planner's
   FootprintCheck, as DWA's rollouts are (footprint_check.py) and, over its first feasibility_check_no_poses poses, its
   clearance must not fall more than a cell below min_obstacle_dist (or below the robot's own
   clearance when that is smaller); otherwise the status is no_valid_trajectory and the command
   brakes as hard as allowed. Else the command is the first interval's velocity, clipped to the
   velocity limits and to what the acceleration limits reach from the current velocity within
   one control period.

The solver: the unknowns are ordered pose by pose so that JᵀJ is a band matrix (every residual
touches neighbouring poses only); residuals and the analytic Jacobian come from one numba kernel
and each step solves the damped normal equations by a banded Cholesky factorisation (damping as
g2o's Levenberg–Marquardt, which TEB uses). scipy's least_squares on the same residuals and
Jacobian (`BandProblem.residuals` / `jacobian`; the tests compare the minima) reaches the same
minimum, but its dense QR costs about 1 ms per step for a 3 m band, 20 ms for TEB's 5 × 4 steps.

Clearance is the distance from the footprint to the nearest lethal or unknown cell: a signed
Euclidean distance field of those cells (interpolated bilinearly, negative inside obstacles so a
band through one is pushed out) minus the radius of circles covering the footprint: one circle per
slab of the footprint's length along the robot's x axis, as many slabs as the footprint is long
by wide (TEB's "two_circles"/"polygon" models measure to the polygon itself).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit

from ...schemas.messages import MapMetaData
from ..costmap.layers import LETHAL_OBSTACLE
from ...geometry.distance import distances_to
from ...geometry.se2 import wrap_angle
from ...geometry.movers import Movers
from ...geometry.polygons import arc_lengths, densify
from .dwa import local_path
from .dynamic import first_contact, slack
from .footprint_check import FootprintCheck
from .params import ElasticBandParams

MIN_INTERVAL = 1e-3     # s: the shortest time interval a new band starts with
FAR = 1e3               # m: clearance on a costmap without obstacles


# ---------------------------------------------------------------- geometry

def covering_circles(footprint: np.ndarray) -> tuple[np.ndarray, float]:
    """(offsets along the robot's x axis (C,), radius) of circles covering the footprint polygon."""
    points = np.asarray(footprint, np.float64).reshape(-1, 2)
    back, front = float(points[:, 0].min()), float(points[:, 0].max())
    side = float(np.abs(points[:, 1]).max())
    count = max(1, math.ceil((front - back) / max(2.0 * side, 1e-9) - 1e-9))
    half = (front - back) / (2 * count)
    return back + half * (2 * np.arange(count) + 1), math.hypot(half, side)


def clearance_field(costs: np.ndarray, resolution: float) -> np.ndarray:
    """(H, W) metres from each cell centre to the nearest lethal or unknown cell's edge; negative
    inside such cells (to their nearest free cell's edge)."""
    blocked = costs >= LETHAL_OBSTACLE
    if not blocked.any():
        return np.full(costs.shape, FAR)
    outside = distances_to(blocked)
    inside = distances_to(~blocked)
    return np.where(blocked, 0.5 - inside, outside - 0.5) * resolution


def _grid_frame(info: MapMetaData) -> np.ndarray:
    theta = info.origin.theta
    return np.array([info.origin.x, info.origin.y, math.cos(theta), math.sin(theta), 1.0 / info.resolution])


@njit(cache=True)
def _interpolate(field, x, y, grid):
    """(value, d/dx, d/dy) of the field, bilinear between cell centres, clamped at the border."""
    ox, oy, cos_o, sin_o, inv_res = grid[0], grid[1], grid[2], grid[3], grid[4]
    dx, dy = x - ox, y - oy
    u = (cos_o * dx + sin_o * dy) * inv_res - 0.5
    v = (-sin_o * dx + cos_o * dy) * inv_res - 0.5
    height, width = field.shape
    du_on, dv_on = 1.0, 1.0
    if u <= 0.0:
        u, du_on = 0.0, 0.0
    elif u >= width - 1:
        u, du_on = width - 1.0, 0.0
    if v <= 0.0:
        v, dv_on = 0.0, 0.0
    elif v >= height - 1:
        v, dv_on = height - 1.0, 0.0
    c0, r0 = min(int(u), width - 2), min(int(v), height - 2)
    fu, fv = u - c0, v - r0
    f00, f01 = field[r0, c0], field[r0, c0 + 1]
    f10, f11 = field[r0 + 1, c0], field[r0 + 1, c0 + 1]
    value = (f00 * (1 - fu) + f01 * fu) * (1 - fv) + (f10 * (1 - fu) + f11 * fu) * fv
    d_u = ((f01 - f00) * (1 - fv) + (f11 - f10) * fv) * du_on * inv_res
    d_v = ((f10 - f00) * (1 - fu) + (f11 - f01) * fu) * dv_on * inv_res
    return value, cos_o * d_u - sin_o * d_v, sin_o * d_u + cos_o * d_v


# ---------------------------------------------------------------- residuals, Jacobian, solver
#
# The unknowns are interleaved, x = (s_0, x_1, y_1, th_1, s_1, …, x_{K-2}, y_{K-2}, th_{K-2}, s_{K-2})
# with s_i the log of the i-th time interval (so intervals stay positive): every residual then
# touches unknowns at most BANDWIDTH apart and JᵀJ is a band matrix. Each residual row keeps its
# Jacobian entries as (column, value) pairs, at most ROW_WIDTH of them.

ROW_WIDTH = 16     # an acceleration row: two intervals' 7 unknowns
BANDWIDTH = 10     # an acceleration row spans poses i-1 … i+1 and intervals i-1, i
MAX_TRIES = 10     # damping increases per LM iteration before giving up
INITIAL_DAMPING = 1e-5   # × the largest diagonal entry of JᵀJ (g2o's and Nielsen's choice)


@njit(cache=True)
def _pose_column(i, n_poses):
    """The column of pose i's x (y and th follow); -1 for the fixed start and end poses."""
    return 4 * i - 3 if 1 <= i <= n_poses - 2 else -1


@njit(cache=True)
def _pack(poses, dts):
    n_poses = poses.shape[0]
    x = np.empty(4 * n_poses - 7)
    for i in range(n_poses - 1):
        x[4 * i] = math.log(dts[i])
    for i in range(1, n_poses - 1):
        x[4 * i - 3], x[4 * i - 2], x[4 * i - 1] = poses[i, 0], poses[i, 1], poses[i, 2]
    return x


@njit(cache=True)
def _unpack(x, start, goal):
    n_poses = (x.shape[0] + 7) // 4
    poses = np.empty((n_poses, 3))
    poses[0] = start
    poses[n_poses - 1] = goal
    dts = np.empty(n_poses - 1)
    for i in range(n_poses - 1):
        dts[i] = math.exp(x[4 * i])
    for i in range(1, n_poses - 1):
        poses[i, 0], poses[i, 1], poses[i, 2] = x[4 * i - 3], x[4 * i - 2], x[4 * i - 1]
    return poses, dts


@njit(cache=True)
def _excess(value, low, high, epsilon):
    """TEB's interval penalty (how far value lies outside [low, high] shrunk by epsilon, never
    across zero) and its derivative."""
    low = min(low + epsilon, 0.0)
    high = max(high - epsilon, 0.0)
    if value > high:
        return value - high, 1.0
    if value < low:
        return low - value, -1.0
    return 0.0, 0.0


@njit(cache=True)
def _shortfall(value, bound):
    """How far value falls below bound (0 above it), and its derivative."""
    if value < bound:
        return bound - value, -1.0
    return 0.0, 0.0


@njit(cache=True)
def _put(cols, vals, counts, row, col, value):
    if col >= 0 and value != 0.0:
        cols[row, counts[row]] = col
        vals[row, counts[row]] = value
        counts[row] += 1


@njit(cache=True)
def _put_all(cols, vals, counts, row, slots, gradient, scale):
    for k in range(slots.shape[0]):
        _put(cols, vals, counts, row, slots[k], scale * gradient[k])


@njit(cache=True)
def _n_residuals(n_poses, holonomic, n_circles, stop_at_goal, n_movers):
    axes = 3 if holonomic else 2
    per_interval = 5
    return ((n_poses - 1) * per_interval + (n_poses - 1 + stop_at_goal) * axes
            + (n_poses - 2) * n_circles * 2 * (1 + n_movers))


@njit(cache=True)
def _clearance_rows(res, cols, vals, counts, row, column, clearance, gx, gy, lever, bounds, weights):
    """Two rows (clearance below each bound, weighed) of one covering circle of the pose at `column`;
    (gx, gy) the clearance's gradient at the circle's centre, `lever` the centre's offset along the
    robot's heading (c, s); returns the next row."""
    c, s = lever[1], lever[2]
    for b in range(2):
        err, d = _shortfall(clearance, bounds[b])
        res[row] = weights[b] * err
        if d != 0.0:
            w = weights[b] * d
            _put(cols, vals, counts, row, column, w * gx)
            _put(cols, vals, counts, row, column + 1, w * gy)
            _put(cols, vals, counts, row, column + 2, w * lever[0] * (-s * gx + c * gy))
        row += 1
    return row


@njit(cache=True)
def _evaluate(x, start, goal, v_start, stop_at_goal, holonomic, limits, weights, epsilon, obstacle,
              field, grid, offsets, radius, movers, res, cols, vals, counts):
    """Fill the residuals `res` and the rows' Jacobian entries (cols, vals, counts); return the cost
    (half the squared norm).

    limits = (max_vel_x, max_vel_x_backwards, max_vel_y, max_vel_theta, acc_lim_x, acc_lim_y,
    acc_lim_theta); weights = square roots of (vel x, vel y, vel theta, acc x, acc y, acc theta,
    optimal time, nh, forward drive, obstacle, inflation, dynamic obstacle, dynamic inflation,
    strafe);
    obstacle = (min_obstacle_dist, inflation_dist, dynamic_obstacle_inflation_dist); movers (K, M, 3):
    each mover's predicted centre and radius at the time pose k is reached (held fixed while solving,
    as TEB's dynamic-obstacle edges hold it)."""
    poses, dts = _unpack(x, start, goal)
    n_poses = poses.shape[0]
    n_intervals = n_poses - 1
    counts[:] = 0
    axes = 3 if holonomic else 2
    component = np.array([0, 1, 2]) if holonomic else np.array([0, 2, 2])   # vx, (vy,) wz
    vel = np.empty((n_intervals, 3))
    grad = np.zeros((n_intervals, 3, 7))      # d vel / d (xi, yi, thi, xj, yj, thj, si)
    slots = np.full((n_intervals, 7), -1, np.int64)
    scratch = np.zeros(7)
    # not 0: a counter starting at a literal 0 has numba compile _put and _put_all once more, for Literal[int](0)
    row = np.int64(0)
    for i in range(n_intervals):
        j = i + 1
        for k in range(3):
            slots[i, k] = _pose_column(i, n_poses) + k if i >= 1 else -1
            slots[i, 3 + k] = _pose_column(j, n_poses) + k if j <= n_poses - 2 else -1
        slots[i, 6] = 4 * i
        dt = dts[i]
        dx, dy = poses[j, 0] - poses[i, 0], poses[j, 1] - poses[i, 1]
        c, s = math.cos(poses[i, 2]), math.sin(poses[i, 2])
        bx, by = c * dx + s * dy, -s * dx + c * dy
        turn = (poses[j, 2] - poses[i, 2] + math.pi) % (2.0 * math.pi) - math.pi
        vel[i, 0], vel[i, 1], vel[i, 2] = bx / dt, by / dt, turn / dt
        g = grad[i]
        g[0, 0], g[0, 1], g[0, 2], g[0, 3], g[0, 4], g[0, 6] = -c / dt, -s / dt, by / dt, c / dt, s / dt, -vel[i, 0]
        g[1, 0], g[1, 1], g[1, 2], g[1, 3], g[1, 4], g[1, 6] = s / dt, -c / dt, -bx / dt, -s / dt, c / dt, -vel[i, 1]
        g[2, 2], g[2, 5], g[2, 6] = -1.0 / dt, 1.0 / dt, -vel[i, 2]
        for a in range(axes):   # velocity limits
            k = component[a]
            low = -limits[1] if k == 0 else -limits[k + 1]
            high = limits[0] if k == 0 else limits[k + 1]
            err, d = _excess(vel[i, k], low, high, epsilon)
            res[row] = weights[k] * err
            if d != 0.0:
                _put_all(cols, vals, counts, row, slots[i], g[k], weights[k] * d)
            row += 1
        res[row] = weights[6] * dt   # time optimality
        _put(cols, vals, counts, row, 4 * i, weights[6] * dt)
        row += 1
        if holonomic:   # strafing, softly: a long robot faces the way it goes unless it must not
            res[row] = weights[13] * vel[i, 1]
            _put_all(cols, vals, counts, row, slots[i], g[1], weights[13])
            row += 1
        else:
            ci, si = math.cos(poses[i, 2]), math.sin(poses[i, 2])
            cj, sj = math.cos(poses[j, 2]), math.sin(poses[j, 2])
            # both poses on one arc: the chord bisects their headings
            res[row] = weights[7] * ((ci + cj) * dy - (si + sj) * dx)
            scratch[0], scratch[1], scratch[2] = si + sj, -(ci + cj), -si * dy - ci * dx
            scratch[3], scratch[4], scratch[5], scratch[6] = -(si + sj), ci + cj, -sj * dy - cj * dx, 0.0
            _put_all(cols, vals, counts, row, slots[i], scratch, weights[7])
            row += 1
            err, d = _shortfall(bx, 0.0)   # forward driving
            res[row] = weights[8] * err
            if d != 0.0:
                scratch[0], scratch[1], scratch[2], scratch[3], scratch[4], scratch[5] = -c, -s, by, c, s, 0.0
                _put_all(cols, vals, counts, row, slots[i], scratch, weights[8] * d)
            row += 1
    # accelerations: from the robot's velocity, between intervals, to standing still at the goal
    for m in range(n_intervals + stop_at_goal):
        before, after = m - 1, m
        if m == 0:
            span, d_span_before, d_span_after = dts[0], 0.0, dts[0]
        elif m == n_intervals:
            before, after = n_intervals - 1, -1
            span, d_span_before, d_span_after = dts[before], dts[before], 0.0
        else:
            span = 0.5 * (dts[before] + dts[after])
            d_span_before, d_span_after = 0.5 * dts[before], 0.5 * dts[after]
        for a in range(axes):
            k = component[a]
            v_after = vel[after, k] if after >= 0 else 0.0
            v_before = vel[before, k] if before >= 0 else v_start[k]
            acc = (v_after - v_before) / span
            err, d = _excess(acc, -limits[4 + k], limits[4 + k], epsilon)
            w = weights[3 + k]
            res[row] = w * err
            if d != 0.0:
                if after >= 0:
                    _put_all(cols, vals, counts, row, slots[after], grad[after, k], w * d / span)
                    _put(cols, vals, counts, row, 4 * after, -w * d * acc * d_span_after / span)
                if before >= 0:
                    _put_all(cols, vals, counts, row, slots[before], grad[before, k], -w * d / span)
                    _put(cols, vals, counts, row, 4 * before, -w * d * acc * d_span_before / span)
            row += 1
    # clearance of the inner poses from the static obstacles, then from each mover where it will be
    static_bounds = np.array([obstacle[0] + epsilon, obstacle[1]])
    dynamic_bounds = np.array([obstacle[0] + epsilon, obstacle[2]])
    lever = np.empty(3)
    for i in range(1, n_poses - 1):
        column = _pose_column(i, n_poses)
        lever[1], lever[2] = math.cos(poses[i, 2]), math.sin(poses[i, 2])
        for q in range(offsets.shape[0]):
            lever[0] = offsets[q]
            cx, cy = poses[i, 0] + lever[1] * offsets[q], poses[i, 1] + lever[2] * offsets[q]
            value, gx, gy = _interpolate(field, cx, cy, grid)
            row = _clearance_rows(res, cols, vals, counts, row, column, value - radius, gx, gy, lever,
                                  static_bounds, weights[9:11])
            for m in range(movers.shape[1]):
                ex, ey = cx - movers[i, m, 0], cy - movers[i, m, 1]
                distance = math.hypot(ex, ey)
                gx, gy = (ex / distance, ey / distance) if distance > 1e-9 else (1.0, 0.0)
                row = _clearance_rows(res, cols, vals, counts, row, column, distance - radius - movers[i, m, 2],
                                      gx, gy, lever, dynamic_bounds, weights[11:13])
    return 0.5 * np.dot(res, res)


@njit(cache=True)
def _row_buffers(rows):
    """(residuals, columns, values, counts) for `rows` residual rows."""
    return (np.empty(rows), np.empty((rows, ROW_WIDTH), np.int64), np.empty((rows, ROW_WIDTH)),
            np.empty(rows, np.int64))


@njit(cache=True)
def _normal_equations(res, cols, vals, counts, n):
    """(JᵀJ as a lower band, (BANDWIDTH + 1, n): entry (j + b, j) at [b, j]; Jᵀr)."""
    band = np.zeros((BANDWIDTH + 1, n))
    gradient = np.zeros(n)
    for row in range(res.shape[0]):
        for a in range(counts[row]):
            ca, va = cols[row, a], vals[row, a]
            gradient[ca] += va * res[row]
            for b in range(counts[row]):
                cb = cols[row, b]
                if cb <= ca:
                    band[ca - cb, cb] += va * vals[row, b]
    return band, gradient


@njit(cache=True)
def _band_cholesky_solve(band, rhs):
    """x with A x = rhs for the symmetric band matrix A (lower band storage); None when A is not
    positive definite."""
    n = rhs.shape[0]
    low = np.zeros_like(band)
    for j in range(n):
        total = band[0, j]
        for k in range(max(0, j - BANDWIDTH), j):
            total -= low[j - k, k] ** 2
        if total <= 0.0:
            return None
        low[0, j] = math.sqrt(total)
        for i in range(j + 1, min(n, j + BANDWIDTH + 1)):
            total = band[i - j, j]
            for k in range(max(0, i - BANDWIDTH), j):
                total -= low[i - k, k] * low[j - k, k]
            low[i - j, j] = total / low[0, j]
    y = np.empty(n)
    for i in range(n):
        total = rhs[i]
        for k in range(max(0, i - BANDWIDTH), i):
            total -= low[i - k, k] * y[k]
        y[i] = total / low[0, i]
    x = np.empty(n)
    for i in range(n - 1, -1, -1):
        total = y[i]
        for k in range(i + 1, min(n, i + BANDWIDTH + 1)):
            total -= low[k - i, i] * x[k]
        x[i] = total / low[0, i]
    return x


@njit(cache=True, nogil=True)     # TEB optimises its homotopy classes' bands on threads
def _levenberg_marquardt(x, iterations, start, goal, v_start, stop_at_goal, holonomic, limits, weights, epsilon,
                         obstacle, field, grid, offsets, radius, movers):
    """(x, cost) after `iterations` Levenberg–Marquardt steps as g2o takes them (damping λ·I,
    Nielsen's update, the normal equations solved in band form); stops early when no damping
    lowers the cost."""
    n_poses = (x.shape[0] + 7) // 4
    rows = _n_residuals(n_poses, holonomic, offsets.shape[0], stop_at_goal, movers.shape[1])
    res, cols, vals, counts = _row_buffers(rows)
    trial_res, trial_cols, trial_vals, trial_counts = _row_buffers(rows)
    cost = _evaluate(x, start, goal, v_start, stop_at_goal, holonomic, limits, weights, epsilon, obstacle,
                     field, grid, offsets, radius, movers, res, cols, vals, counts)
    damping, growth = -1.0, 2.0
    for _ in range(iterations):
        band, gradient = _normal_equations(res, cols, vals, counts, x.shape[0])
        if damping < 0.0:
            damping = INITIAL_DAMPING * max(band[0].max(), 1e-12)
        improved = False
        for _ in range(MAX_TRIES):
            damped = band.copy()
            damped[0] += damping
            step = _band_cholesky_solve(damped, -gradient)
            if step is not None:
                trial = x + step
                trial_cost = _evaluate(trial, start, goal, v_start, stop_at_goal, holonomic, limits, weights,
                                       epsilon, obstacle, field, grid, offsets, radius, movers, trial_res,
                                       trial_cols, trial_vals, trial_counts)
                predicted = 0.5 * (damping * np.dot(step, step) - np.dot(gradient, step))
                if trial_cost < cost and predicted > 0.0:
                    gain = (cost - trial_cost) / predicted
                    x, cost = trial, trial_cost
                    res, trial_res = trial_res, res
                    cols, trial_cols = trial_cols, cols
                    vals, trial_vals = trial_vals, vals
                    counts, trial_counts = trial_counts, counts
                    damping *= max(1.0 / 3.0, 1.0 - (2.0 * gain - 1.0) ** 3)
                    growth = 2.0
                    improved = True
                    break
            damping *= growth
            growth *= 2.0
        if not improved:
            break
    return x, cost


@njit(cache=True)
def _clearances(poses, field, grid, offsets, radius):
    """(N,) the smallest clearance of the covering circles at each pose."""
    out = np.empty(poses.shape[0])
    for i in range(poses.shape[0]):
        c, s = math.cos(poses[i, 2]), math.sin(poses[i, 2])
        lowest = np.inf
        for q in range(offsets.shape[0]):
            value = _interpolate(field, poses[i, 0] + c * offsets[q], poses[i, 1] + s * offsets[q], grid)[0]
            lowest = min(lowest, value - radius)
        out[i] = lowest
    return out


class BandProblem:
    """One outer iteration's least-squares problem over a band with fixed ends: `solve` runs the
    banded Levenberg–Marquardt; `residuals` / `jacobian` (dense) give the same problem to any
    other least-squares solver (scipy's, in the tests)."""

    def __init__(self, planner: ElasticBandPlanner, poses, dts, velocity, stop_at_goal: bool, field, info,
                 outer: int = 0, movers: Movers | None = None, weights: np.ndarray | None = None):
        p = planner.params
        self.start, self.goal = np.array(poses[0], np.float64), np.array(poses[-1], np.float64)
        dts = np.asarray(dts, np.float64)
        self.x0 = _pack(np.asarray(poses, np.float64), dts)
        predicted = planner.predicted(dts, movers)
        self._args = (self.start, self.goal, np.asarray(velocity, np.float64), int(stop_at_goal), p.holonomic_robot,
                      planner.limits, planner.weights(outer) if weights is None else weights, p.penalty_epsilon,
                      np.array([p.min_obstacle_dist, p.inflation_dist, p.dynamic_obstacle_inflation_dist]), field,
                      _grid_frame(info), planner.offsets, planner.radius, predicted)
        self.rows = _n_residuals(len(poses), p.holonomic_robot, len(planner.offsets), int(stop_at_goal),
                                 predicted.shape[1])

    def _rows(self, x):
        res, cols, vals, counts = _row_buffers(self.rows)
        _evaluate(np.asarray(x, np.float64), *self._args, res, cols, vals, counts)
        return res, cols, vals, counts

    def residuals(self, x) -> np.ndarray:
        return self._rows(x)[0]

    def cost(self) -> float:
        """Half the squared norm of the residuals where the problem starts."""
        return 0.5 * float(np.dot(*(self.residuals(self.x0),) * 2))

    def jacobian(self, x) -> np.ndarray:
        _, cols, vals, counts = self._rows(x)
        dense = np.zeros((self.rows, len(self.x0)))
        for row in range(self.rows):
            np.add.at(dense[row], cols[row, :counts[row]], vals[row, :counts[row]])
        return dense

    def solve(self, iterations: int) -> tuple[np.ndarray, np.ndarray, float]:
        """(poses, time intervals, cost) after the solver's iterations."""
        x, cost = _levenberg_marquardt(self.x0.copy(), iterations, *self._args)
        poses, dts = _unpack(x, self.start, self.goal)
        return poses, dts, cost



# ---------------------------------------------------------------- band construction

def span_path(path: np.ndarray, pose, info: MapMetaData, lookahead: float) -> tuple[np.ndarray, bool] | None:
    """(the robot's position followed by the local path up to `lookahead` metres along it, (M, 3);
    whether it ends at the path's final pose), or None when no path point lies on the grid."""
    path = np.asarray(path, np.float64).reshape(-1, 3)
    local = local_path(path, pose, info)
    if len(local) == 0:
        return None
    whole = np.array_equal(local[-1], path[-1])
    # the nearest path point may lie behind the robot: start from the next one then
    if len(local) > 1 and np.dot(np.asarray(pose[:2]) - local[0, :2], local[1, :2] - local[0, :2]) > 0:
        local = local[1:]
    points = np.vstack([np.array([[pose[0], pose[1], pose[2]]], np.float64), local])
    along = arc_lengths(points)
    if along[-1] <= lookahead:
        return points, whole
    cut = int(np.searchsorted(along, lookahead))
    fraction = (lookahead - along[cut - 1]) / (along[cut] - along[cut - 1])
    end = points[cut - 1] + fraction * (points[cut] - points[cut - 1])
    end[2] = math.atan2(*(points[cut, 1::-1] - points[cut - 1, 1::-1]))
    return np.vstack([points[:cut], end]), False


def local_goal(span: np.ndarray, at_final_goal: bool) -> np.ndarray:
    """The band's end: the path's pose at its final goal, else heading along the path."""
    if at_final_goal or len(span) < 2:
        return span[-1].copy()
    direction = span[-1, :2] - span[-2, :2]
    return np.array([span[-1, 0], span[-1, 1], math.atan2(direction[1], direction[0])])


def initial_band(span: np.ndarray, start, goal, params: ElasticBandParams) -> tuple[np.ndarray, np.ndarray]:
    """(poses (K, 3), time intervals (K-1,)) along the span, about dt_ref·max_vel_x apart."""
    spacing = params.dt_ref * params.max_vel_x
    dense = densify(span, spacing / 4)
    along = arc_lengths(dense)
    count = max(params.min_samples, min(params.max_samples, int(math.ceil(along[-1] / spacing)) + 1))
    stations = np.linspace(0.0, along[-1], count)
    xy = np.column_stack([np.interp(stations, along, dense[:, 0]), np.interp(stations, along, dense[:, 1])])
    start, goal = np.asarray(start, np.float64), np.asarray(goal, np.float64)
    if params.holonomic_robot:   # turn evenly from the robot's heading to the goal's
        fraction = stations / along[-1] if along[-1] > 0 else np.linspace(0.0, 1.0, count)
        heading = start[2] + fraction * wrap_angle(goal[2] - start[2])
    else:                        # face along the band
        step = np.diff(xy, axis=0)
        heading = np.concatenate([[start[2]], np.arctan2(step[1:, 1], step[1:, 0]), [goal[2]]])
        heading = start[2] + np.concatenate([[0.0], np.cumsum(wrap_angle(np.diff(heading)))])
    poses = np.column_stack([xy, heading])
    poses[0], poses[-1] = start, goal
    return poses, _intervals(poses, params)


def _intervals(poses: np.ndarray, params: ElasticBandParams) -> np.ndarray:
    """Time intervals driving each step at the velocity limits."""
    step = np.diff(poses, axis=0)
    return np.maximum(MIN_INTERVAL, np.maximum(np.hypot(step[:, 0], step[:, 1]) / params.max_vel_x,
                                               np.abs(wrap_angle(step[:, 2])) / params.max_vel_theta))


def resize(poses: np.ndarray, dts: np.ndarray, params: ElasticBandParams) -> tuple[np.ndarray, np.ndarray]:
    """TEB's autoResize: split intervals above dt_ref + dt_hysteresis, merge those below
    dt_ref − dt_hysteresis into their neighbour, within min_samples … max_samples poses."""
    poses, dts = list(poses), list(dts)
    i = 0
    while i < len(dts):
        if dts[i] > params.dt_ref + params.dt_hysteresis and len(poses) < params.max_samples:
            a, b = poses[i], poses[i + 1]
            middle = np.array([(a[0] + b[0]) / 2, (a[1] + b[1]) / 2, a[2] + wrap_angle(b[2] - a[2]) / 2])
            poses.insert(i + 1, middle)
            dts[i:i + 1] = [dts[i] / 2, dts[i] / 2]
            i += 2
        elif dts[i] < params.dt_ref - params.dt_hysteresis and len(poses) > params.min_samples:
            if i + 1 < len(dts):     # drop the pose after this interval
                del poses[i + 1]
                dts[i:i + 2] = [dts[i] + dts[i + 1]]
            elif i > 0:              # the last interval: drop the pose before it (the goal stays)
                del poses[i]
                dts[i - 1:i + 1] = [dts[i - 1] + dts[i]]
            i += 1
        else:
            i += 1
    return np.array(poses), np.array(dts)


# ---------------------------------------------------------------- the planner

@dataclass(frozen=True)
class EbandResult:
    status: str                 # ok | no_valid_trajectory | no_path
    cmd: np.ndarray             # (3,) vx, vy, wz to send
    trajectory: np.ndarray      # (K, 3) optimised band poses in the costmap frame; (0, 3) without a path
    time_intervals: np.ndarray  # (K-1,) s between consecutive band poses
    message: str = ""
    clearance: float = math.inf  # m: the smallest clearance (covering circles to obstacles) of the checked poses
    warm_started: bool = False


@dataclass
class Band:
    """An optimised band and the path it was made on (the next cycle warm-starts from it)."""
    path: np.ndarray
    poses: np.ndarray
    dts: np.ndarray

    def warm(self, path, start, goal, resolution: float, params: ElasticBandParams) -> tuple[np.ndarray, np.ndarray] | None:
        """(poses, dts) of this band moved to this cycle's ends, or None when it does not apply: the
        path changed beyond a cell (frame corrections between cycles are allowed), the local goal
        moved past force_reinit_new_goal_dist / _angular, or too few poses lie ahead of the robot."""
        if self.path.shape != path.shape or np.abs(self.path[:, :2] - path[:, :2]).max(initial=0.0) > resolution:
            return None
        old_goal = self.poses[-1]
        if (math.hypot(*(goal[:2] - old_goal[:2])) > params.force_reinit_new_goal_dist
                or abs(wrap_angle(goal[2] - old_goal[2])) > params.force_reinit_new_goal_angular):
            return None
        nearest = int(np.argmin(np.hypot(*(self.poses[:-1, :2] - start[:2]).T)))
        poses, dts = self.poses[nearest:].copy(), self.dts[nearest:].copy()
        if len(poses) < params.min_samples:
            return None
        poses[0], poses[-1] = start, goal
        # keep headings continuous from the robot's, the ends exactly as given
        poses[1:-1, 2] = start[2] + np.cumsum(wrap_angle(np.diff(poses[:-1, 2])))
        poses[-1, 2] = poses[-2, 2] + wrap_angle(goal[2] - poses[-2, 2])
        return poses, dts


class ElasticBandPlanner:
    """The pure elastic-band core: `compute` is one control cycle; the planner keeps the last band
    to warm-start the next cycle on the same path. `footprint_check` is the local planner's one
    collision check (footprint_check.py: the padded footprint, its check cost and stop zone), the
    same DWA's rollouts are held to."""

    def __init__(self, params: ElasticBandParams, footprint_check: FootprintCheck):
        self.params = params
        self.footprint_check = footprint_check
        self.footprint = footprint_check.footprint
        self.offsets, self.radius = covering_circles(self.footprint)
        self.reach = float(np.hypot(self.footprint[:, 0], self.footprint[:, 1]).max())
        self._band: Band | None = None
        p = params
        self.limits = np.array([p.max_vel_x, p.max_vel_x_backwards, p.max_vel_y if p.holonomic_robot else 0.0,
                                 p.max_vel_theta, p.acc_lim_x, p.acc_lim_y, p.acc_lim_theta])

    def reset(self) -> None:
        """Forget the previous band (a new goal, or after a recovery)."""
        self._band = None

    def weights(self, outer: int) -> np.ndarray:
        """The square roots of TEB's weights (residuals are squared), in _evaluate's order, for
        outer iteration `outer`."""
        p = self.params
        return np.sqrt([p.weight_max_vel_x, p.weight_max_vel_y, p.weight_max_vel_theta, p.weight_acc_lim_x,
                        p.weight_acc_lim_y, p.weight_acc_lim_theta, p.weight_optimaltime, p.weight_kinematics_nh,
                        p.weight_kinematics_forward_drive,
                        p.weight_obstacle * p.weight_adapt_factor ** outer, p.weight_inflation,
                        p.weight_dynamic_obstacle * p.weight_adapt_factor ** outer,
                        p.weight_dynamic_obstacle_inflation, p.weight_strafe])

    def predicted(self, dts: np.ndarray, movers: Movers | None) -> np.ndarray:
        """(K, M, 3) the movers where they will be as the band reaches each pose (none unless
        include_dynamic_obstacles)."""
        if movers is None or not self.params.include_dynamic_obstacles:
            return np.zeros((len(dts) + 1, 0, 3))
        return movers.along(np.concatenate([[0.0], np.cumsum(dts)]), self.params.dynamic_obstacle_sigmas)

    def optimise(self, poses, dts, velocity, stop_at_goal: bool, field, info: MapMetaData,
                 movers: Movers | None = None):
        """The band after no_outer_iterations rounds of resizing and no_inner_iterations solver
        steps, its intervals then stretched where a velocity limit is still exceeded; the movers'
        predicted places are taken at the band's times as each round begins."""
        p = self.params
        for outer in range(p.no_outer_iterations):
            poses, dts = resize(poses, dts, p)
            poses, dts, _ = BandProblem(self, poses, dts, velocity, stop_at_goal, field, info, outer,
                                        movers).solve(p.no_inner_iterations)
        return poses, np.maximum(dts, self.shortest_intervals(poses))

    def shortest_intervals(self, poses: np.ndarray) -> np.ndarray:
        """(K-1,) the shortest time each band step takes within the velocity limits (the soft
        penalties alone let the optimum exceed them a little); a diff drive's sideways residue is
        the non-holonomic penalty's, not a velocity."""
        p = self.params
        c, s = np.cos(poses[:-1, 2]), np.sin(poses[:-1, 2])
        step = np.diff(poses, axis=0)
        ahead, left = c * step[:, 0] + s * step[:, 1], -s * step[:, 0] + c * step[:, 1]
        need = np.maximum(np.where(ahead > 0, ahead / p.max_vel_x, -ahead / max(p.max_vel_x_backwards, 1e-9)),
                          np.abs(wrap_angle(step[:, 2])) / p.max_vel_theta)
        if p.holonomic_robot:
            need = np.maximum(need, np.abs(left) / p.max_vel_y)
        return need

    def command(self, poses: np.ndarray, dts: np.ndarray, velocity) -> np.ndarray:
        """The first interval's body twist, within the velocity limits and one control period's reach."""
        p = self.params
        c, s = math.cos(poses[0, 2]), math.sin(poses[0, 2])
        dx, dy = poses[1, 0] - poses[0, 0], poses[1, 1] - poses[0, 1]
        twist = np.array([c * dx + s * dy, -s * dx + c * dy, float(wrap_angle(poses[1, 2] - poses[0, 2]))]) / dts[0]
        twist = np.clip(twist, [-p.max_vel_x_backwards, -self.limits[2], -p.max_vel_theta],
                        [p.max_vel_x, self.limits[2], p.max_vel_theta])
        low, high = self._reach(velocity)
        return np.clip(twist, low, high)

    def _reach(self, velocity) -> tuple[np.ndarray, np.ndarray]:
        p = self.params
        v = np.asarray(velocity, np.float64)
        reach = (np.array([p.acc_lim_x, p.acc_lim_y if p.holonomic_robot else 0.0, p.acc_lim_theta])
                 / p.controller_frequency)
        low, high = v - reach, v + reach
        if not p.holonomic_robot:
            low[1] = high[1] = 0.0
        return low, high

    def span(self, pose: np.ndarray, path: np.ndarray, info: MapMetaData) -> tuple[np.ndarray, np.ndarray, bool] | None:
        """(the local path the band spans, its local goal, whether that is the path's final goal),
        or None when no point of the path lies on the local costmap."""
        span = span_path(path, pose, info, self.params.max_global_plan_lookahead_dist)
        if span is None:
            return None
        span, at_final_goal = span
        return span, local_goal(span, at_final_goal), at_final_goal

    def stops_at_goal(self, at_final_goal: bool) -> bool:
        return at_final_goal and not self.params.free_goal_vel

    def problem(self, poses: np.ndarray, dts: np.ndarray, costs: np.ndarray, info: MapMetaData, field,
                movers: Movers | None = None, whole: bool = True) -> tuple[str, float]:
        """(why the optimised band may not be driven, or ''; its smallest clearance over the checked
        poses): it collides on the costmap (checked as DWA checks its rollouts, from the robot's pose,
        the band's first; `whole`: all the band, else its first feasibility_check_no_poses poses, as
        TEB checks), comes more than a cell below min_obstacle_dist (or the robot's own clearance when
        smaller) within feasibility_check_no_poses poses, or — with include_dynamic_obstacles — meets
        a mover there sooner than standing still would (dynamic.py's rule: standing in a person's way
        is no refuge)."""
        p = self.params
        dense, where = _interpolate_band(poses, info.resolution / 2, self.reach)
        # the clearance rule, as TEB's feasibility check, holds for the first feasibility_check_no_poses
        # poses only: further on the band is still being shaped by the coming cycles
        near = where[min(p.feasibility_check_no_poses, len(poses) - 1)]
        clearance = _clearances(dense[:near + 1], field, _grid_frame(info), self.offsets, self.radius)
        closest = float(clearance.min())
        if not self.footprint_check.legal_poses(dense if whole else dense[:near + 1], costs, info)[1:].all():
            return "the optimised band collides in the costmap; braking", closest
        if closest < min(p.min_obstacle_dist, float(clearance[0])) - info.resolution:
            return (f"the optimised band comes within {max(closest, 0.0):.2f} m of an obstacle "
                    f"(min_obstacle_dist {p.min_obstacle_dist} m); braking"), closest
        if movers is not None and len(movers) and p.include_dynamic_obstacles:
            times = np.interp(np.arange(near + 1), where, np.concatenate([[0.0], np.cumsum(dts)]))
            checked = dense[None, :near + 1]
            footprint = self.footprint_check.footprint
            hard, _ = slack(checked, times, footprint, movers, 0.0, 0.0)
            standing, _ = slack(np.repeat(dense[None, :1], near + 1, axis=1), times, footprint, movers, 0.0, 0.0)
            if first_contact(hard)[0] < first_contact(standing)[0]:
                return "the optimised band meets a mover sooner than standing still would; braking", closest
        return "", closest

    def compute(self, pose, velocity, costs: np.ndarray, info: MapMetaData, path: np.ndarray,
                movers: Movers | None = None) -> EbandResult:
        """One cycle: pose (x, y, yaw) and path (N, 3) in the costmap's frame, velocity (vx, vy, wz)
        in the robot frame, movers (the tracker's tracks at this instant, in the costmap's frame)
        heeded with include_dynamic_obstacles."""
        pose = np.asarray(pose, np.float64)
        path = np.asarray(path, np.float64).reshape(-1, 3)
        brake = self.brake(velocity)
        spanned = self.span(pose, path, info)
        if spanned is None:
            self._band = None
            return EbandResult("no_path", brake, np.zeros((0, 3)), np.zeros(0),
                               "no point of the path lies on the local costmap")
        span, goal, at_final_goal = spanned
        warm = self._band.warm(path, pose, goal, info.resolution, self.params) if self._band is not None else None
        poses, dts = warm if warm is not None else initial_band(span, pose, goal, self.params)
        field = clearance_field(costs, info.resolution)
        poses, dts = self.optimise(poses, dts, velocity, self.stops_at_goal(at_final_goal), field, info, movers)
        poses[:, 2] = wrap_angle(poses[:, 2])
        self._band = Band(path.copy(), poses, dts)
        problem, closest = self.problem(poses, dts, costs, info, field, movers)
        if problem:
            return EbandResult("no_valid_trajectory", brake, poses, dts, problem, closest, warm is not None)
        return EbandResult("ok", self.command(poses, dts, velocity), poses, dts, "", closest, warm is not None)

    def brake(self, velocity) -> np.ndarray:
        """The twist braking as hard as the acceleration limits allow."""
        return np.clip(0.0, *self._reach(velocity))


def _interpolate_band(poses: np.ndarray, spacing: float, reach: float) -> tuple[np.ndarray, np.ndarray]:
    """((N, 3) poses along the band, linear between band poses (headings turned the short way), so
    that no point within `reach` of the robot's centre moves more than `spacing` between them;
    (K,) the index among them of each band pose)."""
    step = np.diff(poses, axis=0)
    step[:, 2] = wrap_angle(step[:, 2])
    counts = np.maximum(1, np.ceil(np.maximum(np.hypot(step[:, 0], step[:, 1]), np.abs(step[:, 2]) * reach)
                                   / spacing).astype(np.int64))
    segment = np.repeat(np.arange(len(counts)), counts)
    fraction = (np.arange(segment.size) - np.repeat(np.cumsum(counts) - counts, counts)) / counts[segment]
    inner = poses[segment] + step[segment] * fraction[:, None]
    return np.vstack([inner, poses[-1:]]), np.concatenate([[0], np.cumsum(counts)])


def warm_up() -> None:
    """Compile (or load from cache) the numba kernels (the mover terms' and checks' too: TEB's are
    these), outside any control cycle."""
    info = MapMetaData(resolution=0.1, width=20, height=20)
    square = np.array([[0.1, 0.1], [-0.1, 0.1], [-0.1, -0.1], [0.1, -0.1]])
    path = np.column_stack([np.linspace(0.5, 1.5, 5), np.full(5, 1.0), np.zeros(5)])
    costs = np.zeros((20, 20), np.uint8)
    costs[0] = LETHAL_OBSTACLE
    movers = Movers(np.array([[1.2, 1.5]]), np.array([[0.0, -0.3]]), np.full(1, 0.2), np.zeros((1, 3)))
    for holonomic in (True, False):
        params = ElasticBandParams(holonomic_robot=holonomic, max_vel_y=0.1, include_dynamic_obstacles=True)
        ElasticBandPlanner(params, FootprintCheck(square)).compute((0.5, 1.0, 0.0), (0.0, 0.0, 0.0), costs, info, path,
                                                                    movers)
