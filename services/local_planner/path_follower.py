"""The omni-wheel paper's path follower: straight and arc segments, a speed along the path, PID
corrections for cross-track and heading error, and distance-based deceleration for the final
approach, V = ((l − s)/l)^a · V0: over the last l metres (decel_distance), s metres into them,
with a = decel_exponent. With a < 1 the speed falls to zero exactly at the end in finite time
(2l/V0 for a = ½); the command is also capped at what reaches the end within one step, so a
discrete controller lands on it instead of overshooting.

Holonomic mode drives the path's tangent at V, corrects the cross-track error sideways (PID, m/s
per m) and the heading towards the tangent (curvature feed-forward κ·V plus PID). Differential
mode drives forward at V and corrects both errors by turning: ω = κ·V + PID(heading) +
PID(cross-track)·V/V0 (the cross-track term fades with the speed so the robot does not turn on the
spot at the end). Cross-track error is positive to the left of the path.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ...geometry.se2 import wrap_angle
from .params import FollowerParams


@dataclass(frozen=True)
class Projection:
    s: float            # m along the segment
    lateral: float      # m, positive left of the direction of travel
    heading: float      # rad, the tangent's direction
    curvature: float    # 1/m, positive turning left


@dataclass(frozen=True)
class Line:
    start: tuple[float, float]
    end: tuple[float, float]

    @property
    def length(self) -> float:
        return math.dist(self.start, self.end)

    def project(self, x: float, y: float) -> Projection:
        (x0, y0), (x1, y1) = self.start, self.end
        tx, ty = (x1 - x0) / self.length, (y1 - y0) / self.length
        along = (x - x0) * tx + (y - y0) * ty
        return Projection(min(max(along, 0.0), self.length), (y - y0) * tx - (x - x0) * ty,
                          math.atan2(ty, tx), 0.0)

    def point(self, s: float) -> tuple[float, float]:
        (x0, y0), (x1, y1) = self.start, self.end
        f = s / self.length
        return x0 + f * (x1 - x0), y0 + f * (y1 - y0)


@dataclass(frozen=True)
class Arc:
    center: tuple[float, float]
    radius: float
    start_angle: float   # rad, of the start point seen from the centre
    sweep: float         # rad, positive counter-clockwise (a left turn)

    @property
    def length(self) -> float:
        return self.radius * abs(self.sweep)

    def project(self, x: float, y: float) -> Projection:
        turn = math.copysign(1.0, self.sweep)
        angle = math.atan2(y - self.center[1], x - self.center[0])
        # angle travelled from the start, with the gap beyond the ends split between them
        half = abs(self.sweep) / 2
        travelled = float(np.remainder(turn * (angle - self.start_angle) + math.pi - half, 2 * math.pi)) - math.pi + half
        travelled = min(max(travelled, 0.0), abs(self.sweep))
        distance = math.hypot(x - self.center[0], y - self.center[1])
        lateral = turn * (self.radius - distance)   # inside a left turn is left of the path
        tangent = self.start_angle + turn * (travelled + math.pi / 2)
        return Projection(self.radius * travelled, lateral, float(wrap_angle(tangent)), turn / self.radius)

    def point(self, s: float) -> tuple[float, float]:
        angle = self.start_angle + math.copysign(s / self.radius, self.sweep)
        return self.center[0] + self.radius * math.cos(angle), self.center[1] + self.radius * math.sin(angle)


Segment = Line | Arc


def segments_from_poses(poses) -> list[Line]:
    """A polyline path (N, 3) — e.g. the global planner's — as straight segments."""
    xy = np.asarray(poses, float).reshape(-1, 3)[:, :2]
    return [Line(tuple(a), tuple(b)) for a, b in zip(xy[:-1], xy[1:]) if np.hypot(*(b - a)) > 1e-9]


