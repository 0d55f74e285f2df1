"""overtake: in a corridor, a person walking the robot's way at human speed — more than twice the
robot's — comes from behind and overtakes it about halfway, in a lane beside the robot's (the
corridor's centre, where the robot drives); it walks back at the far end and may meet the robot
head-on on its way back. No furniture: a box beside the person would close the way past it."""
from __future__ import annotations

import numpy as np

from .route import TIMING, person, uniform, walker, world_mapping

SIDE_M = (0.95, 1.1)    # m between the corridor's centre line and the person's lane
ACCELERATING_S = 0.5    # s a person takes to reach walking speed (the model's relaxation time)


def generate(rng: np.random.Generator) -> dict:
    width = uniform(rng, (3.2, 4.0))
    middle = width / 2
    length = uniform(rng, (14.0, 18.0))
    start, goal = (1.2, middle + uniform(rng, (-0.1, 0.1)), 0.0), (length - 1.2, middle + uniform(rng, (-0.3, 0.3)), 0.0)
    who = person(rng)
    lane_y = middle + uniform(rng, SIDE_M) * (1 if rng.random() < 0.5 else -1)
    near, far = (0.6, lane_y), (length - 0.6, lane_y)
    catch_x = uniform(rng, (length / 3, 2 * length / 3))
    # when the robot, driving as expected, is there: the person, setting off from the corridor's
    # start end late enough to walk straight there (half a second to get going), passes it then
    catch_s = TIMING.start_delay_s + (catch_x - start[0]) / TIMING.expected_speed
    set_off_s = max(0.0, catch_s - (catch_x - near[0]) / who.speed - ACCELERATING_S)
    walking = walker(who, [near, far], start_s=set_off_s)
    return world_mapping((length, width), start, goal, walkers=[walking], people_seed=int(rng.integers(2**31)))
