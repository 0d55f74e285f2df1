"""What every scenario kind builds its world from: the robot's route and when it gets where,
people timed to meet it, furniture kept out of the ways, and the world-file mapping.

People walk at human speed (1.0–1.5 m/s, Weidmann's distribution: sim/people) round their loops,
driven by the social force model: a reactive person avoids the robot as another pedestrian, a
distracted one (DISTRACTED_SHARE of them) does not see it. Each is timed from the robot's expected
progress along its route — it starts `start_delay_s` after sim 0 (the first goal goes out at 1 s,
the first plan follows) and drives at `expected_speed` — so that the person reaches the point
where its loop crosses the route when the robot is expected there (give or take what avoiding
others costs them). Until 2026-12-05 the kinds used kinematic movers at 0.3–0.6 m/s that never
gave way; docs/scenarios.md keeps their figures.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ...geometry.polygons import arc_lengths, point_segment_distance, segment_distance
from ...sim.people.plans import RADIUS_RANGE, SPEED_RANGE, draw_speeds


@dataclass(frozen=True)
class Timing:
    expected_speed: float = 0.4     # m/s: the local planner's max_vel_x (0.5) less turning and braking
    start_delay_s: float = 2.0      # sim s before the robot moves


TIMING = Timing()
DISTRACTED_SHARE = 0.2              # people who do not see the robot (on the phone, in a hurry)
KEEP_OUT_M = 0.3                    # furniture keeps this far from routes, lanes and the robot's ends


@dataclass(frozen=True)
class Person:
    radius: float                   # m
    speed: float                    # m/s
    distracted: bool


def uniform(rng: np.random.Generator, bounds: tuple[float, float]) -> float:
    return float(rng.uniform(*bounds))


def across_hall(rng: np.random.Generator, width: float, height: float):
    """The robot's start and goal 1.2 m from a hall's two ends, each at 40–60 % of its height,
    facing each other; and the straight route between them (2, 2)."""
    start_y, goal_y = (uniform(rng, (0.4, 0.6)) * height for _ in range(2))
    heading = math.atan2(goal_y - start_y, width - 2.4)
    start, goal = (1.2, start_y, heading), (width - 1.2, goal_y, heading)
    return start, goal, np.array([start[:2], goal[:2]])


def arrival_s(route: np.ndarray, point, timing: Timing = TIMING) -> float:
    """When the robot, driving its route (N, 2) as expected, is nearest to `point`."""
    a, b = route[:-1], route[1:]
    step = b - a
    length2 = np.maximum(np.sum(step * step, axis=1), 1e-12)
    t = np.clip(np.sum((np.asarray(point) - a) * step, axis=1) / length2, 0.0, 1.0)
    distance = np.hypot(*(a + t[:, None] * step - point).T)
    i = int(np.argmin(distance))
    along = arc_lengths(route)[i] + t[i] * math.sqrt(length2[i])
    return timing.start_delay_s + along / timing.expected_speed


def point_on_loop(loop: np.ndarray, arc: float) -> tuple[np.ndarray, int]:
    """The point at `arc` around a closed loop of vertices (N, 2), and the segment it lies on."""
    closed = np.vstack([loop, loop[:1]])
    ends = arc_lengths(closed)
    arc %= ends[-1]
    i = min(int(np.searchsorted(ends, arc, side="right")) - 1, len(loop) - 1)
    f = (arc - ends[i]) / max(ends[i + 1] - ends[i], 1e-12)
    return closed[i] + f * (closed[i + 1] - closed[i]), i


def loop_crossings(loop: np.ndarray, route: np.ndarray) -> list[tuple[float, np.ndarray]]:
    """(arc around the loop, point) wherever the closed loop (N, 2) crosses the route (M, 2)."""
    closed = np.vstack([loop, loop[:1]])
    ends = arc_lengths(closed)
    found = []
    for i in range(len(loop)):
        p, r = closed[i], closed[i + 1] - closed[i]
        for q, s in zip(route[:-1], np.diff(route, axis=0)):
            denominator = r[0] * s[1] - r[1] * s[0]
            if abs(denominator) < 1e-12:
                continue
            t = ((q - p)[0] * s[1] - (q - p)[1] * s[0]) / denominator
            u = ((q - p)[0] * r[1] - (q - p)[1] * r[0]) / denominator
            if 0.0 <= t < 1.0 and 0.0 <= u <= 1.0:
                found.append((float(ends[i] + t * (ends[i + 1] - ends[i])), p + t * r))
    return found


def route_crossing(loop: np.ndarray, route: np.ndarray, rng: np.random.Generator) -> tuple[float, np.ndarray]:
    """(arc around the loop, point) of one place, chosen at random, where the loop crosses the
    route — or, for a loop that never does, its point nearest to the route."""
    crossings = loop_crossings(loop, route)
    if crossings:
        return crossings[int(rng.integers(len(crossings)))]
    arcs = np.linspace(0.0, arc_lengths(np.vstack([loop, loop[:1]]))[-1], 400, endpoint=False)
    points = np.array([point_on_loop(loop, arc)[0] for arc in arcs])
    nearest = int(np.argmin(point_segment_distance(points[:, None], route[None, :-1], route[None, 1:]).min(axis=1)))
    return float(arcs[nearest]), points[nearest]


def walker(who: Person, path, *, loop: bool = True, start_s: float = 0.0, group: int = 1) -> dict:
    """A walker of the world file's people: key (docs/people.md)."""
    doc = {"path": [list(p) for p in np.asarray(path, np.float64)], "loop": loop, "speed": who.speed,
           "radius": who.radius, "distracted": who.distracted}
    if start_s > 0:
        doc["start_s"] = start_s
    if group > 1:
        doc["group"] = group
    return doc


