"""Movers on timed keyframes: where such a mover is, and how fast it moves, at any sim time.

A track is keyframes (t_i, p_i), t_0 = 0 < t_1 < … < t_{N-1}. Time τ maps to segment i (t_i ≤ τ <
t_{i+1}) and the segment parameter u = (τ − t_i)/(t_{i+1} − t_i), linear in time within each
segment whatever the segments' lengths. Then
  - `linear`: p = p_i + u (p_{i+1} − p_i), at constant velocity along each segment;
  - `gazebo`: Gazebo's PoseAnimation — the cubic Hermite segment p(u) = h00 p_i + h10 m_i +
    h01 p_{i+1} + h11 m_{i+1} (h00 = 2u³ − 3u² + 1, h10 = u³ − 2u² + u, h01 = −2u³ + 3u²,
    h11 = u³ − u²) with Catmull-Rom tangents in units of u: m_i = (p_{i+1} − p_{i−1})/2 inside; at
    the ends of an open track m_0 = (p_1 − p_0)/2 and m_{N−1} = (p_{N−1} − p_{N−2})/2; a closed
    track (p_0 = p_{N−1} within CLOSED_TOLERANCE) wraps: m_0 = m_{N−1} = (p_1 − p_{N−2})/2. Tangents
    are per unit of u, not of time, so the velocity dp/du / (t_{i+1} − t_i) jumps at a keyframe
    between segments of different durations, as it does in Gazebo.
A looping track's time is τ = t mod t_{N−1}: at the end it jumps back to p_0 (a track meant to
close repeats p_0 as its last keyframe). A track that does not loop holds p_{N−1}, at rest, from
t_{N−1} on.

Read, not copied (their maths rewritten here): gazebosim/gazebo-classic gazebo/common/Animation.cc
(Animation::SetTime — fmod for a loop, clamp otherwise; GetKeyFramesAtTime — the segment and u;
PoseAnimation — the position spline, tension 0 by default, gazebo/common/Animation.hh),
gazebo/physics/Entity.cc (UpdateAnimation: the keyframe's pose is the model's world pose each
step; a finished animation that does not loop stops where it ended), and gazebosim/gz-math
src/Spline.cc (RecalcTangents: the tangents above, scaled by 1 − tension; closed when the first and
last points are equal by Vector3's `==`, within 1e-3 per component, include/gz/math/Vector3.hh) with
src/SplinePrivate.cc (the Hermite basis matrix). Gazebo snaps u within 1e-6 of 0 to the keyframe
itself; that micrometre is not reproduced.
"""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from functools import cached_property

import numpy as np

INTERPOLATIONS = ("linear", "gazebo")
CLOSED_TOLERANCE = 1e-3      # m per coordinate: Gazebo's Vector3 equality, which makes a spline closed
TRACE_STEPS = 16             # points per segment that trace a gazebo track's curve (`trace`)


@dataclass(frozen=True, eq=False)
class Keyframes:
    """One mover's keyframes and how it moves between them (module notes)."""

    times: np.ndarray            # (N,) s, times[0] = 0, strictly increasing, N ≥ 2
    points: np.ndarray           # (N, 2) x, y
    loop: bool = True
    interpolation: str = "linear"

    @property
    def period(self) -> float:
        """The animation's length: the last keyframe's time."""
        return float(self.times[-1])

    @cached_property
    def tangents(self) -> np.ndarray:
        """Catmull-Rom tangents (N, 2) per unit of segment parameter (module notes)."""
        p = self.points
        m = np.empty_like(p)
        m[1:-1] = (p[2:] - p[:-2]) / 2
        if np.all(np.abs(p[0] - p[-1]) <= CLOSED_TOLERANCE):
            m[0] = m[-1] = (p[1] - p[-2]) / 2
        else:
            m[0], m[-1] = (p[1] - p[0]) / 2, (p[-1] - p[-2]) / 2
        return m

    @cached_property
    def _alone(self) -> Tracks:
        return Tracks((self,))

    def state(self, t) -> tuple[np.ndarray, np.ndarray]:
        """Positions (..., 2) and velocities (..., 2, m/s) at sim times t (any shape, s ≥ 0)."""
        position, velocity = self._alone.state(np.asarray(t, np.float64)[..., None])
        return position[..., 0, :], velocity[..., 0, :]

    def trace(self) -> np.ndarray:
        """The polyline (M, 2) the mover's centre follows over one period, keyframes included:
        the keyframes themselves for `linear`, TRACE_STEPS points a segment for `gazebo`."""
        steps = 1 if self.interpolation == "linear" else TRACE_STEPS
        within = self.times[:-1, None] + np.diff(self.times)[:, None] * (np.arange(steps) / steps)
        return np.vstack([self.state(within.ravel())[0], self.points[-1:]])


class Tracks:
    """Several tracks evaluated together, each at its own time, in one vectorised call (the
    simulator asks where every keyframe mover is at every step); shorter tracks are padded."""

    def __init__(self, tracks: Sequence[Keyframes]):
        count = max(len(track.times) for track in tracks)
        self.times = np.full((len(tracks), count), np.inf)     # never at or before any time
        self.points = np.zeros((len(tracks), count, 2))
        self.tangents = np.zeros((len(tracks), count, 2))
        for k, track in enumerate(tracks):
            n = len(track.times)
            self.times[k, :n], self.points[k, :n], self.tangents[k, :n] = track.times, track.points, track.tangents
        self.last_segment = np.array([len(track.times) - 2 for track in tracks])
        self.period = np.array([track.period for track in tracks])
        self.loop = np.array([track.loop for track in tracks], bool)
        self.linear = np.array([track.interpolation == "linear" for track in tracks], bool)

    def state(self, t) -> tuple[np.ndarray, np.ndarray]:
        """Positions (..., K, 2) and velocities (..., K, 2, m/s) of the K tracks at times t (..., K)."""
        t = np.asarray(t, np.float64)
        tau = np.where(self.loop, np.mod(t, self.period), np.clip(t, 0.0, self.period))
        k = np.arange(len(self.period))
        i = np.clip((self.times <= tau[..., None]).sum(axis=-1) - 1, 0, self.last_segment)
        start, duration = self.times[k, i], self.times[k, i + 1] - self.times[k, i]
        u = ((tau - start) / duration)[..., None]
        p0, p1, m0, m1 = self.points[k, i], self.points[k, i + 1], self.tangents[k, i], self.tangents[k, i + 1]
        u2, u3 = u * u, u * u * u
        hermite = (2 * u3 - 3 * u2 + 1) * p0 + (u3 - 2 * u2 + u) * m0 + (3 * u2 - 2 * u3) * p1 + (u3 - u2) * m1
        hermite_slope = (6 * u2 - 6 * u) * (p0 - p1) + (3 * u2 - 4 * u + 1) * m0 + (3 * u2 - 2 * u) * m1
        linear = self.linear[:, None]
        position = np.where(linear, p0 + u * (p1 - p0), hermite)
        velocity = np.where(linear, p1 - p0, hermite_slope) / duration[..., None]
        held = (~self.loop & (t >= self.period))[..., None]            # a track that does not loop, ended
        return position, np.where(held, 0.0, velocity)
