"""crossing: in a hall, one or two people walk back and forth across the robot's way,
perpendicular to it at human speed, each reaching the way about when the robot does (within a
second and a half)."""
from __future__ import annotations


import numpy as np

from .route import across_hall, crossing_walker, furniture, lane, person, uniform, world_mapping


def generate(rng: np.random.Generator) -> dict:
    width, height = uniform(rng, (10.0, 14.0)), uniform(rng, (6.0, 8.0))
    start, goal, route = across_hall(rng, width, height)
    lanes, walkers = [lane(route, 0.6)], []
    first = uniform(rng, (3.5, width / 2))
    for x in ([first] if rng.random() < 0.5 else [first, uniform(rng, (first + 1.5, width - 3.5))]):
        who = person(rng)
        ends = [(x, 0.6), (x, height - 0.6)] if rng.random() < 0.5 else [(x, height - 0.6), (x, 0.6)]
        walkers.append(crossing_walker(ends, route, rng, who, late_s=uniform(rng, (-1.5, 1.5))))
        lanes.append(lane(ends, who.radius))
    boxes = furniture(rng, int(rng.integers(2, 5)), (0.1, 0.1, width - 0.1, height - 0.1), lanes)
    return world_mapping((width, height), start, goal, boxes=boxes, walkers=walkers,
                         people_seed=int(rng.integers(2**31)))