def timed_walker(loop, arc: float, at_s: float, who: Person, group: int = 1) -> dict:
    """A person walking the closed loop (N, 2) for ever, placed so that it is `arc` around it at
    sim time at_s. Back and forth between A and B is the loop [A, B]."""
    loop = np.asarray(loop, np.float64)
    start, segment = point_on_loop(loop, arc - who.speed * at_s)
    return walker(who, [start, *np.roll(loop, -(segment + 1), axis=0)], group=group)


def crossing_walker(loop, route: np.ndarray, rng: np.random.Generator, who: Person, *, late_s: float = 0.0,
                    group: int = 1, timing: Timing = TIMING) -> dict:
    """A person on the loop who reaches a place where it crosses the route when the robot is
    expected there, plus late_s."""
    loop = np.asarray(loop, np.float64)
    arc, point = route_crossing(loop, route, rng)
    return timed_walker(loop, arc, arrival_s(route, point, timing) + late_s, who, group)


def person(rng: np.random.Generator) -> Person:
    """A person: radius, walking speed (Weidmann's, within sim/people's range), distracted or not."""
    radius = uniform(rng, RADIUS_RANGE)
    speed = float(draw_speeds(rng, *SPEED_RANGE, 1)[0])
    return Person(radius, round(speed, 3), bool(rng.random() < DISTRACTED_SHARE))


def box_corners(center, size, yaw: float) -> np.ndarray:
    c, s = math.cos(yaw), math.sin(yaw)
    half = np.array([[1, 1], [-1, 1], [-1, -1], [1, -1]]) * np.asarray(size) / 2
    return np.asarray(center) + half @ np.array([[c, s], [-s, c]])


def keeps_out(corners: np.ndarray, lanes: list[tuple[np.ndarray, float]]) -> bool:
    """Whether a box (4, 2) keeps clear of every lane: a polyline (N, 2) with a half-width."""
    edges_a, edges_b = corners, np.roll(corners, -1, axis=0)
    for line, half_width in lanes:
        gap = segment_distance(edges_a[:, None], edges_b[:, None], line[None, :-1], line[None, 1:]).min()
        if gap < half_width + KEEP_OUT_M:
            return False
    return True


def furniture(rng: np.random.Generator, count: int, area: tuple[float, float, float, float],
              lanes: list[tuple[np.ndarray, float]], size: tuple[float, float] = (0.4, 1.4),
              turned: bool = True, tries: int = 40) -> list[dict]:
    """Up to `count` boxes inside area (x0, y0, x1, y1), each clear of the lanes; a box that does
    not fit after a few tries is left out."""
    boxes = []
    for _ in range(count):
        for _ in range(tries):
            w, h = uniform(rng, size), uniform(rng, size)
            yaw = uniform(rng, (0.0, math.pi)) if turned and rng.random() < 0.3 else 0.0
            center = (uniform(rng, (area[0], area[2])), uniform(rng, (area[1], area[3])))
            corners = box_corners(center, (w, h), yaw)
            inside = (corners.min(axis=0) >= area[:2]).all() and (corners.max(axis=0) <= area[2:]).all()
            if inside and keeps_out(corners, lanes):
                boxes.append({"center": list(center), "size": [w, h], "yaw": yaw})
                lanes = lanes + [(np.vstack([corners, corners[:1]]), 0.0)]    # boxes do not overlap
                break
    return boxes


def world_mapping(bounds, start, goal, *, origin=None, walls=(), boxes=(), circles=(), movers=(),
                  walkers=(), flows=(), people_seed: int = 0, robot=None) -> dict:
    """The world file's mapping (docs/worlds.md), every number rounded to the millimetre so the
    file reads well and the same draw always writes the same bytes; `walkers` and `flows` are the
    people (docs/people.md); `robot` adds keys beside the start (drive, footprint)."""
    def mm(value):
        if isinstance(value, dict):
            return {k: mm(v) for k, v in value.items()}
        if isinstance(value, (list, tuple, np.ndarray)):
            return [mm(v) for v in value]
        if isinstance(value, str):
            return value
        if isinstance(value, (bool, np.bool_)):
            return bool(value)
        if isinstance(value, (int, np.integer)):   # counts (a group's size) stay whole numbers
            return int(value)
        return round(float(value), 3) + 0.0       # + 0.0: no -0.0 in the file

    doc = {"bounds": mm(bounds)}
    if origin is not None:
        doc["origin"] = mm(origin)
    for key, items in (("walls", walls), ("boxes", boxes), ("circles", circles), ("movers", movers)):
        if len(items):
            doc[key] = mm(list(items))
    if len(walkers) or len(flows):
        doc["people"] = {"seed": int(people_seed)}
        for key, items in (("walkers", walkers), ("flows", flows)):
            if len(items):
                doc["people"][key] = mm(list(items))
    doc["goals"] = [mm(goal)]
    doc["robot"] = {"start": mm(start), **mm(robot or {})}
    return doc


def lane(points, half_width: float) -> tuple[np.ndarray, float]:
    return np.asarray(points, np.float64), half_width
