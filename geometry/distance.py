"""The exact Euclidean distance transform of a grid, with the nearest cell: Felzenszwalb and
Huttenlocher's lower envelope of parabolas, by columns then rows, in numba."""
from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True)
def _lower_envelope(f, out, arg, v, z):
    """out[q] = min over p of f[p] + (q - p)² and arg[q] the p that gives it (f may be inf; all inf
    gives inf and -1): v and z scratch of len(f) and len(f) + 1. Exact for integer f: a boundary
    between two parabolas is a fraction of denominator below 2·len(f), too far from any other
    integer for rounding to move it past one."""
    n, k = f.shape[0], -1
    for q in range(n):
        if f[q] == np.inf:
            continue
        s = -np.inf
        while k >= 0:
            s = ((f[q] + q * q) - (f[v[k]] + v[k] * v[k])) / (2.0 * (q - v[k]))
            if s > z[k]:
                break
            k -= 1
        if k < 0:
            s = -np.inf
        k += 1
        v[k], z[k], z[k + 1] = q, s, np.inf
    if k < 0:
        out[:] = np.inf
        arg[:] = -1
        return
    j = 0
    for q in range(n):
        while z[j + 1] < q:
            j += 1
        out[q] = (q - v[j]) * (q - v[j]) + f[v[j]]
        arg[q] = v[j]


@njit(cache=True)
def nearest_cells(sources):
    """(squared, rows, cols), each (H, W): the squared distance in cells from each cell's centre to
    the nearest source cell's (0 on them, inf without any source) and that cell's row and column
    (-1 without any source)."""
    height, width = sources.shape
    squared = np.full((height, width), np.inf)
    rows = np.empty((height, width), np.int64)
    cols = np.empty((height, width), np.int64)
    size = max(height, width)
    f, out, arg = np.empty(size), np.empty(size), np.empty(size, np.int64)
    column_rows = np.empty(width, np.int64)
    v, z = np.empty(size, np.int64), np.empty(size + 1)
    for col in range(width):   # the nearest source in each column
        for row in range(height):
            f[row] = 0.0 if sources[row, col] else np.inf
        _lower_envelope(f[:height], out[:height], arg[:height], v, z)
        squared[:, col] = out[:height]
        rows[:, col] = arg[:height]
    for row in range(height):  # then along each row, over the columns' nearest
        f[:width] = squared[row]
        column_rows[:] = rows[row]
        _lower_envelope(f[:width], out[:width], arg[:width], v, z)
        for col in range(width):
            squared[row, col] = out[col]
            nearest = arg[col]
            cols[row, col] = nearest
            rows[row, col] = column_rows[nearest] if nearest >= 0 else -1
    return squared, rows, cols


def distances_to(sources: np.ndarray) -> np.ndarray:
    """(H, W) float64 distance in cells from each cell's centre to the nearest source cell's (0 on
    them, inf without any): scipy.ndimage.distance_transform_edt(~sources) to the bit (both take the
    square root of the same whole number), without importing scipy.ndimage, 0.2 CPU s in each
    process that would (the localizer, the tracker, the local planner)."""
    return np.sqrt(nearest_cells(np.ascontiguousarray(sources, np.bool_))[0])
