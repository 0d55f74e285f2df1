"""shelves: the robot drives down the main aisle of a store or warehouse between two rows of
shelves; people at human speed walk the cross aisles between the shelves and step out into the
main aisle from behind them — hidden from the lidar until then — each when the robot is close.
Behind each row runs a back aisle the cross aisles open into."""
from __future__ import annotations

import numpy as np

from .route import TIMING, person, timed_walker, uniform, world_mapping

BACK_AISLE_M = 1.4      # m behind each row of shelves
STEP_OUT_S = (-2.5, -0.5)   # s before the robot is expected at the cross aisle that a person reaches the main aisle


def _row(rng: np.random.Generator, length: float, y0: float, y1: float) -> tuple[list[dict], list[float]]:
    """Shelves along x between y0 and y1 (boxes), and the centres of the cross aisles between them."""
    boxes, gaps, x = [], [], 2.5
    while True:
        shelf = uniform(rng, (2.0, 4.0))
        if x + shelf > length - 2.5:
            break
        boxes.append({"center": [x + shelf / 2, (y0 + y1) / 2], "size": [shelf, y1 - y0], "yaw": 0.0})
        x += shelf
        gap = uniform(rng, (1.2, 1.6))
        gaps.append(x + gap / 2)
        x += gap
    return boxes, gaps[:-1] if len(gaps) > 1 else gaps


def generate(rng: np.random.Generator) -> dict:
    length, aisle, depth = uniform(rng, (14.0, 18.0)), uniform(rng, (1.8, 2.3)), uniform(rng, (0.6, 1.0))
    low = BACK_AISLE_M + depth                       # the main aisle from y = low to low + aisle
    height = low + aisle + depth + BACK_AISLE_M
    middle = low + aisle / 2
    start, goal = (1.2, middle, 0.0), (length - 1.2, middle, 0.0)
    below, cross_low = _row(rng, length, BACK_AISLE_M, low)
    above, cross_high = _row(rng, length, low + aisle, low + aisle + depth)
    crossings = sorted(set(x for x in cross_low if any(abs(x - h) < 0.3 for h in cross_high)))
    crossings = crossings or cross_low[:1]
    walkers = []
    for x in rng.permutation(crossings)[:int(rng.integers(1, 4))]:
        who = person(rng)
        ends = [(x, BACK_AISLE_M / 2), (x, height - BACK_AISLE_M / 2)]
        if rng.random() < 0.5:
            ends.reverse()
        # on the loop [ends], the main aisle's middle is this far along
        arc = abs(middle - ends[0][1])
        at_s = TIMING.start_delay_s + (x - start[0]) / TIMING.expected_speed + uniform(rng, STEP_OUT_S)
        walkers.append(timed_walker(ends, arc, at_s, who))
    return world_mapping((length, height), start, goal, boxes=below + above, walkers=walkers,
                         people_seed=int(rng.integers(2**31)))
