"""A maneuver for where DWA makes no progress: a search in (x, y, heading) for the padded footprint.

DWA rolls out arcs of one twist for sim_time; at the mouth of a gap its footprint fits only in a
few exact poses (BARN: a 0.53 m padded Jackal in 0.6 m gaps), which no single arc reaches, and the
robot creeps and turns there until a recovery moves it (docs/barn.md). The maneuver searches the
poses a robot reaches by the moves a differential drive can make on the spot — a step of one cell
straight ahead or back along its heading, a turn of TURN_STEP — every pose held to the footprint
check DWA uses, best first (hybrid A*: continuous poses, one kept per cell and heading bin; each
change between moving ahead, back, turning left and right costs SWITCH_COST_M more, because each is
a stop and a start when driven, and without it the way came out as a staircase of 5° turns and
one-cell drives), until a pose lies `progress` metres nearer the local goal than the start by the
distances DWA scores with (PathMaps.goal_dist: around the cells the centre may not enter) and faces
the way on (within FACING of the direction in which those distances fall): handed back to DWA
facing away from its way, the robot would drive back where it came from (BARN world 58's pocket).
For a wedged robot (its check the escape check, which forgives the cells its outline lay on) no
pose may bring the outline deeper over those cells than it lay (FootprintCheck.keeps_away): the
collision monitor, on the scan, stops a turn over them, and a maneuver that began by swinging the
robot's front over a door's jamb stood 9 s (building-diff-84).
The result is a list of segments — turn on the spot to a heading, or drive a distance straight
(negative: back) — that `ManeuverDriver` drives one after the other.

Pure: numpy and the footprint check's kernels; poses in the local costmap's frame.
"""
from __future__ import annotations

import heapq
import math
from dataclasses import dataclass

import numpy as np

from ...geometry.grid import world_to_cell
from ...geometry.se2 import wrap_angle
from ...parameters.declare import Parameters, param
from .footprint_check import FootprintCheck, PoseCheck

TURN_STEP = math.radians(5.0)        # rad: one turn move; 72 heading bins
HEADING_BINS = 72
BACK_COST = 2.0                      # a step back costs this many steps ahead: forward is the way on
TURN_COST_M = 0.1                    # m of travel a turn of one radian costs
TURN_TOLERANCE = math.radians(2.0)   # rad: a turn is done this near its heading
DRIVE_HEADING_SLACK = math.radians(4.0)   # rad: off its heading by more, a drive turns back on the spot first
PROFILE_ACCEL = 0.75                 # of the robot's accelerations: a profile the smoother and the floor follow
SETTLED_RATE = 0.05                  # rad/s and
SETTLED_SPEED = 0.02                 # m/s (seen between ticks): slower, the robot has settled after a profile
SETTLE_S = 0.5                       # s: at most this long waited for it
DRIVE_TOLERANCE = 0.005              # m: a drive is done this near its distance
HEADING_GAIN = 2.0                   # 1/s: turn rate per radian of heading error
SWITCH_COST_M = 0.1                  # m: each change between moves (ahead, back, turn left, turn right) costs this
FACING = math.pi / 4                 # rad: a maneuver ends facing the way on within this (the shim's threshold)


@dataclass(frozen=True)
class ManeuverParams(Parameters):
    """When a maneuver is searched (control.py) and how it is driven. stall_time lies below the
    navigator's oscillation_timeout (10 s), so the maneuver comes before its recoveries; progress:
    the padded footprint's length and more past the tight spot."""
    enabled: bool = True
    stall_time: float = param(4.0, gt=0)          # s over which DWA has moved the robot less than stall_radius
    stall_radius: float = param(0.25, gt=0)       # m
    mover_distance: float = param(3.0, ge=0)      # m: none with a tracked mover this near (it waits for people)
    progress: float = param(1.0, gt=0)            # m nearer the local goal than the start (DWA's goal distances)
    max_expansions: int = param(20000, ge=1)      # poses expanded before the search gives up
    speed: float = param(0.5, gt=0)               # m/s of a drive (at most the robot's max_vel_x)
    turn_speed: float = param(1.5, gt=0)          # rad/s of a turn (at most its max_vel_theta)


@dataclass(frozen=True)
class Segment:
    kind: str        # "turn" (to `value` rad, absolute heading) | "drive" (`value` m along the heading, negative back)
    value: float
    heading: float | None = None   # a drive's heading as planned (None: the one the robot has when it starts)


def _bin(pose, resolution: float) -> tuple[int, int, int]:
    return (int(math.floor(pose[0] / resolution)), int(math.floor(pose[1] / resolution)),
            int(round(wrap_angle(pose[2]) / TURN_STEP)) % HEADING_BINS)


