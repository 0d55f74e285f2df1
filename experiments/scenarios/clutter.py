"""clutter: a hall strewn with boxes (some turned) and pillars, no movers: the static way is
all there is to find."""
from __future__ import annotations

import numpy as np

from .route import furniture, lane, uniform, world_mapping

END_ROOM_M = 0.9        # furniture keeps this far (plus KEEP_OUT_M) from the start and the goal


def generate(rng: np.random.Generator) -> dict:
    width, height = uniform(rng, (10.0, 14.0)), uniform(rng, (6.0, 9.0))
    start = (1.2, uniform(rng, (1.2, height - 1.2)), 0.0)
    goal = (width - 1.2, uniform(rng, (1.2, height - 1.2)), 0.0)
    ends = [lane([start[:2], start[:2]], END_ROOM_M), lane([goal[:2], goal[:2]], END_ROOM_M)]
    boxes = furniture(rng, int(rng.integers(8, 17)), (0.1, 0.1, width - 0.1, height - 0.1), ends, size=(0.4, 1.5))
    pillars = []
    for _ in range(int(rng.integers(2, 6))):
        centre, radius = np.array([uniform(rng, (0.5, width - 0.5)), uniform(rng, (0.5, height - 0.5))]), uniform(rng, (0.1, 0.3))
        if min(np.hypot(*(centre - start[:2])), np.hypot(*(centre - goal[:2]))) > END_ROOM_M + radius + 0.5:
            pillars.append({"center": centre, "radius": radius})
    return world_mapping((width, height), start, goal, boxes=boxes, circles=pillars)
