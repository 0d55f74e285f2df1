"""The maze generator: reproducible by seed, within its sizes, every room reachable by the robot."""
from pathlib import Path

import numpy as np
import pytest
from scipy import ndimage

from omninav.experiments.scenarios import KINDS
from omninav.experiments.scenarios.maze import HEIGHT_M, OPENING_M, WIDTH_M, generate, maze_problems
from omninav.geometry.grid import world_to_cell
from omninav.sim.world import world_from_mapping

SEEDS = range(10)
RES = 0.05


def maze(seed: int):
    doc = generate(np.random.default_rng(seed))
    return doc, world_from_mapping(doc, Path(f"maze-{seed}.yaml"))


def test_the_same_seed_gives_the_same_maze_and_another_seed_another():
    docs = [generate(np.random.default_rng(seed)) for seed in SEEDS]
    assert docs == [generate(np.random.default_rng(seed)) for seed in SEEDS]
    assert len({repr(doc) for doc in docs}) == len(docs)
    assert KINDS["maze"] is generate


@pytest.mark.parametrize("seed", SEEDS)
def test_every_maze_is_open_to_the_robot_everywhere(seed):
    doc, world = maze(seed)
    width, height = world.bounds
    assert WIDTH_M[0] <= width <= WIDTH_M[1] and HEIGHT_M[0] <= height <= HEIGHT_M[1]
    assert len(doc["walls"]) >= 4
    assert world.footprint_clearance(world.robot.start) > 0.1
    grid = world.rasterize(RES)
    free = grid.data == 0
    _, regions = ndimage.label(free)
    assert regions == 1
    # the openings are wider than the robot turned any way (a disk of its circumscribed radius), so
    # the cells where that disk fits form one region, holding the start
    circumscribed = float(np.hypot(*world.robot.footprint.T).max())
    assert 2 * circumscribed < OPENING_M[0]
    clear = ndimage.distance_transform_edt(free) * RES - RES / 2
    labels, fitting = ndimage.label(free & (clear > circumscribed))
    assert fitting == 1 and labels[world_to_cell(grid.info, *world.robot.start[:2])] == 1


def test_the_check_finds_a_closed_room_and_a_start_against_a_wall():
    doc = generate(np.random.default_rng(0))
    width, height = doc["bounds"]
    closed = {**doc, "walls": [*doc["walls"], [1.0, 0.0, 1.0, height]]}      # a closed strip at the left
    assert any("regions" in problem for problem in maze_problems(world_from_mapping(closed, Path("closed"))))
    x, y = 0.4, height / 2
    against = {**doc, "walls": [], "robot": {"start": [x, y, 0.0]}}           # 0.4 m from the left wall
    assert any("start" in problem for problem in maze_problems(world_from_mapping(against, Path("against"))))
