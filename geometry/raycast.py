"""Ray casting kernels (numba): exact distances to segments and circles, and grid traversal through
an occupancy grid (Amanatides & Woo). The simulated lidar (sim/lidar.py) and the localizer's beam
model (services/localizer/sensor.py) both cast with these; the lidar also takes, for each hit, the
cosine of the angle between the ray and the surface normal (1 head-on, 0 grazing), which its sensor
model needs for returns that fail at grazing incidence."""
from __future__ import annotations

import math

import numpy as np
from numba import njit


@njit(cache=True)
def cast_shapes(ox, oy, angles, segments, circles, max_range):
    """Distances from (ox, oy) along `angles` to the first of the segments (N, 4: x1 y1 x2 y2) and
    circles (M, 3: x y r), inf where nothing lies within max_range; and the incidence cosine of each
    hit (1 where nothing is hit, and from inside a circle)."""
    out = np.full(angles.shape[0], np.inf)
    cosines = np.ones(angles.shape[0])
    for k in range(angles.shape[0]):
        dx, dy = math.cos(angles[k]), math.sin(angles[k])
        best, found, cosine = max_range, False, 1.0
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
                cosine = abs(denom) / math.sqrt(ex * ex + ey * ey)  # |sin| of the ray against the edge
        for m in range(circles.shape[0]):
            fx, fy, r = ox - circles[m, 0], oy - circles[m, 1], circles[m, 2]
            b = fx * dx + fy * dy
            c = fx * fx + fy * fy - r * r
            if c <= 0.0:
                t, along_normal = 0.0, 1.0  # the laser is inside the circle
            else:
                disc = b * b - c
                if disc < 0.0 or b > 0.0:  # misses, or lies behind
                    continue
                t = -b - math.sqrt(disc)
                along_normal = math.sqrt(disc) / r  # the ray against the radius to the hit point
            if t <= best:
                best, found, cosine = t, True, along_normal
        if found:
            out[k] = best
            cosines[k] = cosine
    return out, cosines


@njit(cache=True, inline="always")  # not a call per ray: cast_grid, in the localizer's hot loop, kept its speed
def _grid_hit(u0, v0, du, dv, occupied, max_t):
    """The distance in cells from (u0, v0) along the unit direction (du, dv) to the first occupied
    cell (inf: none within max_t), and the axis of the step that entered it: 0 along u, 1 along v,
    -1 when the ray starts in it (or enters the grid there)."""
    height, width = occupied.shape
    t0, t1 = 0.0, max_t
    if du != 0.0:  # clip the ray to the grid's box
        ta, tb = -u0 / du, (width - u0) / du
        t0, t1 = max(t0, min(ta, tb)), min(t1, max(ta, tb))
    elif not 0.0 <= u0 < width:
        return np.inf, -1
    if dv != 0.0:
        ta, tb = -v0 / dv, (height - v0) / dv
        t0, t1 = max(t0, min(ta, tb)), min(t1, max(ta, tb))
    elif not 0.0 <= v0 < height:
        return np.inf, -1
    if t0 > t1:
        return np.inf, -1
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
    t, axis = t0, -1
    while t <= t1:
        if occupied[row, col]:
            return t, axis
        if next_u < next_v:
            t, col, next_u, axis = next_u, col + step_c, next_u + delta_u, 0
            if col < 0 or col >= width:
                break
        else:
            t, row, next_v, axis = next_v, row + step_r, next_v + delta_v, 1
            if row < 0 or row >= height:
                break
    return np.inf, -1


@njit(cache=True)
def cast_grid(u0, v0, angles, occupied, max_t):
    """Distances in cells from (u0, v0) (grid coordinates) to the first occupied cell."""
    out = np.empty(angles.shape[0])
    for k in range(angles.shape[0]):
        out[k] = _grid_hit(u0, v0, math.cos(angles[k]), math.sin(angles[k]), occupied, max_t)[0]
    return out


@njit(cache=True)
def cast_grid_incidence(u0, v0, angles, occupied, max_t):
    """cast_grid's distances, and the incidence cosine of each hit on the face of the cell the ray
    enters: a map's cells are the surface, so a diagonal wall is the staircase the distances see too
    (1 where nothing is hit, or the ray starts in the cell)."""
    out = np.empty(angles.shape[0])
    cosines = np.ones(angles.shape[0])
    for k in range(angles.shape[0]):
        du, dv = math.cos(angles[k]), math.sin(angles[k])
        out[k], axis = _grid_hit(u0, v0, du, dv, occupied, max_t)
        if axis == 0:
            cosines[k] = abs(du)
        elif axis == 1:
            cosines[k] = abs(dv)
    return out, cosines
