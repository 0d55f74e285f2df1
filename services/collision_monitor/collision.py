"""Collision monitor after Nav2's collision_monitor, on the raw scan: the last check between the
planner and the chassis, independent of the costmaps.

Two polygons around the footprint (each vertex pushed out by stop_padding / slowdown_padding, as
costmap_2d pads a footprint): with at least min_points scan points that the command brings into
the stop zone, and closer to the footprint than stopping now would, the command becomes zero; else
with at least min_points inside the slowdown zone it is scaled by slowdown_ratio (all axes, so the
direction is kept). Points are in the robot frame. What a command brings is judged over the whole
motion it starts (a path, given by the caller): the commands already on their way, the command
held approach_check_s, then braking until the robot stands. A stop takes effect only after the
chassis's delay and its deceleration: judged on the instant, a turn at 0.5 rad/s was stopped when
a corner 0.5 m out was already 3 cm from a wall, and then rolled into it (generated maze 35).

Moving obstacles (the tracker's tracks, circles at constant velocity, robot frame at the command's
time): as Nav2's "approach" action, the command and each track are carried forward every
simulation_time_step up to time_before_collision; a command that brings a track into the stop zone
within that time, deeper than standing still would at the same time, is scaled down (in quarters)
to the fastest that does not, or stopped ("approach"). Standing still is the measure, not a
refuge: a person walking into a robot that moves away from them is no reason to stop. Scan points
on a track (within its radius + TRACKED_POINT_MARGIN) are left to the approach action and count in
neither zone: halving the speed of a robot leaving a person's way behind it, or stopping it because
a slight turn swung its corner a millimetre towards the person pressing on, let them walk into it
(generated crossing variant). The approach action also looks at the scan itself, fresher and exact
where the tracks are old estimates: every point in the stop zone, and every point in the slowdown
zone that may be a person's (within PERSON_POINT_MARGIN of a track). A command that brings
min_points of them closer faster than APPROACH_TOLERANCE_SPEED is scaled down like one meeting a
track: a person walks through the 5 cm stop zone between two scans, and the track of one who had
turned was 17 cm off them, its points split between on and off the track, too few either way
(generated doorway worlds, seeds 20–39: a creep at 2 cm/s and a turn at 0.4 rad/s into a person).

Unlike Nav2's stop polygon, a point in the stop zone stops only a command that approaches it (its
distance to the footprint would shrink more than stopping would shrink it): a robot that has come
within stop_padding of a door post may still turn or move away from it, instead of standing there
until the navigator gives up. Likewise the slowdown zone slows only a command that brings
min_points of its points nearer to the footprint than the nearest of them is now (by
SLOWDOWN_TOLERANCE): driving along a wall or through a door keeps the same clearance and keeps
its speed; closing in on a wall ahead, or swinging a corner towards one, is slowed.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

from ...schemas.messages import LaserScan
from ...geometry.polygons import points_in_polygons, transform_points
from ...geometry.footprint import STOP_PADDING, pad
from ...geometry.frames import scan_points
from ...geometry.se2 import integrate, inverse
from ...geometry.movers import TRACKED_POINT_MARGIN, Movers
from ...parameters.declare import Parameters, Rule, param

# a command -> the robot's poses (K, 3), robot frame now, while it carries the command out and then stops
PathOf = Callable[[np.ndarray], np.ndarray]
APPROACH_SCALES = (1.0, 0.75, 0.5, 0.25)   # of a command, tried in turn against the tracks (then standing)
# m beyond a track's radius within which a scan point may be the person it follows: the tracks in
# effect are tracks_delay_s (0.5 s) old, carried on at constant velocity, and a person who turned
# since is up to 0.3 m from there (0.5 s × a right-angle turn at 0.55 m/s)
PERSON_POINT_MARGIN = 0.4
ZONE_REACH_MARGIN = 1e-6      # m beyond the zones' farthest corner: far beyond rounding in the inside test
APPROACH_TOLERANCE = 0.01     # m deeper into the stop zone than standing that a command may bring a track
# ... and no sooner than this rate allows: just before a contact, a command closing in on a person
# faster than the simulator's fault_speed (0.02 m/s) makes the contact the robot's
APPROACH_TOLERANCE_SPEED = 0.01   # m/s
# m nearer than the nearest point in the slowdown zone is now that a command must bring points
# before it is slowed: along a wall or through a door the nearest stays as near, and a robot slowed
# wherever a wall stood within the zone crossed a building at a quarter of its speed (bench buildings)
SLOWDOWN_TOLERANCE = 0.01


@dataclass(frozen=True)
class CollisionMonitorParams(Parameters):
    """Nav2 collision_monitor's stop and slowdown polygons, here grown from the footprint."""
    footprint: tuple[tuple[float, float], ...] = param(((0.416, 0.318), (-0.416, 0.318), (-0.416, -0.318),
                                                        (0.416, -0.318)), min_items=3)   # m, robot frame (the mecanum paper's)
    stop_padding: float = param(STOP_PADDING, ge=0)   # m added around the footprint for the stop zone
    slowdown_padding: float = param(0.30, ge=0)       # m added around the footprint for the slowdown zone
    slowdown_ratio: float = param(0.5, ge=0.0, le=1.0)          # Nav2's default
    min_points: int = param(4, ge=1)                  # Nav2's default: fewer points inside a zone are noise
    approach_check_s: float = param(0.1, gt=0)        # s a command is held in the motion it is judged by, before braking
    # Nav2's "approach" action, here against the tracker's moving obstacles (constant velocity)
    time_before_collision: float = param(2.0, gt=0)   # s: a command meeting a track in its stop zone sooner is slowed or stopped
    simulation_time_step: float = param(0.1, gt=0)    # s between the predicted poses checked

    rules = (Rule("slowdown_padding", lambda p: p.slowdown_padding >= p.stop_padding,
                  "at least stop_padding ({p.stop_padding})"),)