class Pid:
    def __init__(self, kp: float, ki: float, kd: float, integral_limit: float):
        self.kp, self.ki, self.kd, self.limit = kp, ki, kd, integral_limit
        self.integral, self.previous = 0.0, None

    def step(self, error: float, dt: float) -> float:
        self.integral = min(max(self.integral + error * dt, -self.limit), self.limit)
        rate = 0.0 if self.previous is None or dt <= 0 else (error - self.previous) / dt
        self.previous = error
        return self.kp * error + self.ki * self.integral + self.kd * rate


@dataclass(frozen=True)
class FollowerCommand:
    twist: np.ndarray     # (3,) vx, vy, wz in the robot frame
    speed: float          # m/s along the path
    s: float              # m travelled along the whole path
    remaining: float      # m to the end
    cross_track: float    # m, positive left of the path
    heading_error: float  # rad, tangent minus robot yaw
    done: bool


class PathFollower:
    """Follows one path (a list of Line / Arc segments, in order); `step` once per control period.
    `speed` is the robot's speed along the path when it starts (it may already be moving)."""

    def __init__(self, params: FollowerParams, segments: list[Segment], speed: float = 0.0):
        if not segments:
            raise ValueError("a path needs at least one segment")
        self.params = params
        self.segments = list(segments)
        self._starts = np.concatenate([[0.0], np.cumsum([seg.length for seg in self.segments])])
        self._index = 0                  # the segment the robot is on; only moves forward
        self._speed = max(speed, 0.0)    # the last commanded speed along the path
        self._cross = Pid(params.kp_cross, params.ki_cross, params.kd_cross, params.integral_limit)
        self._heading = Pid(params.kp_heading, params.ki_heading, params.kd_heading, params.integral_limit)

    @property
    def length(self) -> float:
        return float(self._starts[-1])

    def _project(self, x: float, y: float) -> tuple[int, Projection]:
        """The nearest projection on the current segment or the next one (never going back)."""
        best = None
        for i in range(self._index, min(self._index + 2, len(self.segments))):
            seg = self.segments[i]
            proj = seg.project(x, y)
            px, py = seg.point(proj.s)
            gap = math.hypot(x - px, y - py)
            if best is None or gap < best[0] - 1e-12:
                best = (gap, i, proj)
        return best[1], best[2]

    def profile(self, remaining: float) -> float:
        """The speed the path allows `remaining` metres from its end: V0, then ((l − s)/l)^a · V0."""
        p = self.params
        if remaining >= p.decel_distance:
            return p.cruise_speed
        return (max(remaining, 0.0) / p.decel_distance) ** p.decel_exponent * p.cruise_speed

    def step(self, pose, dt: float) -> FollowerCommand:
        """The command for the robot at pose (x, y, yaw), the control period being dt seconds."""
        p = self.params
        x, y, yaw = (float(v) for v in pose)
        self._index, proj = self._project(x, y)
        s = float(self._starts[self._index]) + proj.s
        remaining = self.length - s
        heading_error = float(wrap_angle(proj.heading - yaw))
        if remaining <= p.goal_tolerance:
            self._speed = 0.0
            return FollowerCommand(np.zeros(3), 0.0, s, remaining, proj.lateral, heading_error, True)
        speed = min(self.profile(remaining), self._speed + p.acc_lim * dt, remaining / dt)
        self._speed = speed
        correction = self._cross.step(-proj.lateral, dt)
        turn = self._heading.step(heading_error, dt)
        if p.drive == "holonomic":
            # along the tangent plus the sideways correction (path frame), turned into the robot frame
            rel = proj.heading - yaw
            vx = speed * math.cos(rel) - correction * math.sin(rel)
            vy = speed * math.sin(rel) + correction * math.cos(rel)
            wz = proj.curvature * speed + turn
        else:
            vx, vy = speed, 0.0
            wz = proj.curvature * speed + turn + correction * speed / p.cruise_speed
        wz = min(max(wz, -p.max_vel_theta), p.max_vel_theta)
        return FollowerCommand(np.array([vx, vy, wz]), speed, s, remaining, proj.lateral, heading_error, False)
