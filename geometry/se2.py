"""SE(2) pose algebra, shared by every service: poses as arrays (..., 3) of (x, y, theta).

Theta is in [-pi, pi); every helper broadcasts over leading axes. A "motion" is a twist times its
duration, (vx*dt, vy*dt, wz*dt) in the robot frame at the start of the step; `se2_exp` turns it
into the pose increment of driving that constant twist for dt (a straight line, an arc, or a
sideways arc for a holonomic robot).
"""
from __future__ import annotations

import math

import numpy as np

_EPS = float(np.finfo(float).eps)       # np.sinc's stand-in for a zero argument


def wrap_angle(angle):
    """Angles into [-pi, pi)."""
    return np.remainder(np.asarray(angle, dtype=float) + np.pi, 2 * np.pi) - np.pi


def compose(a, b) -> np.ndarray:
    """a (+) b: the pose b, given in the frame of pose a, expressed in a's parent frame."""
    a = np.asarray(a, dtype=float)
    b = np.asarray(b, dtype=float)
    if a.shape == b.shape == (3,):
        return np.array(_compose_one(a.tolist(), b.tolist()))
    c, s = np.cos(a[..., 2]), np.sin(a[..., 2])
    return np.stack([a[..., 0] + c * b[..., 0] - s * b[..., 1],
                     a[..., 1] + s * b[..., 0] + c * b[..., 1],
                     wrap_angle(a[..., 2] + b[..., 2])], axis=-1)


def inverse(a) -> np.ndarray:
    """The pose whose composition with `a` is the identity: the parent frame seen from a."""
    a = np.asarray(a, dtype=float)
    if a.shape == (3,):
        x, y, theta = a.tolist()
        c, s = math.cos(theta), math.sin(theta)
        return np.array([-c * x - s * y, s * x - c * y, _wrap_one(-theta)])
    c, s = np.cos(a[..., 2]), np.sin(a[..., 2])
    return np.stack([-c * a[..., 0] - s * a[..., 1],
                     s * a[..., 0] - c * a[..., 1],
                     wrap_angle(-a[..., 2])], axis=-1)


def relative(a, b) -> np.ndarray:
    """The pose b seen from pose a (both in one frame): inverse(a) (+) b."""
    return compose(inverse(a), b)


# Single poses take these float paths: numpy's per-call overhead on 3-vectors was most of the cost
# of odometry and of the sim's step. They compute the same operations in the same order as the
# array expressions (math.sin/cos and % give numpy's values on this platform), so a pose comes out
# the same to the bit either way (tests/test_se2.py compares them).

def _wrap_one(angle: float) -> float:
    return (angle + math.pi) % (2 * math.pi) - math.pi


def _compose_one(a: list[float], b: list[float]) -> tuple[float, float, float]:
    c, s = math.cos(a[2]), math.sin(a[2])
    return a[0] + c * b[0] - s * b[1], a[1] + s * b[0] + c * b[1], _wrap_one(a[2] + b[2])


def _sinc_one(x: float) -> float:
    y = math.pi * x
    y = y if y else _EPS
    return math.sin(y) / y


def _exp_one(dx: float, dy: float, phi: float) -> tuple[float, float, float]:
    along = _sinc_one(phi / math.pi)
    across = math.sin(phi / 2) * _sinc_one(phi / (2 * math.pi))
    return along * dx - across * dy, across * dx + along * dy, phi


def se2_exp(motion) -> np.ndarray:
    """Pose increment of driving the constant twist `motion / dt` for dt, from (vx, vy, wz)*dt.

    x = dx sin(phi)/phi - dy (1 - cos phi)/phi, y = dx (1 - cos phi)/phi + dy sin(phi)/phi.
    Written with sinc and the half angle, (1 - cos phi)/phi = sin(phi/2) * sinc(phi/2), neither
    term cancels for small phi, so no separate series branch is needed near phi = 0.
    """
    motion = np.asarray(motion, dtype=float)
    if motion.shape == (3,):
        return np.array(_exp_one(*motion.tolist()))
    dx, dy, phi = motion[..., 0], motion[..., 1], motion[..., 2]
    along = np.sinc(phi / np.pi)
    across = np.sin(phi / 2) * np.sinc(phi / (2 * np.pi))
    return np.stack([along * dx - across * dy, across * dx + along * dy, phi], axis=-1)


def integrate(pose, twist, dt) -> np.ndarray:
    """The pose after driving a constant body twist (vx, vy, wz) for dt seconds, exactly."""
    twist = np.asarray(twist, dtype=float)
    return compose(pose, se2_exp(twist * np.asarray(dt, dtype=float)[..., None]))
