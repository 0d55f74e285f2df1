"""overtake: in a corridor wide enough to pass, a slow person walks the robot's way ahead of it,
so the robot catches up with it about halfway and has to overtake (or follow it to the end,
where it turns back). No furniture: a box beside the person would close the way past it."""
from __future__ import annotations

import numpy as np

from .route import TIMING, timed_mover, uniform, world_mapping

SLOW = (0.12, 0.25)     # m/s: well below the robot's expected speed


def generate(rng: np.random.Generator) -> dict:
    width = uniform(rng, (3.2, 4.0))
    middle = width / 2
    start_y, lane_y = middle + uniform(rng, (-0.3, 0.3)), middle + uniform(rng, (-0.2, 0.2))
    radius, speed = uniform(rng, (0.25, 0.32)), uniform(rng, SLOW)
    ahead_x = 1.2 + uniform(rng, (2.0, 3.5))
    # where the robot, driving as expected, would reach the person
    catch_s = (ahead_x - 1.2 + TIMING.expected_speed * TIMING.start_delay_s) / (TIMING.expected_speed - speed)
    catch_x = ahead_x + speed * catch_s
    length = max(uniform(rng, (14.0, 18.0)), catch_x + 6.0)
    start, goal = (1.2, start_y, 0.0), (length - 1.2, middle + uniform(rng, (-0.3, 0.3)), 0.0)
    near, far = (3.0, lane_y), (length - 3.0, lane_y)
    mover = timed_mover([near, far], ahead_x - near[0], 0.0, radius=radius, speed=speed)
    return world_mapping((length, width), start, goal, movers=[mover])
