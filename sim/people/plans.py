"""Who walks where: people's plans, the flows that bring them, and the population that holds them.

A party (one person, or a group of 2–4 walking together) follows a route of waypoints, standing a
while at those with a wait; a looping route starts over, one that ends leaves the world there. Two
things make parties:
  - a Walker: one party with its own route, from its first point at start_s;
  - a Flow: parties arriving at a source area at a rate (Poisson or regular), sizes drawn from
    weights, each walking via fixed points to a point drawn in the goal area, where it leaves.
Everything about an arrival (its time, size, speed, radii, who is distracted, where it stands at
the source) is drawn from its flow's own generator in arrival order before it spawns, so what the
robot does can delay a spawn but never changes who comes: the same seed gives the same people.

`Crowd` is the population: fixed-size State arrays (the simulator pre-allocates a body per slot) with
an active mask; `update(t)` spawns the arrivals that are due where there is room, moves parties on
along their routes, and sets every person's target and desired speed for the model.
"""
from __future__ import annotations

import math
import statistics
from collections import deque
from dataclasses import dataclass, field

import numpy as np

from .social_force import Obstacles, PeopleParams, RobotShape, State, accelerations, integrate

# Weidmann 1993: free walking speed 1.34 ± 0.26 m/s; drawn from that normal truncated to the range asked
WALKING_SPEED = statistics.NormalDist(1.34, 0.26)
SPEED_RANGE = (1.0, 1.5)       # m/s
RADIUS_RANGE = (0.2, 0.25)     # m, drawn uniformly
SPAWN_CLEARANCE = 0.05         # m between a new body and anyone already there
ROW_GAP = 0.1                  # m between the bodies of a group lined up at its start
STANDING_SPEED = 0.2           # m/s: a party slower than this (on average) stands, and its wait begins


def walking_speeds(u: np.ndarray, low: float, high: float) -> np.ndarray:
    """The walking speeds at quantiles u (in [0, 1)) of Weidmann's normal truncated to [low, high]."""
    if high <= low:
        return np.full(len(u), low)
    lo, hi = WALKING_SPEED.cdf(low), WALKING_SPEED.cdf(high)
    return np.array([min(high, max(low, WALKING_SPEED.inv_cdf(lo + x * (hi - lo)))) for x in u])


def draw_speeds(rng: np.random.Generator, low: float, high: float, n: int) -> np.ndarray:
    """n walking speeds drawn from Weidmann's normal truncated to [low, high] (by the inverse CDF, one
    uniform each, so a draw always takes the same share of the stream)."""
    return walking_speeds(rng.random(n), low, high)


@dataclass(frozen=True)
class Area:
    """An axis-aligned rectangle."""
    center: tuple[float, float]
    size: tuple[float, float] = (0.0, 0.0)

    def sample(self, rng: np.random.Generator) -> np.ndarray:
        return np.asarray(self.center) + (rng.random(2) - 0.5) * np.asarray(self.size)


@dataclass(frozen=True, eq=False)
class Walker:
    """One party with a route: it appears at path[0] at start_s."""
    path: np.ndarray                                   # (W, 2)
    waits: np.ndarray                                  # (W,) s standing at each point
    loop: bool = False                                 # after the last point, the first again; else leave
    group: int = 1                                     # people walking together, 1–4
    speed: tuple[float, float] = SPEED_RANGE           # m/s the party walks at, drawn within
    radius: tuple[float, float] = RADIUS_RANGE         # m, each person's, drawn within
    distracted: bool = False                           # ignores the robot
    start_s: float = 0.0


@dataclass(frozen=True, eq=False)
class Flow:
    """Parties arriving at `source` and walking via fixed points to a point in `goal`, where they leave."""
    source: Area
    goal: Area
    rate_per_min: float                                # people per minute (not parties)
    via: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))
    regular: bool = False                              # arrivals evenly spaced; else a Poisson process
    start_s: float = 0.0
    stop_s: float = math.inf                           # no arrival after this
    groups: tuple[float, ...] = (1.0, 0.0, 0.0, 0.0)   # weights of party sizes 1, 2, 3, 4
    distracted: float = 0.0                            # share of people who ignore the robot
    speed: tuple[float, float] = SPEED_RANGE
    radius: tuple[float, float] = RADIUS_RANGE

    @property
    def mean_group(self) -> float:
        w = np.asarray(self.groups)
        return float((w * np.arange(1, len(w) + 1)).sum() / w.sum())


@dataclass(frozen=True)
class PeopleSpec:
    """The people of a world (the `people:` key of a world file, docs/people.md)."""
    seed: int = 0
    walkers: tuple[Walker, ...] = ()
    flows: tuple[Flow, ...] = ()
    max_people: int | None = None                      # None: enough for what the flows bring (capacity)

    @property
    def capacity(self) -> int:
        """Slots in the population: max_people, else every walker plus, per flow, the people on its
        way at once by Little's law (arrival rate × the route walked at the slowest speed) with room
        for three standard deviations of the Poisson count and one more party."""
        if self.max_people is not None:
            return self.max_people
        slots = sum(w.group for w in self.walkers)
        for f in self.flows:
            route = np.vstack([f.source.center, f.via.reshape(-1, 2), f.goal.center])
            walking_s = float(np.hypot(*np.diff(route, axis=0).T).sum()) / max(f.speed[0], 0.1)
            present = f.rate_per_min / 60.0 * walking_s
            slots += math.ceil(present + 3 * math.sqrt(present)) + len(f.groups)
        return slots


