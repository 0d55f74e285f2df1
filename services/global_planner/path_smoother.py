"""A path smoother that never moves the path into higher cost.

Gradient smoothing (as Nav2's simple smoother: each point is pulled towards its original position
and towards its neighbours' midpoint, points updated in place, until nothing moves more than a
tolerance), with one constraint per move: a point may only move to a cell whose cost is at most
the cost of its original cell, and the two path segments meeting at it may only cross cells whose
cost is at most the larger bound of their end points. So no point of the path ever gets costlier,
and the straight segments between points never cross a cell costlier than the path had there.

Points are in continuous grid coordinates: u along columns, v along rows, cell (r, c) spanning
[c, c + 1) × [r, r + 1).
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

from ...geometry.grid import kernel_costs

_TIE = 1e-12   # a segment through a cell corner steps diagonally, touching neither side cell


@njit(cache=True)
def segment_max_cost(costs, u0, v0, u1, v1):
    """Largest cost of the cells a straight segment crosses (grid traversal, ends included)."""
    height, width = costs.shape
    col = min(max(int(math.floor(u0)), 0), width - 1)
    row = min(max(int(math.floor(v0)), 0), height - 1)
    end_col = min(max(int(math.floor(u1)), 0), width - 1)
    end_row = min(max(int(math.floor(v1)), 0), height - 1)
    worst = costs[row, col]
    du, dv = u1 - u0, v1 - v0
    step_c, next_u, delta_u = 0, np.inf, np.inf
    if du > 0.0:
        step_c, next_u, delta_u = 1, (col + 1 - u0) / du, 1.0 / du
    elif du < 0.0:
        step_c, next_u, delta_u = -1, (col - u0) / du, -1.0 / du
    step_r, next_v, delta_v = 0, np.inf, np.inf
    if dv > 0.0:
        step_r, next_v, delta_v = 1, (row + 1 - v0) / dv, 1.0 / dv
    elif dv < 0.0:
        step_r, next_v, delta_v = -1, (row - v0) / dv, -1.0 / dv
    while row != end_row or col != end_col:
        t = min(next_u, next_v)
        if t > 1.0:
            break
        if abs(next_u - next_v) <= _TIE:
            col, row = col + step_c, row + step_r
            next_u, next_v = next_u + delta_u, next_v + delta_v
        elif next_u < next_v:
            col, next_u = col + step_c, next_u + delta_u
        else:
            row, next_v = row + step_r, next_v + delta_v
        if not (0 <= row < height and 0 <= col < width):
            break
        worst = max(worst, costs[row, col])
    return worst


@njit(cache=True)
def _smooth(points, bounds, costs, w_data, w_smooth, max_iterations, tolerance):
    height, width = costs.shape
    out = points.copy()
    n = points.shape[0]
    # changed[j]: point j moved at its last update. A point whose inputs (itself and both
    # neighbours) did not change since its last update would be proposed the same move and get
    # the same answer, so it is skipped: on straight runs, which the smoothing leaves where they are,
    # that is most of the path. Updated in place, changed[i - 1] already says this sweep's news.
    changed = np.ones(n, np.bool_)
    changed[0] = changed[n - 1] = False
    for _ in range(max_iterations):
        moved = 0.0
        for i in range(1, n - 1):
            if not (changed[i - 1] or changed[i] or changed[i + 1]):
                continue
            changed[i] = False
            pu = out[i, 0] + w_data * (points[i, 0] - out[i, 0]) \
                + w_smooth * (out[i - 1, 0] + out[i + 1, 0] - 2.0 * out[i, 0])
            pv = out[i, 1] + w_data * (points[i, 1] - out[i, 1]) \
                + w_smooth * (out[i - 1, 1] + out[i + 1, 1] - 2.0 * out[i, 1])
            if not (0.0 <= pu < width and 0.0 <= pv < height):
                continue
            if costs[int(pv), int(pu)] > bounds[i]:
                continue
            if segment_max_cost(costs, out[i - 1, 0], out[i - 1, 1], pu, pv) > max(bounds[i - 1], bounds[i]):
                continue
            if segment_max_cost(costs, pu, pv, out[i + 1, 0], out[i + 1, 1]) > max(bounds[i], bounds[i + 1]):
                continue
            moved = max(moved, math.hypot(pu - out[i, 0], pv - out[i, 1]))
            changed[i] = pu != out[i, 0] or pv != out[i, 1]
            out[i, 0], out[i, 1] = pu, pv
        if moved < tolerance:
            break
    return out


def smooth(points: np.ndarray, costs: np.ndarray, weight_data: float = 0.2, weight_smooth: float = 0.3,
           max_iterations: int = 100, tolerance: float = 1e-3) -> np.ndarray:
    """The smoothed path (same number of points, end points fixed) for points (N, 2) in grid
    coordinates over uint8 costs; each point's cell cost stays at most its original cell's."""
    points = np.ascontiguousarray(points, np.float64)
    if len(points) < 3:
        return points.copy()
    rows = np.clip(np.floor(points[:, 1]).astype(np.int64), 0, costs.shape[0] - 1)
    cols = np.clip(np.floor(points[:, 0]).astype(np.int64), 0, costs.shape[1] - 1)
    bounds = costs[rows, cols].astype(np.int64)
    return _smooth(points, bounds, kernel_costs(costs), float(weight_data), float(weight_smooth),
                   int(max_iterations), float(tolerance))
