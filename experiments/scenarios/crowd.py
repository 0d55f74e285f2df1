"""crowd: in a hall, four to six parties walk at once at human speed — across the robot's way,
diagonally, along the hall and in circles, a third of them groups of two or three abreast — each
reaching the way within a few seconds of the robot."""
from __future__ import annotations

import math

import numpy as np

from .route import crossing_walker, furniture, lane, person, uniform, world_mapping

CIRCLE_POINTS = 12      # a circling person's loop


def _walk(rng: np.random.Generator, width: float, height: float, route: np.ndarray) -> np.ndarray:
    """A closed loop for one person: across, diagonal, along the hall, or a circle near the way."""
    x0, x1 = 3.0, width - 3.0
    pattern = rng.integers(4)
    if pattern == 0:
        x = uniform(rng, (x0, x1))
        return np.array([(x, 0.6), (x, height - 0.6)])
    if pattern == 1:
        return np.array([(uniform(rng, (x0, x1)), 0.6), (uniform(rng, (x0, x1)), height - 0.6)])
    if pattern == 2:
        y = uniform(rng, (1.0, height - 1.0))
        return np.array([(x0, y), (x1, y)])
    radius = uniform(rng, (1.0, 1.6))
    along = uniform(rng, (0.3, 0.7))
    centre = route[0] + along * (route[1] - route[0]) + (0.0, uniform(rng, (-0.8, 0.8)))
    centre = np.clip(centre, (x0 + radius, 0.6 + radius), (x1 - radius, height - 0.6 - radius))
    angles = np.linspace(0.0, 2 * math.pi, CIRCLE_POINTS, endpoint=False) * (1 if rng.random() < 0.5 else -1)
    return centre + radius * np.column_stack([np.cos(angles), np.sin(angles)])


def generate(rng: np.random.Generator) -> dict:
    width, height = uniform(rng, (10.0, 14.0)), uniform(rng, (8.0, 10.0))
    start_y, goal_y = uniform(rng, (1.5, height - 1.5)), uniform(rng, (1.5, height - 1.5))
    heading = math.atan2(goal_y - start_y, width - 2.4)
    start, goal = (1.2, start_y, heading), (width - 1.2, goal_y, heading)
    route = np.array([start[:2], goal[:2]])
    lanes, walkers = [lane(route, 0.6)], []
    for _ in range(int(rng.integers(4, 7))):
        loop = _walk(rng, width, height, route)
        who = person(rng)
        group = int(rng.choice([1, 2, 3], p=[2 / 3, 2 / 9, 1 / 9]))
        walkers.append(crossing_walker(loop, route, rng, who, late_s=uniform(rng, (-3.0, 3.0)), group=group))
        lanes.append(lane(np.vstack([loop, loop[:1]]), who.radius + 0.35 * (group - 1)))
    boxes = furniture(rng, int(rng.integers(0, 4)), (0.1, 0.1, width - 0.1, height - 0.1), lanes)
    return world_mapping((width, height), start, goal, boxes=boxes, walkers=walkers,
                         people_seed=int(rng.integers(2**31)))
