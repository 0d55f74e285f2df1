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

from .social_force import (Obstacles, PeopleParams, RobotShape, State, accelerations, disc_around, integrate,
                           outline_distance)

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

    A party is known by the slot of its first member, and what it is doing is kept in arrays indexed
    by that number, so an update is a few vectorised steps plus a Python step only for the parties
    that arrive somewhere, stand, or go on.
    """

    def __init__(self, spec: PeopleSpec, params: PeopleParams = PeopleParams()):
        self.spec, self.params = spec, params
        n = spec.capacity
        self.state = State.empty(n)
        # one generator per walker and per flow, so adding a flow never changes the others' people
        self._waiting: list[deque[Arrival]] = [
            deque([walker_arrival(w, np.random.default_rng([spec.seed, 0, k]))]) for k, w in enumerate(spec.walkers)]
        self._flows = [FlowArrivals(f, np.random.default_rng([spec.seed, 1, k])) for k, f in enumerate(spec.flows)]
        self._waiting += [deque() for _ in self._flows]
        self._party = np.full(n, -1, np.int64)         # per slot: its party
        self._routes: list[Arrival | None] = [None] * n
        self._leg = np.zeros(n, np.int64)               # per party: the waypoint it walks to or stands at
        self._goal = np.zeros((n, 2))                   # ... that waypoint
        self._from = np.zeros((n, 2))                   # ... where the leg began (the waypoint before)
        self._wait = np.zeros(n)                        # ... the wait there (s)
        self._reach = np.zeros(n)                       # ... how near its centre must come to be there
        self._stopping = np.zeros(n, bool)              # ... arrived where it waits, not yet standing
        self._wait_until = np.full(n, np.nan)           # ... standing until then
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
        self._move_on(t)
        s = self.state
        slots = np.flatnonzero(s.active)
        party = self._party[slots]
        s.target[slots] = self._goal[party]
        standing = self._stopping[party] | ~np.isnan(self._wait_until[party])
        distance = np.hypot(*(self._goal[party] - s.position[slots]).T) - self._reach[party]
        braking = np.sqrt(2 * self.params.stop_deceleration * np.maximum(distance, 0.0))
        # slowing where it will wait, so it arrives as a person does; not at all while standing
        s.speed[slots] = np.where(standing, 0.0, np.where(self._wait[party] > 0, np.minimum(s.v0[slots], braking),
                                                          s.v0[slots]))

    def step(self, t: float, dt: float, obstacles: Obstacles, robot: RobotShape | None = None) -> None:
        """Without the simulator: update at t, then move everyone by dt (`integrate`)."""
        self.update(t, robot)
        integrate(self.state, accelerations(self.state, obstacles, robot, self.params), dt, self.params)

    def _move_on(self, t: float) -> None:
        """One step along its route for each party that is due one: arrive, stand, go on."""
        s = self.state
        slots = np.flatnonzero(s.active)
        if not len(slots):
            return
        party, n = self._party[slots], len(s)
        members = np.bincount(party, minlength=n)
        live = np.flatnonzero(members)
        centre = np.column_stack([np.bincount(party, s.position[slots, k], n)[live] for k in (0, 1)]) \
            / members[live, None]
        speed = np.bincount(party, np.hypot(*s.velocity[slots].T), n)[live] / members[live]
        waiting = ~np.isnan(self._wait_until[live])
        stopping = self._stopping[live]
        goal = self._goal[live]
        near = np.hypot(*(goal - centre).T) <= self._reach[live]
        # past a waypoint without a wait (beyond the line through it across the leg) is as good as
        # there: one pushed through a door wide of its middle must not turn back to it
        near |= (self._wait[live] <= 0) & (((centre - goal) * (goal - self._from[live])).sum(axis=1) >= 0)
        for p in live[stopping & (speed < STANDING_SPEED)]:
            self._stopping[p], self._wait_until[p] = False, t + self._wait[p]
        for p in live[waiting & (self._wait_until[live] <= t)]:
            self._wait_until[p] = np.nan
            self._next_leg(p)
        for p in live[near & ~stopping & ~waiting]:
            if self._wait[p] > 0:
                self._stopping[p] = True
            else:
                self._next_leg(p)

    def _next_leg(self, p: int) -> None:
        route = self._routes[p]
        leg = self._leg[p] + 1
        if leg == len(route.route):
            if not route.loop:
                self._leave(p)
                return
            leg = 0
        self._from[p] = self._goal[p]
        self._leg[p], self._goal[p], self._wait[p] = leg, route.route[leg], route.waits[leg]

    def _leave(self, p: int) -> None:
        s = self.state
        slots = np.flatnonzero(self._party == p)
        s.active[slots], s.velocity[slots] = False, 0.0
        self._party[slots] = -1
        self._routes[p] = None
        self.left += len(slots)

    def _spawn(self, arrival: Arrival, robot: RobotShape | None) -> bool:
        """Put the party in the world if its members have free slots and room; False: it waits."""
        s, size = self.state, len(arrival.radius)
        free = np.flatnonzero(~s.active)[:size]
        if len(free) < size or self._blocked(arrival, robot):
            return False
        p = int(free[0])
        s.position[free], s.velocity[free] = arrival.start, 0.0
        s.radius[free], s.reactive[free] = arrival.radius, arrival.reactive
        s.v0[free] = s.speed[free] = arrival.speed
        s.group[free] = p if size > 1 else -1
        s.active[free] = True
        self._party[free] = p
        self._routes[p] = arrival
        self._leg[p], self._goal[p], self._wait[p] = 0, arrival.route[0], arrival.waits[0]
        self._from[p] = arrival.start.mean(axis=0)
        self._reach[p] = self.params.waypoint_reach + 0.5 * (size - 1)
        self._stopping[p], self._wait_until[p] = False, np.nan
        self.spawned += size
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
        outline = np.ascontiguousarray(robot.outline, np.float64)
        x, y, reach = disc_around(outline)
        if (np.hypot(arrival.start[:, 0] - x, arrival.start[:, 1] - y) > reach + arrival.radius + SPAWN_CLEARANCE).all():
            return False                          # clear of the circle round the robot: no need to look closer
        return bool((outline_distance(arrival.start, outline) < arrival.radius + SPAWN_CLEARANCE).any())
