"""hall: the robot crosses a hall that people cross the other way — two flows of people at human
speed from wall to wall across the robot's way, a third of the parties groups of two or three,
a fifth of the people distracted — while a group or two stands talking near the way and walks
off after a while. About six people are in the hall at once."""
from __future__ import annotations


import numpy as np

from .route import Person, across_hall, furniture, lane, person, uniform, walker, world_mapping

PEOPLE_AT_ONCE = (4.0, 8.0)     # the flows' people in the hall at a time, by Little's law
WINDOW_S = 90.0                 # s: the flows run this long, well past the robot's crossing
GROUPS = {1: 0.6, 2: 0.3, 3: 0.1}


def _flow(x0: float, x1: float, y_from: float, y_to: float, rate: float) -> dict:
    band = x1 - x0
    return {"source": {"center": [(x0 + x1) / 2, y_from], "size": [band, 0.0]},
            "goal": {"center": [(x0 + x1) / 2, y_to], "size": [band, 0.0]},
            "rate_per_min": rate, "stop_s": WINDOW_S, "groups": dict(GROUPS), "distracted": 0.2}


def _standing(rng: np.random.Generator, width: float, height: float, route: np.ndarray) -> dict:
    """A group standing 1.0-2.0 m beside the way for 20-60 s, then walking off to a wall."""
    along = uniform(rng, (0.3, 0.7))
    side = 1 if rng.random() < 0.5 else -1
    spot = route[0] + along * (route[1] - route[0]) + (0.0, side * uniform(rng, (1.3, 2.0)))
    exit_y = 0.7 if side < 0 else height - 0.7
    who = person(rng)
    return walker(Person(who.radius, who.speed, False), [spot, (spot[0], exit_y)], loop=False,
                  group=int(rng.integers(2, 4))) | {"waits": {0: round(uniform(rng, (20.0, 60.0)), 1)}}


def generate(rng: np.random.Generator) -> dict:
    width, height = uniform(rng, (12.0, 16.0)), uniform(rng, (8.0, 10.0))
    start, goal, route = across_hall(rng, width, height)
    x0, x1 = 3.5, width - 3.5
    crossing_s = (height - 1.2) / 1.27                       # at Weidmann's mean speed in the range
    rate = uniform(rng, PEOPLE_AT_ONCE) / crossing_s * 60.0  # people per minute, both flows together
    share = uniform(rng, (0.35, 0.65))
    flows = [_flow(x0, x1, 0.6, height - 0.6, rate * share), _flow(x0, x1, height - 0.6, 0.6, rate * (1 - share))]
    walkers = [_standing(rng, width, height, route) for _ in range(int(rng.integers(1, 3)))]
    lanes = [lane(route, 0.6), lane([(x0 - 0.5, 0.0), (x0 - 0.5, height)], 0.0),
             lane([(x1 + 0.5, 0.0), (x1 + 0.5, height)], 0.0)]
    lanes += [lane(np.array(w["path"]), 1.0) for w in walkers]
    pillars_area = (0.1, 0.1, width - 0.1, height - 0.1)
    boxes = [b for b in furniture(rng, int(rng.integers(0, 3)), pillars_area, lanes, size=(0.3, 0.6))
             if not (x0 - 0.5 < b["center"][0] < x1 + 0.5)]       # the flows' band stays open
    return world_mapping((width, height), start, goal, boxes=boxes, walkers=walkers, flows=flows,
                         people_seed=int(rng.integers(2**31)))
