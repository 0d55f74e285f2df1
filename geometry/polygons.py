"""Points, segments and polygons as numpy arrays (..., 2), broadcasting over leading axes: placing
points at poses, distances between points and segments, inside tests, densifying a polyline."""
from __future__ import annotations

import numpy as np


def transform_points(points: np.ndarray, poses: np.ndarray) -> np.ndarray:
    """Points (P, 2) in the frames of poses (Q, 3) → world points (Q, P, 2)."""
    poses = np.atleast_2d(np.asarray(poses, np.float64))
    c, s = np.cos(poses[:, 2])[:, None], np.sin(poses[:, 2])[:, None]
    px, py = points[None, :, 0], points[None, :, 1]
    return np.stack([poses[:, 0:1] + c * px - s * py, poses[:, 1:2] + s * px + c * py], axis=-1)


def point_segment_distance(p: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Distance from points p to segments ab; all (..., 2) arrays that broadcast."""
    ab, ap = b - a, p - a
    length2 = np.sum(ab * ab, axis=-1)
    t = np.clip(np.sum(ap * ab, axis=-1) / np.where(length2 > 0, length2, 1.0), 0.0, 1.0)
    closest = a + t[..., None] * ab
    return np.hypot(*np.moveaxis(p - closest, -1, 0))


def _cross(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    return u[..., 0] * v[..., 1] - u[..., 1] * v[..., 0]


def segment_distance(a: np.ndarray, b: np.ndarray, c: np.ndarray, d: np.ndarray) -> np.ndarray:
    """Distance between segments ab and cd (broadcast (..., 2) arrays); 0 where they cross."""
    d1, d2 = _cross(b - a, c - a), _cross(b - a, d - a)
    d3, d4 = _cross(d - c, a - c), _cross(d - c, b - c)
    crossing = (d1 * d2 <= 0) & (d3 * d4 <= 0) & ((d1 != 0) | (d2 != 0) | (d3 != 0) | (d4 != 0))
    ends = np.minimum(np.minimum(point_segment_distance(a, c, d), point_segment_distance(b, c, d)),
                      np.minimum(point_segment_distance(c, a, b), point_segment_distance(d, a, b)))
    return np.where(crossing, 0.0, ends)


def points_in_polygons(points: np.ndarray, polygons: np.ndarray) -> np.ndarray:
    """Whether points (..., P, 2) lie inside polygons (..., K, V, 2) (even-odd rule) → (..., P, K)."""
    p = points[..., :, None, None, :]                      # (..., P, 1, 1, 2)
    a = polygons[..., None, :, :, :]                        # (..., 1, K, V, 2)
    b = np.roll(polygons, -1, axis=-2)[..., None, :, :, :]
    straddles = (a[..., 1] > p[..., 1]) != (b[..., 1] > p[..., 1])
    with np.errstate(divide="ignore", invalid="ignore"):
        x_cross = a[..., 0] + (p[..., 1] - a[..., 1]) * (b[..., 0] - a[..., 0]) / (b[..., 1] - a[..., 1])
    return (np.count_nonzero(straddles & (p[..., 0] < x_cross), axis=-1) % 2) == 1


def polygon_area(polygon: np.ndarray) -> float:
    x, y = polygon[:, 0], polygon[:, 1]
    return 0.5 * float(np.dot(x, np.roll(y, -1)) - np.dot(np.roll(x, -1), y))


def arc_lengths(points: np.ndarray) -> np.ndarray:
    """(N,) distance along a polyline (N, 2 or more: its first two columns are x, y) to each vertex."""
    return np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(points[:, :2], axis=0).T))])


def densify(points: np.ndarray, spacing: float) -> np.ndarray:
    """(K, 2) points along the polyline, at most `spacing` apart, ends included."""
    xy = points[:, :2]
    if len(xy) < 2:
        return xy
    steps = np.maximum(1, np.ceil(np.hypot(*np.diff(xy, axis=0).T) / spacing).astype(np.int64))
    segment = np.repeat(np.arange(len(steps)), steps)
    fraction = (np.arange(segment.size) - np.repeat(np.cumsum(steps) - steps, steps)) / steps[segment]
    inner = xy[segment] + (xy[segment + 1] - xy[segment]) * fraction[:, None]
    return np.vstack([inner, xy[-1:]])
