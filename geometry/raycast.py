"""Ray casting kernels (numba): exact distances to segments and circles, and grid traversal through
an occupancy grid (Amanatides & Woo). The simulated lidar (sim/lidar.py) and the localizer's beam
model (services/localizer/sensor.py) both cast with these."""
from __future__ import annotations

import math

import numpy as np
from numba import njit


@njit(cache=True)
def cast_shapes(ox, oy, angles, segments, circles, max_range):
    """Distances from (ox, oy) along `angles` to the first of the segments (N, 4: x1 y1 x2 y2) and
    circles (M, 3: x y r); inf where nothing lies within max_range."""
    out = np.full(angles.shape[0], np.inf)
    for k in range(angles.shape[0]):
        dx, dy = math.cos(angles[k]), math.sin(angles[k])
        best, found = max_range, False
        for n in range(segments.shape[0]):
            ax, ay = segments[n, 0], segments[n, 1]
            ex, ey = segments[n, 2] - ax, segments[n, 3] - ay
            denom = dx * ey - dy * ex
            if denom == 0.0:  # parallel: the solid's other edges catch the ray
                continue
            wx, wy = ax - ox, ay - oy
            t = (wx * ey - wy * ex) / denom
            s = (wx * dy - wy * dx) / denom
            if 0.0 <= t <= best and 0.0 <= s <= 1.0:
                best, found = t, True
        for m in range(circles.shape[0]):
            fx, fy, r = ox - circles[m, 0], oy - circles[m, 1], circles[m, 2]
            b = fx * dx + fy * dy
            c = fx * fx + fy * fy - r * r
            if c <= 0.0:
                t = 0.0  # the laser is inside the circle
            else:
                disc = b * b - c
                if disc < 0.0 or b > 0.0:  # misses, or lies behind
                    continue
                t = -b - math.sqrt(disc)
            if t <= best:
                best, found = t, True
        if found:
            out[k] = best
    return out


@njit(cache=True)
def cast_grid(u0, v0, angles, occupied, max_t):
    """Distances in cells from (u0, v0) (grid coordinates) to the first occupied cell."""
    height, width = occupied.shape
    out = np.full(angles.shape[0], np.inf)
    for k in range(angles.shape[0]):
        du, dv = math.cos(angles[k]), math.sin(angles[k])
        t0, t1 = 0.0, max_t
        if du != 0.0:  # clip the ray to the grid's box
            ta, tb = -u0 / du, (width - u0) / du
            t0, t1 = max(t0, min(ta, tb)), min(t1, max(ta, tb))
        elif not 0.0 <= u0 < width:
            continue
        if dv != 0.0:
            ta, tb = -v0 / dv, (height - v0) / dv
            t0, t1 = max(t0, min(ta, tb)), min(t1, max(ta, tb))
        elif not 0.0 <= v0 < height:
            continue
        if t0 > t1:
            continue
        u, v = u0 + t0 * du, v0 + t0 * dv
        col = min(max(int(math.floor(u)), 0), width - 1)
        row = min(max(int(math.floor(v)), 0), height - 1)
        step_c, next_u, delta_u = 0, np.inf, np.inf
        if du > 0.0:
            step_c, next_u, delta_u = 1, t0 + (col + 1 - u) / du, 1.0 / du
        elif du < 0.0:
            step_c, next_u, delta_u = -1, t0 + (col - u) / du, -1.0 / du
        step_r, next_v, delta_v = 0, np.inf, np.inf
        if dv > 0.0:
            step_r, next_v, delta_v = 1, t0 + (row + 1 - v) / dv, 1.0 / dv
        elif dv < 0.0:
            step_r, next_v, delta_v = -1, t0 + (row - v) / dv, -1.0 / dv
        t = t0
        while t <= t1:
            if occupied[row, col]:
                out[k] = t
                break
            if next_u < next_v:
                t, col, next_u = next_u, col + step_c, next_u + delta_u
                if col < 0 or col >= width:
                    break
            else:
                t, row, next_v = next_v, row + step_r, next_v + delta_v
                if row < 0 or row >= height:
                    break
    return out