@dataclass(frozen=True, eq=False)
class Arrival:
    """A party as drawn, before it spawns."""
    time: float
    start: np.ndarray            # (n, 2) where its members stand
    radius: np.ndarray           # (n,)
    reactive: np.ndarray         # (n,) bool
    speed: float
    route: np.ndarray            # (W, 2)
    waits: np.ndarray            # (W,)
    loop: bool


@dataclass(eq=False)
class Party:
    members: np.ndarray          # slots
    group: int                   # the group number the model sees (−1 alone)
    route: np.ndarray
    waits: np.ndarray
    loop: bool
    leg: int = 0                 # the waypoint it walks to, or stands at
    stopping: bool = False       # arrived where it will wait, not yet standing
    wait_until: float | None = None


def line_up(center: np.ndarray, towards: np.ndarray, radius: np.ndarray) -> np.ndarray:
    """Where a party's members stand at its start: abreast, side by side across the way to its
    first waypoint, centred on `center`."""
    way = np.asarray(towards, np.float64) - center
    d = float(np.hypot(*way))
    across = np.array([-way[1], way[0]]) / d if d > 1e-9 else np.array([0.0, 1.0])
    spacing = 2 * float(radius.max()) + ROW_GAP
    return center + np.outer((np.arange(len(radius)) - (len(radius) - 1) / 2) * spacing, across)


def _draw_party(rng: np.random.Generator, size: int, speed, radius, distracted_share: float) -> tuple:
    """The speed, radii and reactivity of a party, in a fixed order of draws."""
    v = float(draw_speeds(rng, speed[0], speed[1], 1)[0])
    r = radius[0] + rng.random(size) * (radius[1] - radius[0])
    reactive = rng.random(size) >= distracted_share
    return v, r, reactive


class FlowArrivals:
    """The arrivals of one flow, drawn in order from its own generator."""

    def __init__(self, flow: Flow, rng: np.random.Generator):
        self.flow, self.rng = flow, rng
        self.sizes = np.arange(1, len(flow.groups) + 1)
        self.weights = np.asarray(flow.groups, np.float64) / sum(flow.groups)
        self.next_time = flow.start_s + self._interval(first=True)

    def _interval(self, first: bool = False) -> float:
        f = self.flow
        if f.rate_per_min <= 0:
            return math.inf
        party_rate = f.rate_per_min / 60.0 / f.mean_group            # parties per second
        if f.regular:
            return 0.0 if first else 1.0 / party_rate
        return float(self.rng.exponential(1.0 / party_rate))

    def due(self, t: float) -> list[Arrival]:
        """The arrivals whose time has come by t."""
        out = []
        while self.next_time <= min(t, self.flow.stop_s):
            out.append(self._draw(self.next_time))
            self.next_time += self._interval()
        return out

    def _draw(self, time: float) -> Arrival:
        f, rng = self.flow, self.rng
        size = int(rng.choice(self.sizes, p=self.weights))
        speed, radius, reactive = _draw_party(rng, size, f.speed, f.radius, f.distracted)
        center, goal = f.source.sample(rng), f.goal.sample(rng)
        route = np.vstack([f.via.reshape(-1, 2), goal])
        return Arrival(time, line_up(center, route[0], radius), radius, reactive, speed, route,
                       np.zeros(len(route)), loop=False)


def walker_arrival(walker: Walker, rng: np.random.Generator) -> Arrival:
    speed, radius, reactive = _draw_party(rng, walker.group, walker.speed, walker.radius,
                                          1.0 if walker.distracted else 0.0)
    towards = walker.path[1] if len(walker.path) > 1 else walker.path[0] + (1.0, 0.0)
    return Arrival(walker.start_s, line_up(walker.path[0], towards, radius), radius, reactive, speed,
                   walker.path, walker.waits, walker.loop)


