"""doorway: a wall across a hall with one door (1.2–1.6 m between the wall ends) that the robot
must pass; a person walks back and forth through the same door at human speed and reaches it
when the robot does, coming towards it or going its way."""
from __future__ import annotations

import numpy as np

from ...geometry.polygons import arc_lengths
from .route import arrival_s, furniture, lane, person, timed_walker, uniform, world_mapping

APPROACH_M = 0.8        # the person walks straight through the door from this far either side


def generate(rng: np.random.Generator) -> dict:
    width, height = uniform(rng, (10.0, 14.0)), uniform(rng, (6.0, 8.0))
    wall_x, door = uniform(rng, (0.4, 0.6)) * width, uniform(rng, (1.2, 1.6))
    door_y = uniform(rng, (1.2 + door / 2, height - 1.2 - door / 2))
    walls = [(wall_x, 0.0, wall_x, door_y - door / 2), (wall_x, door_y + door / 2, wall_x, height)]
    start = (1.2, uniform(rng, (1.0, height - 1.0)), 0.0)
    goal = (width - 1.2, uniform(rng, (1.0, height - 1.0)), 0.0)
    route = np.array([start[:2], (wall_x - 1.0, door_y), (wall_x + 1.0, door_y), goal[:2]])
    who = person(rng)
    there = [(wall_x + uniform(rng, (2.5, 4.0)), uniform(rng, (1.0, height - 1.0))), (wall_x + APPROACH_M, door_y)]
    back = [(wall_x - APPROACH_M, door_y), (wall_x - uniform(rng, (2.5, 4.0)), uniform(rng, (1.0, height - 1.0)))]
    walk = np.array(there + back)                       # from the far side through the door and back
    loop = np.vstack([walk, walk[-2:0:-1]])
    ends = arc_lengths(np.vstack([loop, loop[:1]]))
    towards_robot, robot_way = ends[1] + APPROACH_M, ends[4] + APPROACH_M    # at the door, each way
    arc = towards_robot if rng.random() < 0.6 else robot_way
    walking = timed_walker(loop, arc, arrival_s(route, (wall_x, door_y)) + uniform(rng, (-1.0, 1.0)), who)
    lanes = [lane(route, 0.6), lane(walk, who.radius)] + [lane(np.reshape(w, (2, 2)), 0.05) for w in walls]
    boxes = furniture(rng, int(rng.integers(2, 6)), (0.1, 0.1, width - 0.1, height - 0.1), lanes)
    return world_mapping((width, height), start, goal, walls=walls, boxes=boxes, walkers=[walking],
                         people_seed=int(rng.integers(2**31)))