def plan_maneuver(start, footprint_check: FootprintCheck, check: PoseCheck, costs: np.ndarray, info,
                  goal_dist: np.ndarray, params: ManeuverParams = ManeuverParams()) -> list[Segment] | None:
    """Segments that take the robot from `start` (x, y, yaw) to a legal pose params.progress metres
    nearer the local goal (goal_dist, metres per cell of the costmap), or None when the search finds
    none within params.max_expansions."""
    res = info.resolution
    height, width = costs.shape

    def cell(x, y) -> tuple[int, int]:
        row, col = world_to_cell(info, np.array([x]), np.array([y]))
        return int(row[0]), int(col[0])

    def goal_distance(x, y) -> float:
        r, c = cell(x, y)
        return float(goal_dist[r, c]) if 0 <= r < height and 0 <= c < width else math.inf

    def facing_on(x, y, th) -> bool:
        """Whether the heading lies within FACING of the direction in which goal_dist falls fastest
        (central differences on the grid's axes)."""
        r, c = cell(x, y)
        d_col = goal_dist[r, min(c + 1, width - 1)] - goal_dist[r, max(c - 1, 0)]
        d_row = goal_dist[min(r + 1, height - 1), c] - goal_dist[max(r - 1, 0), c]
        if d_col == 0.0 and d_row == 0.0:
            return True
        downhill = math.atan2(-d_row, -d_col) + info.origin.theta
        return abs(float(wrap_angle(th - downhill))) <= FACING

    start = tuple(float(v) for v in start)
    target = goal_distance(start[0], start[1]) - params.progress
    if not math.isfinite(target):
        return None
    came_from: dict[tuple, tuple] = {}
    kinds: dict[tuple, int] = {}   # the move that reached a pose: ahead, back, left or right
    best: dict[tuple, float] = {_bin(start, res): 0.0}
    poses = {_bin(start, res): start}
    queue = [(goal_distance(start[0], start[1]), 0.0, _bin(start, res))]
    expansions = 0
    while queue and expansions < params.max_expansions:
        _, g, key = heapq.heappop(queue)
        if g > best[key]:
            continue
        x, y, th = poses[key]
        if goal_distance(x, y) <= target and facing_on(x, y, th):
            return _segments(key, came_from, poses)
        expansions += 1
        c, s = math.cos(th), math.sin(th)
        moves = ((x + c * res, y + s * res, th, res), (x - c * res, y - s * res, th, BACK_COST * res),
                 (x, y, th + TURN_STEP, TURN_COST_M * TURN_STEP), (x, y, th - TURN_STEP, TURN_COST_M * TURN_STEP))
        candidates = np.array([m[:3] for m in moves])
        legal = footprint_check.check_poses(check, candidates, costs, info) & footprint_check.keeps_away(check, candidates)
        last = kinds.get(key)
        for kind, ((nx, ny, nth, cost), ok) in enumerate(zip(moves, legal)):
            if not ok:
                continue
            nkey = _bin((nx, ny, nth), res)
            ng = g + cost + (SWITCH_COST_M if last is not None and kind != last else 0.0)
            if ng < best.get(nkey, math.inf):
                best[nkey], poses[nkey], came_from[nkey], kinds[nkey] = ng, (nx, ny, nth), key, kind
                heapq.heappush(queue, (ng + goal_distance(nx, ny), ng, nkey))
    return None


def _segments(key, came_from, poses) -> list[Segment]:
    """The moves from the start to `key`, merged into turns to a heading and straight drives."""
    chain = [key]
    while chain[-1] in came_from:
        chain.append(came_from[chain[-1]])
    path = [poses[k] for k in reversed(chain)]
    segments: list[Segment] = []
    for (x0, y0, th0), (x1, y1, th1) in zip(path, path[1:]):
        if th1 != th0:   # consecutive turns are one turn to the last heading
            if segments and segments[-1].kind == "turn":
                segments.pop()
            segments.append(Segment("turn", float(wrap_angle(th1))))
        else:
            ahead = math.cos(th0) * (x1 - x0) + math.sin(th0) * (y1 - y0) > 0
            step = math.hypot(x1 - x0, y1 - y0) * (1.0 if ahead else -1.0)
            if segments and segments[-1].kind == "drive" and segments[-1].value * step > 0:
                segments[-1] = Segment("drive", segments[-1].value + step, segments[-1].heading)
            else:
                segments.append(Segment("drive", step, float(wrap_angle(th0))))
    return segments


