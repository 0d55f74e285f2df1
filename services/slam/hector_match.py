"""Hector mapping's scan matcher (Kohlbrecher, Meyer, von Stryk, Klingauf 2011, "A Flexible and
Scalable SLAM System with Full 3D Motion Estimation", section IV): the pose ξ = (x, y, ψ) that
puts a scan's end points on occupied cells, found by Gauss-Newton on the map's occupancy
probability M interpolated bilinearly between cell centres, coarse grid first.

For end points s_i (robot frame) placed at S_i(ξ), the matcher minimises Σ (1 − M(S_i(ξ)))²; one
step solves H Δξ = Σ (∇M(S_i) ∂S_i/∂ξ)ᵀ (1 − M(S_i)) with H = Σ (∇M ∂S_i/∂ξ)ᵀ (∇M ∂S_i/∂ξ), where
∂S_i/∂ξ = [[1, 0, −sin ψ s_x − cos ψ s_y], [0, 1, cos ψ s_x − sin ψ s_y]]. Points off the grid
count for nothing. With a prior pose ξ₀ (odometry's),
(ξ − ξ₀)ᵀ W (ξ − ξ₀) is added: negligible where the walls fix the pose, it holds it along a
corridor, where they do not. The levels are (probability, MapMetaData) pairs, finest first
(hector keeps one map per level, each half the resolution of the one before; `coarser` makes one
from another).

Pure: numpy and numba; grid rows are y, columns x (geometry/grid.py).
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

from ...schemas.messages import MapMetaData

SINGULAR = 1e-9        # a Hessian this close to singular (too few or collinear points) gives no step
CONVERGED = 1e-5       # m (and rad): a step this small ends a level's iterations


@njit(cache=True, inline="always")
def _bilinear(probability, u, v):
    """(M, ∂M/∂u, ∂M/∂v) at grid coordinates (u, v) in cells with the cell centres at whole
    numbers (the paper's eq. 4–6); zeros off the grid."""
    height, width = probability.shape
    col, row = math.floor(u), math.floor(v)
    if col < 0 or row < 0 or col >= width - 1 or row >= height - 1:
        return 0.0, 0.0, 0.0
    col, row = int(col), int(row)
    fu, fv = u - col, v - row
    p00, p01 = float(probability[row, col]), float(probability[row, col + 1])
    p10, p11 = float(probability[row + 1, col]), float(probability[row + 1, col + 1])
    value = (1 - fv) * ((1 - fu) * p00 + fu * p01) + fv * ((1 - fu) * p10 + fu * p11)
    return value, (1 - fv) * (p01 - p00) + fv * (p11 - p10), (1 - fu) * (p10 - p00) + fu * (p11 - p01)


@njit(cache=True, inline="always")
def _at(probability, origin, x, y):
    """(M, ∂M/∂x, ∂M/∂y) at the world point (x, y); origin = (x, y, cos, sin, 1 / resolution) of
    the grid."""
    dx, dy = x - origin[0], y - origin[1]
    c, s, scale = origin[2], origin[3], origin[4]
    value, du, dv = _bilinear(probability, (c * dx + s * dy) * scale - 0.5, (-s * dx + c * dy) * scale - 0.5)
    return value, (c * du - s * dv) * scale, (s * du + c * dv) * scale


@njit(cache=True, _nrt=False)
def _interpolate_all(probability, origin, x, y, out):
    for i in range(x.shape[0]):
        out[0, i], out[1, i], out[2, i] = _at(probability, origin, x[i], y[i])


@njit(cache=True, _nrt=False)
def _normal_equations(probability, origin, points, x, y, psi, hessian, gradient):
    """H and Σ (∇M ∂S/∂ξ)ᵀ (1 − M) of the scan's end points at pose (x, y, psi), into hessian (3, 3)
    and gradient (3,)."""
    c, s = math.cos(psi), math.sin(psi)
    hessian[:] = 0.0
    gradient[:] = 0.0
    for i in range(points.shape[0]):
        sx, sy = points[i, 0], points[i, 1]
        value, gx, gy = _at(probability, origin, x + c * sx - s * sy, y + s * sx + c * sy)
        row = (gx, gy, gx * (-s * sx - c * sy) + gy * (c * sx - s * sy))
        residual = 1.0 - value
        for a in range(3):
            gradient[a] += row[a] * residual
            for b in range(3):
                hessian[a, b] += row[a] * row[b]


@njit(cache=True, _nrt=False)
def _mismatch(probability, origin, points, x, y, psi):
    c, s = math.cos(psi), math.sin(psi)
    total = 0.0
    for i in range(points.shape[0]):
        sx, sy = points[i, 0], points[i, 1]
        value = _at(probability, origin, x + c * sx - s * sy, y + s * sx + c * sy)[0]
        total += (1.0 - value) ** 2
    return total / max(points.shape[0], 1)


def _origin(info: MapMetaData) -> np.ndarray:
    return np.array([info.origin.x, info.origin.y, math.cos(info.origin.theta), math.sin(info.origin.theta),
                     1.0 / info.resolution])


def interpolate(probability: np.ndarray, info: MapMetaData, x, y) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(M, ∂M/∂x, ∂M/∂y) at world points, bilinear between cell centres; 0 with no gradient off
    the grid."""
    x, y = np.broadcast_arrays(np.asarray(x, np.float64).ravel(), np.asarray(y, np.float64).ravel())
    out = np.empty((3, x.shape[0]))
    _interpolate_all(probability, _origin(info), np.ascontiguousarray(x), np.ascontiguousarray(y), out)
    return out[0], out[1], out[2]


def gauss_newton_step(probability: np.ndarray, info: MapMetaData, points: np.ndarray, pose,
                      prior=None, prior_weights=(0.0, 0.0, 0.0)) -> np.ndarray:
    """The pose after one Gauss-Newton step from `pose` for end points (N, 2) in the robot frame,
    held towards `prior` (x, y, yaw) by prior_weights (per m², m², rad²) when given."""
    pose = np.asarray(pose, np.float64)[:3]
    hessian, gradient = np.empty((3, 3)), np.empty(3)
    _normal_equations(probability, _origin(info), np.ascontiguousarray(points, np.float64),
                      float(pose[0]), float(pose[1]), float(pose[2]), hessian, gradient)
    if prior is not None:
        weights = np.asarray(prior_weights, np.float64)
        off = pose - np.asarray(prior, np.float64)[:3]
        off[2] = math.remainder(off[2], 2 * math.pi)
        hessian, gradient = hessian + np.diag(weights), gradient - weights * off
    if abs(np.linalg.det(hessian)) < SINGULAR:
        return pose.copy()
    return pose + np.linalg.solve(hessian, gradient)


def match(levels: list[tuple[np.ndarray, MapMetaData]], points: np.ndarray, pose, iterations: int = 10,
          prior=None, prior_weights=(0.0, 0.0, 0.0)) -> np.ndarray:
    """The pose matched coarse to fine (levels finest first), up to `iterations` steps a level,
    from `pose` (held towards `prior` when given, as gauss_newton_step)."""
    pose = np.asarray(pose, np.float64)[:3].copy()
    points = np.ascontiguousarray(np.asarray(points, np.float64).reshape(-1, 2))
    for probability, info in reversed(levels):
        for _ in range(iterations):
            moved = gauss_newton_step(probability, info, points, pose, prior, prior_weights)
            step, pose = np.abs(moved - pose), moved
            if step.max() < CONVERGED:
                break
    return pose


def mismatch(probability: np.ndarray, info: MapMetaData, points: np.ndarray, pose) -> float:
    """The matcher's cost per end point, the mean of (1 − M)² (0: every end point on a certainly
    occupied cell), at `pose`."""
    return _mismatch(probability, _origin(info), np.ascontiguousarray(np.asarray(points, np.float64).reshape(-1, 2)),
                     float(pose[0]), float(pose[1]), float(pose[2]))


def hessian(probability: np.ndarray, info: MapMetaData, points: np.ndarray, pose) -> np.ndarray:
    """Gauss-Newton's H = Σ (∇M ∂S_i/∂ξ)ᵀ (∇M ∂S_i/∂ξ) of end points (N, 2, robot frame) at `pose`:
    the information the scan holds about each direction of the pose (per m², m², rad²; units of
    the cost's)."""
    information, gradient = np.empty((3, 3)), np.empty(3)
    points = np.ascontiguousarray(np.asarray(points, np.float64).reshape(-1, 2))
    _normal_equations(probability, _origin(info), points, float(pose[0]), float(pose[1]), float(pose[2]),
                      information, gradient)
    return information


def pose_covariance(probability: np.ndarray, info: MapMetaData, points: np.ndarray, pose) -> np.ndarray:
    """Gauss-Newton's covariance of a matched pose: the cost per end point times H⁻¹ (zeros where H
    is singular)."""
    information = hessian(probability, info, points, pose)
    if abs(np.linalg.det(information)) < SINGULAR:
        return np.zeros((3, 3))
    return mismatch(probability, info, points, pose) * np.linalg.inv(information)


def coarser(probability: np.ndarray, info: MapMetaData) -> tuple[np.ndarray, MapMetaData]:
    """The grid at half the resolution: each cell the most occupied of the four it covers (an odd
    last row or column is dropped)."""
    height, width = (n // 2 * 2 for n in probability.shape)
    blocks = probability[:height, :width].reshape(height // 2, 2, width // 2, 2)
    return blocks.max(axis=(1, 3)), MapMetaData(resolution=info.resolution * 2, width=width // 2,
                                               height=height // 2, origin=info.origin)
