"""Hector mapping's scan matcher (Kohlbrecher, Meyer, von Stryk, Klingauf 2011, "A Flexible and
Scalable SLAM System with Full 3D Motion Estimation", section IV): the pose ξ = (x, y, ψ) that
puts a scan's end points on occupied cells, found by Gauss-Newton on the map's occupancy
probability M interpolated bilinearly between cell centres, coarse grid first.

For end points s_i (robot frame) placed at S_i(ξ), the matcher minimises Σ (1 − M(S_i(ξ)))²; one
step solves H Δξ = Σ (∇M(S_i) ∂S_i/∂ξ)ᵀ (1 − M(S_i)) with H = Σ (∇M ∂S_i/∂ξ)ᵀ (∇M ∂S_i/∂ξ), where
∂S_i/∂ξ = [[1, 0, −sin ψ s_x − cos ψ s_y], [0, 1, cos ψ s_x − sin ψ s_y]]. Points off the grid
count for nothing. With a prior pose ξ₀ (odometry's), (ξ − ξ₀)ᵀ W (ξ − ξ₀) is added: negligible
where the walls fix the pose, it holds it along a corridor, where they do not. The levels are (probability, MapMetaData) pairs, finest first (hector keeps one
map per level, each half the resolution of the one before; `coarser` makes one from another).

Pure: numpy only; grid rows are y, columns x (geometry/grid.py).
"""
from __future__ import annotations

import math

import numpy as np

from ...geometry.grid import grid_coords
from ...schemas.messages import MapMetaData

SINGULAR = 1e-9    # a Hessian this close to singular (too few or collinear points) gives no step


def interpolate(probability: np.ndarray, info: MapMetaData, x, y) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(M, ∂M/∂x, ∂M/∂y) at world points, bilinear between cell centres (the paper's eq. 4–6);
    0 with no gradient off the grid."""
    u, v = grid_coords(info, x, y)
    u, v = u - 0.5, v - 0.5                    # cell centres at whole numbers
    col, row = np.floor(u).astype(np.int64), np.floor(v).astype(np.int64)
    height, width = probability.shape
    inside = (col >= 0) & (row >= 0) & (col < width - 1) & (row < height - 1)
    col, row = np.where(inside, col, 0), np.where(inside, row, 0)
    fu, fv = u - col, v - row
    p00, p01 = probability[row, col], probability[row, col + 1]
    p10, p11 = probability[row + 1, col], probability[row + 1, col + 1]
    value = (1 - fv) * ((1 - fu) * p00 + fu * p01) + fv * ((1 - fu) * p10 + fu * p11)
    du = ((1 - fv) * (p01 - p00) + fv * (p11 - p10)) / info.resolution
    dv = ((1 - fu) * (p10 - p00) + fu * (p11 - p01)) / info.resolution
    c, s = math.cos(info.origin.theta), math.sin(info.origin.theta)
    zero = np.zeros_like(value)
    return (np.where(inside, value, zero), np.where(inside, c * du - s * dv, zero),
            np.where(inside, s * du + c * dv, zero))


def gauss_newton_step(probability: np.ndarray, info: MapMetaData, points: np.ndarray, pose,
                      prior=None, prior_weights=(0.0, 0.0, 0.0)) -> np.ndarray:
    """The pose after one Gauss-Newton step from `pose` for end points (N, 2) in the robot frame,
    held towards `prior` (x, y, yaw) by prior_weights (per m², m², rad²) when given."""
    x, y, psi = (float(v) for v in pose)
    c, s = math.cos(psi), math.sin(psi)
    sx, sy = points[:, 0], points[:, 1]
    value, gx, gy = interpolate(probability, info, x + c * sx - s * sy, y + s * sx + c * sy)
    rows = np.column_stack([gx, gy, gx * (-s * sx - c * sy) + gy * (c * sx - s * sy)])   # ∇M ∂S/∂ξ
    hessian, gradient = rows.T @ rows, rows.T @ (1.0 - value)
    if prior is not None:
        weights = np.asarray(prior_weights, np.float64)
        off = np.array([x - prior[0], y - prior[1], math.remainder(psi - prior[2], 2 * math.pi)])
        hessian, gradient = hessian + np.diag(weights), gradient - weights * off
    if abs(np.linalg.det(hessian)) < SINGULAR:
        return np.array([x, y, psi])
    return np.array([x, y, psi]) + np.linalg.solve(hessian, gradient)


def match(levels: list[tuple[np.ndarray, MapMetaData]], points: np.ndarray, pose, iterations: int = 10,
          prior=None, prior_weights=(0.0, 0.0, 0.0)) -> np.ndarray:
    """The pose matched coarse to fine (levels finest first), `iterations` steps a level, from
    `pose` (held towards `prior` when given, as gauss_newton_step)."""
    pose = np.asarray(pose, np.float64)[:3].copy()
    points = np.asarray(points, np.float64).reshape(-1, 2)
    for probability, info in reversed(levels):
        for _ in range(iterations):
            pose = gauss_newton_step(probability, info, points, pose, prior, prior_weights)
    return pose


def coarser(probability: np.ndarray, info: MapMetaData) -> tuple[np.ndarray, MapMetaData]:
    """The grid at half the resolution: each cell the most occupied of the four it covers (an odd
    last row or column is dropped)."""
    height, width = (n // 2 * 2 for n in probability.shape)
    blocks = probability[:height, :width].reshape(height // 2, 2, width // 2, 2)
    return blocks.max(axis=(1, 3)), MapMetaData(resolution=info.resolution * 2, width=width // 2,
                                               height=height // 2, origin=info.origin)
