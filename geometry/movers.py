"""The tracker's moving obstacles as the planners, the costmap and the collision monitor use them:
each track a circle moving at constant velocity, predicted to an instant and carried into a frame.

The standard deviation of a predicted position grows as the constant-velocity filter's covariance
does: var(τ) = var_p + 2τ·cov_pv + τ²·var_v (per axis, averaged over x and y).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..schemas.messages import Tracks
from .se2 import compose


TRACKED_POINT_MARGIN = 0.15   # m beyond a track's radius within which a scan point is that track's


@dataclass(frozen=True)
class Movers:
    """Tracks at one instant in one frame."""
    positions: np.ndarray    # (N, 2)
    velocities: np.ndarray   # (N, 2)
    radii: np.ndarray        # (N,)
    variance: np.ndarray     # (N, 3): position variance, position-velocity covariance, velocity variance

    def __len__(self) -> int:
        return len(self.radii)

    def along(self, times, sigmas: float) -> np.ndarray:
        """(K, N, 3): each mover's predicted centre at each of the times (s after these tracks'
        instant) and its radius grown by `sigmas` standard deviations of that prediction."""
        t = np.asarray(times, np.float64)[:, None]
        centres = self.positions[None] + self.velocities[None] * t[..., None]
        variance = self.variance[:, 0] + 2.0 * t * self.variance[:, 1] + t * t * self.variance[:, 2]
        radii = self.radii + sigmas * np.sqrt(np.maximum(variance, 0.0))
        return np.concatenate([centres, radii[..., None]], axis=2)

    def moving_at_least(self, speed: float) -> Movers:
        """The movers moving at speed (m/s) or faster."""
        keep = np.hypot(self.velocities[:, 0], self.velocities[:, 1]) >= speed
        return Movers(self.positions[keep], self.velocities[keep], self.radii[keep], self.variance[keep])

    def on_movers(self, points: np.ndarray, margin: float, after_s: float = 0.0) -> np.ndarray:
        """(K,) whether each point (K, 2) lies within a mover's radius plus margin of where the
        mover is after_s seconds after these tracks' instant: a scan point that is a mover's."""
        points = np.asarray(points, np.float64).reshape(-1, 2)
        if not len(self) or not len(points):
            return np.zeros(len(points), bool)
        centres = self.positions + self.velocities * after_s
        gap = np.hypot(points[:, None, 0] - centres[None, :, 0], points[:, None, 1] - centres[None, :, 1])
        return np.any(gap <= self.radii[None] + margin, axis=1)

    def nearest_edge(self, xy) -> float:
        """Distance from the point xy to the nearest mover's edge (inf when there is none)."""
        if not len(self):
            return math.inf
        return float(np.min(np.hypot(*(self.positions - np.asarray(xy, np.float64)[:2]).T) - self.radii))


def tracks_problem(msg: Tracks) -> str:
    """Why a Tracks message cannot be used (its arrays disagree in length), or ''."""
    n = len(msg.ids)
    shapes = {"states": msg.states.shape[0], "covariances": msg.covariances.shape[0], "radii": msg.radii.shape[0]}
    wrong = [f"{name} has {count}" for name, count in shapes.items() if count != n]
    if wrong:
        return f"{n} ids but " + ", ".join(wrong)
    if (msg.radii < 0).any():
        return "a negative radius"
    return ""


def movers_at(msg: Tracks, now_s: float, frame_pose, min_speed: float) -> Movers:
    """The tracks of msg as they will be at now_s (constant velocity), carried into a frame in which
    the tracks' frame has the pose frame_pose; tracks slower than min_speed are left out."""
    states = np.asarray(msg.states, np.float64).reshape(-1, 4)
    cov = np.asarray(msg.covariances, np.float64).reshape(-1, 4, 4)
    keep = np.hypot(states[:, 2], states[:, 3]) >= min_speed
    states, cov = states[keep], cov[keep]
    age = max(0.0, now_s - msg.header.stamp_ns * 1e-9)
    p = (cov[:, 0, 0] + cov[:, 1, 1]) / 2
    pv = (cov[:, 0, 2] + cov[:, 1, 3]) / 2
    v = (cov[:, 2, 2] + cov[:, 3, 3]) / 2
    variance = np.column_stack([p + 2 * age * pv + age * age * v, pv + age * v, v])
    positions = states[:, :2] + states[:, 2:] * age
    x, y, theta = (float(t) for t in frame_pose)
    placed = compose((x, y, theta), np.column_stack([positions, np.zeros(len(positions))]))[:, :2]
    c, s = math.cos(theta), math.sin(theta)
    velocities = states[:, 2:] @ np.array([[c, s], [-s, c]])
    return Movers(placed.reshape(-1, 2), velocities.reshape(-1, 2), np.asarray(msg.radii, np.float64)[keep], variance)
