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
TURN_TOLERANCE = math.radians(2.0)   # rad: a turn is done this near its heading, and turning no faster than
SETTLED_RATE = 0.1                   # rad/s (seen between ticks): a robot still swinging overshoots it
DRIVE_HEADING_SLACK = math.radians(4.0)   # rad: off its heading by more, a drive turns back on the spot first
ANSWER_LAG_S = 0.2                   # s: a turn command takes effect this late (the command chain, the pose's age)
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
    """Drives the segments one after the other: a turn on the spot towards its heading, at most
    turn_speed, done once within TURN_TOLERANCE and no longer swinging (SETTLED_RATE between ticks);
    a drive straight at most `speed`, its heading held to the one planned, turning back on the spot
    first when more than DRIVE_HEADING_SLACK off it, until the distance along that heading is
    covered — neither faster than the robot's own top speeds (`top`: m/s, rad/s). A robot answers a
    command late: a turn ended the tick it came within tolerance swung on by 9° while the next drive
    began, and that drive, holding the heading it started with, carried the Jackal's corner into a
    cylinder its plan cleared (BARN world 112). Each segment ends at the speed from which the robot
    stops in what is left of it at half its acceleration limits (`accel`: m/s², rad/s²; half,
    because a command takes effect a tick late), and never faster than covers the rest in one tick:
    a segment ends in about the time its distance takes, not in an exponential approach. `step`
    gives the twist for the robot at a pose, None once every segment is done or the time it may take
    is up (`finished` says which)."""

    def __init__(self, segments: list[Segment], pose, params: ManeuverParams, top: tuple[float, float],
                 accel: tuple[float, float]):
        self.segments = list(segments)
        self.speed, self.turn_speed = min(params.speed, top[0]), min(params.turn_speed, top[1])
        self.accel = accel
        self._twist = np.zeros(3)              # the twist last commanded
        self.index = 0
        self.anchor = np.asarray(pose, np.float64)[:3].copy()
        self._last_heading: float | None = None
        # twice the time the segments take at full speed, and a second more: a robot the monitor holds
        # back (or that cannot follow) gives the maneuver up
        full_speed = sum(abs(s.value) / (self.speed if s.kind == "drive" else self.turn_speed) for s in self.segments)
        self.time_left = 2.0 * full_speed + 1.0

    def _next(self, pose) -> None:
        self.index += 1
        self.anchor = np.asarray(pose, np.float64)[:3].copy()

    def step(self, pose, dt: float) -> np.ndarray | None:
        """The twist for the robot at `pose` for the next dt seconds; None once done or out of time."""
        self.time_left -= dt
        if self.time_left < 0.0:
            return None
        swing = 0.0 if self._last_heading is None else float(wrap_angle(pose[2] - self._last_heading)) / dt
        self._last_heading = float(pose[2])
        while self.index < len(self.segments):
            segment = self.segments[self.index]
            if segment.kind == "turn":
                error = float(wrap_angle(segment.value - pose[2]))
                if abs(error) <= TURN_TOLERANCE and abs(swing) <= SETTLED_RATE:
                    self._next(pose)
                    continue
                return self._turn(error, dt)
            heading = self.anchor[2] if segment.heading is None else segment.heading
            covered = math.cos(heading) * (pose[0] - self.anchor[0]) + math.sin(heading) * (pose[1] - self.anchor[1])
            remaining = segment.value - covered
            if remaining * math.copysign(1.0, segment.value) <= DRIVE_TOLERANCE:
                self._next(pose)
                continue
            off = float(wrap_angle(heading - pose[2]))
            if abs(off) > DRIVE_HEADING_SLACK:
                return self._turn(off, dt)
            speed = self._ramp(0, remaining, self.speed, dt)
            hold = float(np.clip(HEADING_GAIN * off, -self.turn_speed, self.turn_speed))
            return self._command(speed, hold)
        return None

    def _turn(self, error: float, dt: float) -> np.ndarray:
        return self._command(0.0, self._ramp(2, error, self.turn_speed, dt))

    def _command(self, speed: float, rate: float) -> np.ndarray:
        self._twist = np.array([speed, 0.0, rate])
        return self._twist.copy()

    def _ramp(self, axis: int, remaining: float, top: float, dt: float) -> float:
        """The rate along `axis` (0 ahead, 2 turning) towards a target `remaining` away: braking for
        where the rate last commanded carries the robot before a command takes effect, and changed
        no faster than the robot's acceleration (a command the smoother must ramp to arrives later
        still)."""
        last, accel = float(self._twist[axis]), self.accel[0 if axis == 0 else 1]
        wanted = self._approach(remaining - last * ANSWER_LAG_S, top, 0.5 * accel, dt)
        return float(np.clip(wanted, last - accel * dt, last + accel * dt))

    @staticmethod
    def _approach(remaining: float, top: float, braking: float, dt: float) -> float:
        """The signed rate towards a target `remaining` away: at most top, slow enough to stop in
        the rest at `braking`, and covering no more than the rest in one tick."""
        size = abs(remaining)
        return math.copysign(min(top, math.sqrt(2.0 * braking * size), size / dt), remaining)

    @property
    def finished(self) -> bool:
        return self.index >= len(self.segments)
