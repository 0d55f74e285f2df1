"""headon: in a corridor, a person walks back and forth along it at human speed and meets the
robot head-on somewhere in its middle third; its lane is near the centre line, where the robot
drives too. No furniture: a box beside the person's lane would leave the robot no way past it."""
from __future__ import annotations

import numpy as np

from .route import arrival_s, person, timed_walker, uniform, world_mapping


def generate(rng: np.random.Generator) -> dict:
    length, width = uniform(rng, (12.0, 16.0)), uniform(rng, (3.0, 3.8))
    middle = width / 2
    start, goal = (1.2, middle + uniform(rng, (-0.3, 0.3)), 0.0), (length - 1.2, middle + uniform(rng, (-0.3, 0.3)), 0.0)
    route = np.array([start[:2], goal[:2]])
    who = person(rng)
    lane_y = middle + uniform(rng, (-0.25, 0.25))
    far, near = (length - 3.0, lane_y), (3.0, lane_y)          # the person walks from the far end first
    meet_x = uniform(rng, (length / 3, 2 * length / 3))
    walking = timed_walker([far, near], far[0] - meet_x, arrival_s(route, (meet_x, lane_y)), who)
    return world_mapping((length, width), start, goal, walkers=[walking], people_seed=int(rng.integers(2**31)))
