"""The robot footprint as costmap_2d derives it: a polygon (or a circle), padded, and its radii.

As ROS 1 (costmap_2d/footprint.cpp): a robot_radius becomes a 16-point polygon on that circle;
padding moves every vertex outwards by `padding` along x and along y (sign of each coordinate);
the inscribed radius is the smallest and the circumscribed radius the largest distance from the
robot's origin to a vertex or an edge. For a circle the inscribed radius is therefore the
16-gon's, r·cos(π/16) for padding 0.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..schemas.messages import MapMetaData
from .grid import grid_coords

CIRCLE_POINTS = 16
# the mecanum paper's robot, 0.832 × 0.636 m: every robot's footprint unless its world or profile says otherwise
# m around the footprint where the collision monitor stops the robot (its stop_padding default); the local
# planner keeps its trajectories out of that zone
STOP_PADDING = 0.05
DEFAULT_FOOTPRINT = np.array([[0.416, 0.318], [-0.416, 0.318], [-0.416, -0.318], [0.416, -0.318]])


@dataclass(frozen=True)
class Footprint:
    points: np.ndarray              # (P, 2) padded polygon in the robot frame, m
    inscribed_radius: float         # m
    circumscribed_radius: float     # m
    body: np.ndarray                # (P, 2) the polygon without the padding: the robot itself, m


def _sign0(value: float) -> float:
    return -1.0 if value < 0 else (1.0 if value > 0 else 0.0)


def circle_polygon(radius: float) -> np.ndarray:
    angles = np.arange(CIRCLE_POINTS) * 2.0 * math.pi / CIRCLE_POINTS
    return np.stack([np.cos(angles) * radius, np.sin(angles) * radius], axis=1)


def pad(points: np.ndarray, padding: float) -> np.ndarray:
    return np.array([[x + _sign0(x) * padding, y + _sign0(y) * padding] for x, y in points], np.float64).reshape(-1, 2)


def _distance_to_segment(ax: float, ay: float, bx: float, by: float) -> float:
    """Distance from the origin to segment a-b."""
    dx, dy = bx - ax, by - ay
    length2 = dx * dx + dy * dy
    t = 0.0 if length2 == 0 else min(1.0, max(0.0, -(ax * dx + ay * dy) / length2))
    return math.hypot(ax + t * dx, ay + t * dy)


def radii(points: np.ndarray) -> tuple[float, float]:
    """(inscribed, circumscribed) radius of a polygon around the origin."""
    if len(points) <= 2:
        return 0.0, 0.0
    inscribed, circumscribed = math.inf, 0.0
    for i in range(len(points)):
        (ax, ay), (bx, by) = points[i], points[(i + 1) % len(points)]
        vertex, edge = math.hypot(ax, ay), _distance_to_segment(ax, ay, bx, by)
        inscribed = min(inscribed, vertex, edge)
        circumscribed = max(circumscribed, vertex, edge)
    return inscribed, circumscribed


def make_footprint(polygon=(), robot_radius: float = 0.46, padding: float = 0.01) -> Footprint:
    """The padded footprint: `polygon` if given (≥ 3 points), else a circle of robot_radius."""
    raw = np.asarray(polygon, np.float64).reshape(-1, 2) if len(polygon) else circle_polygon(robot_radius)
    points = pad(raw, padding)
    inscribed, circumscribed = radii(points)
    return Footprint(points=points, inscribed_radius=inscribed, circumscribed_radius=circumscribed, body=raw)


def transform(points: np.ndarray, pose) -> np.ndarray:
    """Footprint points placed at pose (x, y, yaw)."""
    x, y, yaw = (float(v) for v in pose)
    c, s = math.cos(yaw), math.sin(yaw)
    return np.stack([x + c * points[:, 0] - s * points[:, 1], y + s * points[:, 0] + c * points[:, 1]], axis=1)


def cells_inside(info: MapMetaData, polygon_world: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(rows, cols) of the grid cells whose centres lie inside a world-frame polygon."""
    u, v = grid_coords(info, polygon_world[:, 0], polygon_world[:, 1])
    c0, c1 = max(int(math.floor(u.min())), 0), min(int(math.ceil(u.max())), info.width)
    r0, r1 = max(int(math.floor(v.min())), 0), min(int(math.ceil(v.max())), info.height)
    if c0 >= c1 or r0 >= r1:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    rows, cols = np.mgrid[r0:r1, c0:c1]
    pu, pv = cols.ravel() + 0.5, rows.ravel() + 0.5
    inside = np.zeros(pu.shape, bool)
    for i in range(len(u)):   # even-odd rule, one edge at a time
        ua, va, ub, vb = u[i], v[i], u[(i + 1) % len(u)], v[(i + 1) % len(u)]
        crosses = (va > pv) != (vb > pv)
        with np.errstate(divide="ignore", invalid="ignore"):
            at = ua + (pv - va) * (ub - ua) / (vb - va)
        inside ^= crosses & (pu < at)
    return rows.ravel()[inside], cols.ravel()[inside]
