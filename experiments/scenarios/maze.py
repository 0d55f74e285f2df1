"""Random mazes for exploration: a rectangle cut into a grid of rooms by walls with openings.

The rooms are linked by a random spanning tree (every room reachable), plus a few more openings
so that the maze has loops; each link is an opening in the wall between two rooms, of a random
width and place. The robot starts at the centre of a random room, turned any way. Before a maze is
returned it is checked on its rasterised world (`maze_problems`): the free space is one region, the
cells where the robot fits (a disk of the footprint's inscribed radius) are one region that holds
the start, and the footprint at the start keeps clear of every wall.
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
from scipy import ndimage

from ...geometry.grid import world_to_cell
from ...sim.world import WALL_THICKNESS, World, world_from_mapping
from ...geometry.polygons import point_segment_distance

WIDTH_M = (7.0, 12.0)           # the maze's bounds
HEIGHT_M = (5.0, 9.0)
ROOM_M = (1.8, 3.2)             # a room's side (wall centre to wall centre)
OPENING_M = (1.2, 2.5)          # clear width of an opening, wall end cap to wall end cap
LOOP_SHARE = 0.2                # share of the walls off the spanning tree that get an opening as well
START_CLEARANCE_M = 0.1         # the footprint at the start keeps this far from every wall
CHECK_RESOLUTION_M = 0.05       # the rasterised check's cells (slam's map resolution)
CAP = WALL_THICKNESS / 2        # a wall reaches this far beyond its segment's ends (sim/world.py)


def generate(rng: np.random.Generator) -> dict:
    """A maze world file's mapping (docs/worlds.md), reproducible from the generator's state."""
    width, height = (round(float(rng.uniform(*span)), 1) for span in (WIDTH_M, HEIGHT_M))
    cols, rows = (int(rng.integers(math.ceil(side / ROOM_M[1]), math.floor(side / ROOM_M[0]) + 1))
                  for side in (width, height))
    room_w, room_h = width / cols, height / rows
    links = spanning_tree(rows, cols, rng) | extra_links(rows, cols, rng)
    walls = []
    for (r, c), (r2, c2) in room_edges(rows, cols):
        if r2 == r:     # rooms side by side: a vertical wall at the right of (r, c)
            x = (c + 1) * room_w
            pieces = wall_pieces(r * room_h, (r + 1) * room_h, ((r, c), (r2, c2)) in links, rng)
            walls += [[x, a, x, b] for a, b in pieces]
        else:           # one above the other: a horizontal wall above (r, c)
            y = (r + 1) * room_h
            pieces = wall_pieces(c * room_w, (c + 1) * room_w, ((r, c), (r2, c2)) in links, rng)
            walls += [[a, y, b, y] for a, b in pieces]
    start_r, start_c = int(rng.integers(rows)), int(rng.integers(cols))
    start = [round((start_c + 0.5) * room_w, 3), round((start_r + 0.5) * room_h, 3),
             round(float(rng.uniform(-math.pi, math.pi)), 3)]
    doc = {"name": "maze", "bounds": [width, height],
           "walls": [[round(float(v), 3) for v in wall] for wall in walls],
           "robot": {"start": start, "drive": "mecanum"}}
    problems = maze_problems(world_from_mapping(doc, Path("<generated maze>")))
    if problems:
        raise RuntimeError("the maze generator made an unusable maze: " + "; ".join(problems))
    return doc


def room_edges(rows: int, cols: int) -> list[tuple[tuple[int, int], tuple[int, int]]]:
    """Every pair of neighbouring rooms, (row, col) ordered: the right and the upper neighbour."""
    edges = []
    for r in range(rows):
        for c in range(cols):
            if c + 1 < cols:
                edges.append(((r, c), (r, c + 1)))
            if r + 1 < rows:
                edges.append(((r, c), (r + 1, c)))
    return edges


def spanning_tree(rows: int, cols: int, rng: np.random.Generator) -> set:
    """Links between neighbouring rooms that join all of them without a loop."""
    return random_spanning_tree(room_edges(rows, cols), rng)


def random_spanning_tree(edges: list[tuple], rng: np.random.Generator) -> set:
    """The edges (pairs of hashable nodes) of a random spanning tree (randomised Kruskal)."""
    parent = {room: room for edge in edges for room in edge}

    def root(room):
        while parent[room] != room:
            parent[room] = parent[parent[room]]
            room = parent[room]
        return room

    tree = set()
    for i in rng.permutation(len(edges)):
        a, b = edges[i]
        if root(a) != root(b):
            parent[root(a)] = root(b)
            tree.add(edges[i])
    return tree


def extra_links(rows: int, cols: int, rng: np.random.Generator) -> set:
    """Each neighbouring pair with probability LOOP_SHARE (those already linked change nothing)."""
    return {edge for edge in room_edges(rows, cols) if rng.random() < LOOP_SHARE}


def wall_pieces(lo: float, hi: float, opening: bool, rng: np.random.Generator) -> list[tuple[float, float]]:
    """The segments of a wall from lo to hi along its line: whole, or with one opening of a random
    clear width and place. A piece shorter than a wall's thickness is left out (the opening then
    reaches the corner)."""
    if not opening:
        return [(lo, hi)]
    clear = float(rng.uniform(OPENING_M[0], min(OPENING_M[1], hi - lo - 2 * WALL_THICKNESS)))
    gap_lo = lo + float(rng.uniform(0.0, hi - lo - clear))
    gap_hi = gap_lo + clear
    pieces = [(lo, gap_lo - CAP), (gap_hi + CAP, hi)]
    return [(a, b) for a, b in pieces if b - a >= WALL_THICKNESS]


def maze_problems(world: World) -> list[str]:
    """What makes a world unfit as a maze to explore: free space in more than one region, space the
    robot fits in (its inscribed disk) split or not holding the start, the start too close to a wall."""
    grid = world.rasterize(CHECK_RESOLUTION_M)
    free = grid.data == 0
    problems = []
    _, regions = ndimage.label(free)
    if regions != 1:
        problems.append(f"the free space falls into {regions} regions")
    footprint = world.robot.footprint
    inscribed = float(point_segment_distance(np.zeros(2), footprint, np.roll(footprint, -1, axis=0)).min())
    clear = ndimage.distance_transform_edt(~(grid.data > 0)) * CHECK_RESOLUTION_M - CHECK_RESOLUTION_M / 2
    labels, fitting = ndimage.label(free & (clear > inscribed))
    start_label = labels[world_to_cell(grid.info, *world.robot.start[:2])]
    if fitting != 1 or start_label == 0:
        problems.append(f"the space the robot fits in falls into {fitting} regions"
                        + ("" if start_label else ", none at the start"))
    if world.footprint_clearance(world.robot.start) <= START_CLEARANCE_M:
        problems.append(f"the robot's start {world.robot.start.tolist()} is within {START_CLEARANCE_M} m of a wall")
    return problems