class ManeuverDriver:
    """Drives the segments one after the other, each as a velocity profile at the robot's limits
    (speeding up and braking at PROFILE_ACCEL of its accelerations, at most `speed` / turn_speed and
    its own top speeds `top`: m/s, rad/s), commanded tick by tick without waiting for the pose to
    follow; once the robot has settled (SETTLED_RATE, SETTLED_SPEED, or SETTLE_S at most) what is
    left is measured, and a segment further off than TURN_TOLERANCE / DRIVE_TOLERANCE is driven
    again by a profile of the rest. A drive holds the heading planned (HEADING_GAIN), turning back
    on the spot first when it starts more than DRIVE_HEADING_SLACK off it. A robot answers a
    command late (the command chain, the smoother's ramp, the pose's age): steered by the pose it
    overshoots, and a turn ended the tick the pose came within tolerance swung on 9° while the
    next drive began, holding the heading it began with, into a cylinder its plan cleared (BARN
    world 112). `step` gives the twist for the robot at a pose, None once every segment is done or
    the time it may take is up (`finished` says which)."""

    def __init__(self, segments: list[Segment], pose, params: ManeuverParams, top: tuple[float, float],
                 accel: tuple[float, float]):
        self.segments = list(segments)
        self.speed, self.turn_speed = min(params.speed, top[0]), min(params.turn_speed, top[1])
        self.accel = (PROFILE_ACCEL * accel[0], PROFILE_ACCEL * accel[1])
        self.index = 0
        self.anchor = np.asarray(pose, np.float64)[:3].copy()
        self._profile: tuple[str, np.ndarray] | None = None   # ("drive" | "turn", the rates still to command)
        self._settling_s = 0.0
        self._last_pose: np.ndarray | None = None
        # twice the time the segments take at full speed, a settling per segment and a second more:
        # a robot the monitor holds back (or that cannot follow) gives the maneuver up
        full_speed = sum(abs(s.value) / (self.speed if s.kind == "drive" else self.turn_speed) for s in self.segments)
        self.time_left = 2.0 * full_speed + SETTLE_S * len(self.segments) + 1.0

    def step(self, pose, dt: float) -> np.ndarray | None:
        """The twist for the robot at `pose` for the next dt seconds; None once done or out of time."""
        self.time_left -= dt
        if self.time_left < 0.0:
            return None
        pose = np.asarray(pose, np.float64)[:3]
        moving = self._moving(pose, dt)
        while self.index < len(self.segments):
            segment = self.segments[self.index]
            heading = self.anchor[2] if segment.heading is None else segment.heading
            if self._profile is not None and len(self._profile[1]):
                kind, rates = self._profile
                rate, self._profile = rates[0], (kind, rates[1:])
                if kind == "turn":
                    return np.array([0.0, 0.0, rate])
                hold = float(np.clip(HEADING_GAIN * wrap_angle(heading - pose[2]), -self.turn_speed, self.turn_speed))
                return np.array([rate, 0.0, hold])
            if self._profile is not None and moving and self._settling_s < SETTLE_S:
                self._settling_s += dt
                return np.zeros(3)
            self._profile, self._settling_s = None, 0.0
            if segment.kind == "turn":
                error = float(wrap_angle(segment.value - pose[2]))
                if abs(error) <= TURN_TOLERANCE:
                    self._next(pose)
                    continue
                self._profile = ("turn", self._rates(error, self.turn_speed, self.accel[1], dt))
                continue
            off = float(wrap_angle(heading - pose[2]))
            if abs(off) > DRIVE_HEADING_SLACK:
                self._profile = ("turn", self._rates(off, self.turn_speed, self.accel[1], dt))
                continue
            covered = math.cos(heading) * (pose[0] - self.anchor[0]) + math.sin(heading) * (pose[1] - self.anchor[1])
            remaining = segment.value - covered
            if remaining * math.copysign(1.0, segment.value) <= DRIVE_TOLERANCE:
                self._next(pose)
                continue
            self._profile = ("drive", self._rates(remaining, self.speed, self.accel[0], dt))
        return None

    def _next(self, pose) -> None:
        self.index += 1
        self.anchor = np.asarray(pose, np.float64)[:3].copy()

    def _moving(self, pose: np.ndarray, dt: float) -> bool:
        """Whether the robot moved faster than settled between the last tick and this one."""
        last, self._last_pose = self._last_pose, pose.copy()
        if last is None:
            return False
        return (abs(float(wrap_angle(pose[2] - last[2]))) > SETTLED_RATE * dt
                or math.hypot(*(pose[:2] - last[:2])) > SETTLED_SPEED * dt)

    @staticmethod
    def _rates(distance: float, top: float, accel: float, dt: float) -> np.ndarray:
        """The rate for each tick of dt that covers `distance` (signed) speeding up and braking at
        `accel`, at most `top`: each the mean over its tick of the trapezoid (or triangle), so that
        the ticks cover the distance exactly."""
        size = abs(distance)
        peak = min(top, math.sqrt(size * accel))
        ramp = peak / accel
        total = 2.0 * ramp + (size - peak * ramp) / peak

        def covered(t):
            t = np.clip(t, 0.0, total)
            up = 0.5 * accel * np.minimum(t, ramp) ** 2
            cruise = peak * np.clip(t - ramp, 0.0, total - 2.0 * ramp)
            left = np.clip(total - t, 0.0, ramp)
            down = np.where(t > total - ramp, peak * ramp / 2.0 - 0.5 * accel * left ** 2, 0.0)
            return up + cruise + down

        ticks = np.arange(math.ceil(total / dt - 1e-9) + 1) * dt
        return math.copysign(1.0, distance) * np.diff(covered(ticks)) / dt

    @property
    def finished(self) -> bool:
        return self.index >= len(self.segments)