@dataclass(frozen=True)
class MonitorResult:
    twist: np.ndarray    # (3,) the command to send
    action: str          # none | slowdown | stop
    points: int          # scan points inside the zone that acted (0 for none)
    reason: str


def distance_to_outline(points: np.ndarray, polygon: np.ndarray) -> np.ndarray:
    """(K,) distance from each point to the nearest edge of the polygon (its outline)."""
    a = polygon[:, None, :]                                   # (E, 1, 2) edge starts
    edge = np.roll(polygon, -1, axis=0)[:, None, :] - a       # (E, 1, 2)
    t = np.clip(np.sum((points[None] - a) * edge, axis=2) / np.sum(edge * edge, axis=2), 0.0, 1.0)
    nearest = a + t[..., None] * edge                         # (E, K, 2)
    return np.min(np.hypot(*(points[None] - nearest).transpose(2, 0, 1)), axis=0)


def robot_frame_points(scan: LaserScan, sensor_pose) -> np.ndarray:
    """(K, 2) scan endpoints in the robot frame; sensor_pose (x, y, yaw) is the laser on the robot."""
    return scan_points(scan, sensor_pose, inf_is_valid=False)


class CollisionMonitor:
    def __init__(self, params: CollisionMonitorParams):
        self.params = params
        footprint = self._footprint = np.asarray(params.footprint, float)
        self._radius = float(np.hypot(*footprint.T).max())       # the footprint's farthest point from the origin
        self.stop_zone = pad(footprint, params.stop_padding)
        self.slowdown_zone = pad(footprint, params.slowdown_padding)
        self._zones = np.stack([self.stop_zone, self.slowdown_zone])
        self._stop_reach = float(np.hypot(*self.stop_zone.T).max()) + ZONE_REACH_MARGIN
        self._slowdown_reach = float(np.hypot(*self.slowdown_zone.T).max()) + ZONE_REACH_MARGIN

    def check(self, twist, points, movers: Movers | None = None, path: PathOf | None = None) -> MonitorResult:
        """The command allowed with these obstacle points and moving obstacles (robot frame);
        path(twist) gives the robot's poses while it carries out a command and then stops
        (default: the command held for approach_check_s from standing, then an instant stop)."""
        path = path or self.held_path
        twist = np.asarray(twist, float)
        paths = Paths(path)
        points = np.asarray(points, float).reshape(-1, 2)
        # the zone and path tests only for points a path could bring into the stop zone, or in
        # the slowdown zone: a scan's other points (most of them) are in neither, and testing them
        # was most of the monitor's cost
        reach = max(self._slowdown_reach, self._stop_reach + paths.extent(twist))
        points = points[np.hypot(points[:, 0], points[:, 1]) <= reach]
        zones = points_in_polygons(points, self._zones)
        if movers is None or len(movers) == 0:
            return self._check_points(twist, paths, points, zones)
        on_track = movers.on_movers(points, TRACKED_POINT_MARGIN)
        result = self._check_points(twist, paths, points[~on_track], zones[~on_track])
        if result.action == "stop":
            return result
        near_person = movers.on_movers(points, PERSON_POINT_MARGIN)
        return self._check_movers(result, movers, paths, points[zones[:, 0] | (zones[:, 1] & near_person)])

    def held_path(self, twist) -> np.ndarray:
        """The robot's poses for a command held approach_check_s from standing, then an instant stop."""
        return np.stack([np.zeros(3), integrate((0.0, 0.0, 0.0), twist, self.params.approach_check_s)])

    def gaps(self, twist, movers: Movers) -> np.ndarray:
        """(K,) metres between the stop zone and the nearest track's circle every
        simulation_time_step up to time_before_collision while the robot drives twist (negative:
        the circle reaches into the zone, as deep as its radius when its centre is inside)."""
        p = self.params
        taus = np.arange(0.0, p.time_before_collision + 1e-9, p.simulation_time_step)
        robot = integrate((0.0, 0.0, 0.0), np.asarray(twist, float), taus)          # (K, 3)
        where = movers.positions[None] + movers.velocities[None] * taus[:, None, None]   # (K, N, 2)
        shifted = where - robot[:, None, :2]
        c, s = np.cos(robot[:, 2])[:, None], np.sin(robot[:, 2])[:, None]
        local = np.stack([c * shifted[..., 0] + s * shifted[..., 1], -s * shifted[..., 0] + c * shifted[..., 1]], -1)
        flat = local.reshape(-1, 2)
        inside = points_in_polygons(flat, self.stop_zone[None])[:, 0]
        distance = np.where(inside, 0.0, distance_to_outline(flat, self.stop_zone)).reshape(len(taus), -1)
        return np.min(distance - movers.radii[None], axis=1)

    def time_to_collision(self, twist, movers: Movers) -> float:
        """Seconds until a track's circle first reaches the stop zone while the robot drives twist
        (inf: not within time_before_collision)."""
        hit = self.gaps(twist, movers) <= 0
        return float(np.argmax(hit) * self.params.simulation_time_step) if hit.any() else np.inf

    def _worse_than_standing(self, twist: np.ndarray, movers: Movers, standing: np.ndarray) -> bool:
        """Whether driving twist brings a track into the stop zone, deeper than standing still would
        at the same time (by more than APPROACH_TOLERANCE, or APPROACH_TOLERANCE_SPEED × the time
        ahead when that is less), until standing would have the track touch the footprint itself
        (stop_padding into the zone): beyond, the prediction has a person walk through the robot. At
        least the next step is compared: a person already in the stop zone is no licence to close in."""
        p = self.params
        moving = self.gaps(twist, movers)
        touching = np.flatnonzero(standing < -p.stop_padding)
        until = max(touching[0] + 1 if len(touching) else len(standing), 2)
        taus = np.arange(until) * p.simulation_time_step
        allowed = np.minimum(APPROACH_TOLERANCE, APPROACH_TOLERANCE_SPEED * taus)
        return bool(np.any((moving[:until] < 0) & (moving[:until] < standing[:until] - allowed)))

    def _check_movers(self, result: MonitorResult, movers: Movers, paths: Paths, watched: np.ndarray) -> MonitorResult:
        standing = self.gaps(np.zeros(3), movers)
        closing = APPROACH_TOLERANCE_SPEED * self.params.approach_check_s
        for scale in APPROACH_SCALES:
            twist = result.twist * scale
            if (not self._worse_than_standing(twist, movers, standing)
                    and self._approached(paths, twist, watched, closing, np.inf) < self.params.min_points):
                if scale == 1.0:
                    return result
                return MonitorResult(twist, "approach", 0, f"a track met within {self.params.time_before_collision} s "
                                                           f"at full speed, deeper than standing")
        return MonitorResult(np.zeros(3), "approach", 0, "a track would be met deeper than standing still")

    def _check_points(self, twist: np.ndarray, paths: Paths, points: np.ndarray, zones: np.ndarray) -> MonitorResult:
        """The stop and slowdown rules on points (K, 2) with their zones (K, 2): in the stop zone,
        in the slowdown zone."""
        p = self.params
        inside = zones.sum(axis=0)
        approached = self._approached(paths, twist, points, 1e-9, p.stop_padding)
        if approached >= p.min_points:
            return MonitorResult(np.zeros(3), "stop", approached,
                                 f"{approached} scan points the command brings within {p.stop_padding} m "
                                 f"of the footprint before the robot can stop")
        if inside[1] >= p.min_points:
            slow = points[zones[:, 1]]
            standing = self._closest(paths.of(np.zeros(3)), slow)
            nearest = float(standing.min())
            nearer = self._approached(paths, twist, slow, 1e-9, min(p.slowdown_padding, nearest - SLOWDOWN_TOLERANCE),
                                      standing)
            if nearer >= p.min_points:
                return MonitorResult(twist * p.slowdown_ratio, "slowdown", nearer,
                                     f"{nearer} scan points within {p.slowdown_padding} m of the footprint the command "
                                     f"brings nearer than the nearest is ({nearest:.2f} m)")
        return MonitorResult(twist.copy(), "none", 0, "")

    def _approached(self, paths: Paths, twist: np.ndarray, points: np.ndarray, tolerance: float, within: float,
                    standing: np.ndarray | None = None) -> int:
        """How many of the points the command's path brings closer to the footprint's outline than
        stopping now would (by more than tolerance metres), and within `within` of it; `standing`:
        the points' distances when stopping now, if the caller has them already."""
        path = paths.of(twist)
        if np.isfinite(within) and len(points):
            # no point of the footprint moves farther along the path than this: points farther out
            # (most of them) cannot be brought within, and the path test is the monitor's cost
            sweep = float(np.max(np.hypot(path[:, 0], path[:, 1]) + self._radius * np.abs(path[:, 2])))
            near = self._signed_distance(points) < within + sweep
            points, standing = points[near], None if standing is None else standing[near]
        if len(points) == 0:
            return 0
        moving = self._closest(path, points)
        if standing is None:
            standing = self._closest(paths.of(np.zeros(3)), points)
        return int(np.count_nonzero((moving < standing - tolerance) & (moving < within)))

    def _signed_distance(self, points: np.ndarray) -> np.ndarray:
        """(K,) distance from each point to the footprint's outline, negative inside."""
        distance = distance_to_outline(points, self._footprint)
        return np.where(points_in_polygons(points, self._footprint[None])[:, 0], -distance, distance)

    def _closest(self, poses: np.ndarray, points: np.ndarray) -> np.ndarray:
        """(K,) the least signed distance from each point to the footprint's outline (negative
        inside) over the poses (robot frame now): a point a path carries through the outline is
        approached, not left."""
        local = transform_points(points, inverse(poses)).reshape(-1, 2)     # the points in each pose's frame
        return self._signed_distance(local).reshape(len(poses), len(points)).min(axis=0)


class Paths:
    """The robot's poses for each command asked about in one check, each worked out once."""

    def __init__(self, path: PathOf):
        self._path = path
        self._known: dict[bytes, np.ndarray] = {}

    def of(self, twist: np.ndarray) -> np.ndarray:
        key = np.asarray(twist, float).tobytes()
        if key not in self._known:
            self._known[key] = self._path(twist)
        return self._known[key]

    def extent(self, twist: np.ndarray) -> float:
        """How far the robot's origin gets from where it is, with the command or stopping now."""
        return float(max(np.hypot(*self.of(t)[:, :2].T).max() for t in (twist, np.zeros(3))))