class Crowd:
    """The people of a world: their State for the model, their parties, and the arrivals still to come.

    Call `update(t, robot)` before computing forces (once per simulator step is enough: it only
    changes targets, desired speeds and who is there); the caller keeps `state.position` and
    `state.velocity` current (the simulator copies its bodies in, or `integrate` moves them).
    """

    def __init__(self, spec: PeopleSpec, params: PeopleParams = PeopleParams()):
        self.spec, self.params = spec, params
        self.state = State.empty(spec.capacity)
        # one generator per walker and per flow, so adding a flow never changes the others' people
        self._waiting: list[deque[Arrival]] = [
            deque([walker_arrival(w, np.random.default_rng([spec.seed, 0, k]))]) for k, w in enumerate(spec.walkers)]
        self._flows = [FlowArrivals(f, np.random.default_rng([spec.seed, 1, k])) for k, f in enumerate(spec.flows)]
        self._waiting += [deque() for _ in self._flows]
        self.parties: list[Party] = []
        self._groups = 0
        self.spawned = 0
        self.left = 0

    @property
    def queued(self) -> int:
        """People whose time has come but who wait at their source for room."""
        return sum(len(a.radius) for queue in self._waiting for a in queue)

    def update(self, t: float, robot: RobotShape | None = None) -> None:
        for flow, queue in zip(self._flows, self._waiting[len(self.spec.walkers):]):
            queue.extend(flow.due(t))
        for queue in self._waiting:
            while queue and queue[0].time <= t and self._spawn(queue[0], robot):
                queue.popleft()
        self.parties = [party for party in self.parties if self._follow(party, t)]

    def step(self, t: float, dt: float, obstacles: Obstacles, robot: RobotShape | None = None) -> None:
        """Without the simulator: update at t, then move everyone by dt (`integrate`)."""
        self.update(t, robot)
        integrate(self.state, accelerations(self.state, obstacles, robot, self.params), dt, self.params)

    def _spawn(self, arrival: Arrival, robot: RobotShape | None) -> bool:
        """Put the party in the world if its members have free slots and room; False: it waits."""
        s = self.state
        free = np.flatnonzero(~s.active)[:len(arrival.radius)]
        if len(free) < len(arrival.radius) or self._blocked(arrival, robot):
            return False
        s.position[free], s.velocity[free] = arrival.start, 0.0
        s.radius[free], s.reactive[free] = arrival.radius, arrival.reactive
        s.v0[free] = s.speed[free] = arrival.speed
        s.group[free] = self._groups if len(free) > 1 else -1
        s.active[free] = True
        self._groups += len(free) > 1
        self.spawned += len(free)
        self.parties.append(Party(free, int(s.group[free[0]]), arrival.route, arrival.waits, arrival.loop))
        return True

    def _blocked(self, arrival: Arrival, robot: RobotShape | None) -> bool:
        s = self.state
        others = s.position[s.active]
        gaps = np.hypot(*(arrival.start[:, None] - others[None]).transpose(2, 0, 1)) \
            - arrival.radius[:, None] - s.radius[s.active][None]
        if (gaps < SPAWN_CLEARANCE).any():
            return True
        if robot is None or len(robot.outline) < 3:
            return False
        return bool((_outline_distance(arrival.start, robot.outline) < arrival.radius + SPAWN_CLEARANCE).any())

    def _follow(self, party: Party, t: float) -> bool:
        """Move the party on along its route (one step per update: arrive, stand, go on) and set its
        members' targets and speeds; False once it has left the world."""
        s, m = self.state, party.members
        reach = self.params.waypoint_reach + 0.5 * (len(m) - 1)
        if party.wait_until is not None:
            if t >= party.wait_until:
                party.wait_until = None
                party.leg += 1
        elif party.stopping:
            if np.hypot(*s.velocity[m].T).mean() < STANDING_SPEED:
                party.stopping, party.wait_until = False, t + float(party.waits[party.leg])
        elif np.hypot(*(party.route[party.leg] - s.position[m].mean(axis=0))) <= reach:
            if party.waits[party.leg] > 0:
                party.stopping = True
            else:
                party.leg += 1
        if party.leg == len(party.route):
            if not party.loop:
                s.active[m] = False
                s.velocity[m] = 0.0
                self.left += len(m)
                return False
            party.leg = 0
        s.target[m] = party.route[party.leg]
        s.speed[m] = self._speed(party, reach)
        return True

    def _speed(self, party: Party, reach: float) -> np.ndarray:
        """Desired speeds: the party's own, less where it will stand (so it arrives slowing as a
        person does, at stop_deceleration), none while it stands."""
        s, m = self.state, party.members
        if party.stopping or party.wait_until is not None:
            return np.zeros(len(m))
        if party.waits[party.leg] <= 0:
            return s.v0[m]
        distance = np.hypot(*(party.route[party.leg] - s.position[m]).T) - reach
        return np.minimum(s.v0[m], np.sqrt(2 * self.params.stop_deceleration * np.maximum(distance, 0.0)))


def _outline_distance(points: np.ndarray, outline: np.ndarray) -> np.ndarray:
    """Distance from points (K, 2) to a polygon's boundary, 0 inside it."""
    a, b = outline, np.roll(outline, -1, axis=0)
    ab = b - a
    t = np.clip(((points[:, None] - a[None]) * ab[None]).sum(-1) / (ab * ab).sum(-1)[None], 0.0, 1.0)
    nearest = a[None] + t[..., None] * ab[None]
    d = np.hypot(*(points[:, None] - nearest).transpose(2, 0, 1)).min(axis=1)
    crossings = ((a[None, :, 1] > points[:, None, 1]) != (b[None, :, 1] > points[:, None, 1])) & (
        points[:, None, 0] < a[None, :, 0] + (points[:, None, 1] - a[None, :, 1]) * ab[None, :, 0]
        / np.where(ab[None, :, 1] == 0, 1.0, ab[None, :, 1]))
    return np.where(crossings.sum(axis=1) % 2 == 1, 0.0, d)
