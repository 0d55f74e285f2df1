"""Odometry motion models of ROS amcl (amcl_odom.cpp), sampled for every particle in place.

The odometry step between two filter updates is taken as amcl takes it: the difference of the
two odometry poses in the odom frame, (Δx, Δy) and Δθ wrapped, with the robot's heading at the
older pose. From it each model draws, per particle:

- diff / diff-corrected (Probabilistic Robotics' sample_motion_model_odometry): a first turn
  rot1 = atan2(Δy, Δx) − θ_old (0 when the step is shorter than 1 cm), a translation, a second
  turn rot2 = Δθ − rot1. The turns' noise uses min(|rot|, |π − rot|), so driving backwards is
  not mistaken for a half turn. Standard deviations:
      σ_rot1 = f(α1 rot1² + α2 trans²), σ_trans = f(α3 trans² + α4 rot1² + α4 rot2²),
      σ_rot2 = f(α1 rot2² + α2 trans²)
- omni / omni-corrected: a translation along the bearing of the step (relative to each
  particle's heading), a rotation and a sideways "strafe" of zero mean:
      omni:            σ_trans = α3 t² + α1 r², σ_rot = α4 r² + α2 t², σ_strafe = α1 r² + α5 t²
      omni-corrected:  σ_trans = √(α3 t² + α4 r²), σ_rot = √(α1 r² + α2 t²), σ_strafe = √(α4 r² + α5 t²)

with f(v) = v for diff and f(v) = √v for diff-corrected. The uncorrected models use a variance-like
sum directly as a standard deviation; amcl kept them for compatibility and so do we (the
"-corrected" variants are the textbook ones).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit

from ...geometry.se2 import wrap_angle
from .params import ODOM_MODELS

_ROT1_MIN_STEP = 0.01  # m: below this the step's bearing is noise (amcl: turning in place)
TWO_PI = 2.0 * math.pi


@dataclass(frozen=True)
class MotionStep:
    """One odometry step decomposed as `model` samples it.

    diff models: (first, trans, second) = (rot1, trans, rot2), sd = (σ_rot1, σ_trans, σ_rot2).
    omni models: (first, trans, second) = (bearing, trans, rot), sd = (σ_trans, σ_rot, σ_strafe),
    where bearing is the step's direction relative to the old heading.
    """
    model: str
    first: float
    trans: float
    second: float
    sd: tuple[float, float, float]


def odom_delta(old_odom, new_odom) -> np.ndarray:
    """(Δx, Δy, Δθ) between two odometry poses, in the odom frame, as amcl computes it."""
    old_odom, new_odom = np.asarray(old_odom, float), np.asarray(new_odom, float)
    return np.array([new_odom[0] - old_odom[0], new_odom[1] - old_odom[1],
                     float(wrap_angle(new_odom[2] - old_odom[2]))])


def _flip_free(angle: float) -> float:
    """How far a turn is from driving straight, forwards or backwards."""
    return min(abs(float(wrap_angle(angle))), abs(float(wrap_angle(angle - math.pi))))


def decompose(model: str, old_odom, new_odom, alphas) -> MotionStep:
    """The model's means and standard deviations for the step from old_odom to new_odom."""
    if model not in ODOM_MODELS:
        raise ValueError(f"odom_model_type must be one of {ODOM_MODELS}, got {model!r}")
    a1, a2, a3, a4, a5 = (float(a) for a in alphas)
    dx, dy, dtheta = odom_delta(old_odom, new_odom)
    trans = math.hypot(dx, dy)
    bearing = float(wrap_angle(math.atan2(dy, dx) - float(np.asarray(old_odom, float)[2])))
    if model in ("diff", "diff-corrected"):
        rot1 = 0.0 if trans < _ROT1_MIN_STEP else bearing
        rot2 = float(wrap_angle(dtheta - rot1))
        n1, n2 = _flip_free(rot1), _flip_free(rot2)
        var = (a1 * n1 ** 2 + a2 * trans ** 2, a3 * trans ** 2 + a4 * n1 ** 2 + a4 * n2 ** 2,
               a1 * n2 ** 2 + a2 * trans ** 2)
        sd = tuple(math.sqrt(v) for v in var) if model == "diff-corrected" else var
        return MotionStep(model, rot1, trans, rot2, sd)
    t2, r2 = trans ** 2, dtheta ** 2
    if model == "omni":
        sd = (a3 * t2 + a1 * r2, a4 * r2 + a2 * t2, a1 * r2 + a5 * t2)
    else:
        sd = (math.sqrt(a3 * t2 + a4 * r2), math.sqrt(a1 * r2 + a2 * t2), math.sqrt(a4 * r2 + a5 * t2))
    return MotionStep(model, bearing, trans, dtheta, sd)


@njit(cache=True)
def _wrap(angle):
    return angle - TWO_PI * math.floor((angle + math.pi) / TWO_PI)


@njit(cache=True)
def _sample_diff(poses, n, rot1, trans, rot2, sd_rot1, sd_trans, sd_rot2, rng):
    for i in range(n):
        r1 = rot1 - sd_rot1 * rng.standard_normal()
        t = trans - sd_trans * rng.standard_normal()
        r2 = rot2 - sd_rot2 * rng.standard_normal()
        heading = poses[i, 2] + r1
        poses[i, 0] += t * math.cos(heading)
        poses[i, 1] += t * math.sin(heading)
        poses[i, 2] = _wrap(heading + r2)


@njit(cache=True)
def _sample_omni(poses, n, bearing, trans, rot, sd_trans, sd_rot, sd_strafe, rng):
    for i in range(n):
        direction = poses[i, 2] + bearing
        c, s = math.cos(direction), math.sin(direction)
        t = trans + sd_trans * rng.standard_normal()
        r = rot + sd_rot * rng.standard_normal()
        side = sd_strafe * rng.standard_normal()
        poses[i, 0] += t * c + side * s
        poses[i, 1] += t * s - side * c
        poses[i, 2] = _wrap(poses[i, 2] + r)


def sample_motion(poses: np.ndarray, n: int, step: MotionStep, rng: np.random.Generator) -> None:
    """Move the first n particles (rows x, y, θ of `poses`, float64, C order) by one sampled step."""
    if step.model in ("diff", "diff-corrected"):
        _sample_diff(poses, n, step.first, step.trans, step.second, *step.sd, rng)
    else:
        _sample_omni(poses, n, step.first, step.trans, step.second, *step.sd, rng)


def warm_up() -> None:
    """Compile (or load from cache) the sampling kernels."""
    rng = np.random.default_rng(0)
    poses = np.zeros((1, 3))
    _sample_diff(poses, 1, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, rng)
    _sample_omni(poses, 1, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, rng)
