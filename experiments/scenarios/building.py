"""building: a floor plan of rooms, sometimes a corridor, joined by doors 0.9–1.3 m wide, with
dead-end rooms, alcoves and corridor ends, furniture against the walls and in the rooms; the robot
starts in one room and its goal lies in another two to four doors away. Drawn for one of the
robots the project ships (ROBOTS), and checked (generate_world) to be solvable for that robot's
own shape with 5 cm to spare on either side (check.py building_problems).
No people: a building is a static world where the way must be found, not waited for.
"""
from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass

import numpy as np

from ...cli.profile import load_profile
from ...geometry.footprint import DEFAULT_FOOTPRINT
from ...sim.world import WALL_THICKNESS
from .maze import random_spanning_tree
from .route import box_corners, keeps_out, lane, uniform, world_mapping

COLUMNS, ROWS = (3, 4), (2, 3)      # rooms across and up (corridor not counted)
ROOM_W_M, ROOM_H_M = (3.0, 4.6), (3.0, 4.2)
CORRIDOR_M = (1.5, 2.0)             # a corridor's clear width
CORRIDOR_SHARE = 0.6                # buildings with a corridor between two rows of rooms
DOOR_M = (0.9, 1.3)                 # a door's clear width, jamb to jamb
JAMB_M = 0.15                       # the least wall beside a door, to the room's corner
LOOP_SHARE = 0.15                   # neighbours with a door beyond the spanning tree's
ALCOVE_SHARE = 0.3                  # rooms with an alcove: a wall stub parallel to a side wall
ALCOVE_WIDTH_M, ALCOVE_DEPTH_M = (1.0, 1.5), (1.0, 1.8)
DOORS_AWAY = (2, 4)                 # the goal's room, counted in doors from the start's
CAP = WALL_THICKNESS / 2            # a wall reaches this far beyond its segment's ends (sim/world.py)


@dataclass(frozen=True)
class Robot:
    drive: str
    shape: np.ndarray               # (P, 2): what collides, the shape the world is checked for
    profile: str | None = None      # the robot profile `navigate --profile` takes


def _jackal() -> Robot:
    outline = np.asarray(load_profile("jackal").body["outline"], np.float64)
    (x0, y0), (x1, y1) = outline.min(axis=0), outline.max(axis=0)     # its wheels' notches do not pass doors
    return Robot("diff", np.array([[x1, y0], [x1, y1], [x0, y1], [x0, y0]]), "jackal")


ROBOTS = {"mecanum": lambda: Robot("mecanum", DEFAULT_FOOTPRINT), "omni3": lambda: Robot("omni3", DEFAULT_FOOTPRINT),
          "diff": lambda: Robot("diff", DEFAULT_FOOTPRINT), "jackal": _jackal}


@dataclass(frozen=True)
class Room:
    x0: float
    y0: float
    x1: float
    y1: float


def _layout(rng: np.random.Generator):
    """Rooms by name ((row, col), or "corridor"), the pairs of rooms that share a wall with the
    wall's line ((x, y0, x, y1) or (x0, y, x1, y)), and the building's bounds."""
    cols, rows = int(rng.integers(COLUMNS[0], COLUMNS[1] + 1)), int(rng.integers(ROWS[0], ROWS[1] + 1))
    xs = np.concatenate([[0.0], np.cumsum([uniform(rng, ROOM_W_M) for _ in range(cols)])])
    heights = [uniform(rng, ROOM_H_M) for _ in range(rows)]
    corridor_below = int(rng.integers(1, rows)) if rng.random() < CORRIDOR_SHARE else None   # row above it
    corridor = uniform(rng, CORRIDOR_M) + WALL_THICKNESS if corridor_below is not None else 0.0
    ys = [0.0]
    for r, h in enumerate(heights):
        ys.append(ys[-1] + (corridor if r == corridor_below else 0.0) + h)
    rooms = {(r, c): Room(xs[c], ys[r + 1] - heights[r], xs[c + 1], ys[r + 1]) for r in range(rows) for c in range(cols)}
    shared = []
    for (r, c), room in rooms.items():
        if c + 1 < cols:
            shared.append(((r, c), (r, c + 1), (room.x1, room.y0, room.x1, room.y1)))
        if r + 1 < rows and r + 1 != corridor_below:
            shared.append(((r, c), (r + 1, c), (room.x0, room.y1, room.x1, room.y1)))
    if corridor_below is not None:
        below, above = ys[corridor_below], ys[corridor_below] + corridor
        rooms["corridor"] = Room(0.0, below, float(xs[-1]), above)
        for c in range(cols):
            shared.append(((corridor_below - 1, c), "corridor", (xs[c], below, xs[c + 1], below)))
            shared.append(("corridor", (corridor_below, c), (xs[c], above, xs[c + 1], above)))
    return rooms, shared, (float(xs[-1]), float(ys[-1]))


def _door(rng: np.random.Generator, line) -> tuple[float, float]:
    """(lo, hi) along the wall's line of a door's clear opening, JAMB_M from the wall's ends."""
    lo, hi = (line[1], line[3]) if line[0] == line[2] else (line[0], line[2])
    clear = uniform(rng, DOOR_M)
    at = uniform(rng, (lo + CAP + JAMB_M, hi - CAP - JAMB_M - clear))
    return at, at + clear


def _wall_pieces(line, doors: list[tuple[float, float]]) -> list[list[float]]:
    """The wall along `line` with its doors left open (as world-file segments)."""
    vertical = line[0] == line[2]
    lo, hi = (line[1], line[3]) if vertical else (line[0], line[2])
    pieces, at = [], lo
    for a, b in sorted(doors):
        pieces.append((at, a - CAP))
        at = b + CAP
    pieces.append((at, hi))
    return [[line[0], a, line[0], b] if vertical else [a, line[1], b, line[1]] for a, b in pieces if b - a >= WALL_THICKNESS]


def _doors_away(links: list[tuple], start) -> dict:
    """Rooms by the number of doors between them and `start`."""
    neighbours: dict = {}
    for a, b in links:
        neighbours.setdefault(a, []).append(b)
        neighbours.setdefault(b, []).append(a)
    away, queue = {start: 0}, deque([start])
    while queue:
        room = queue.popleft()
        for other in neighbours.get(room, []):
            if other not in away:
                away[other] = away[room] + 1
                queue.append(other)
    return away


def _door_lanes(doors: list[tuple], reach: float) -> list[tuple[np.ndarray, float]]:
    """Keep-out lanes through every door: furniture leaves the way in and out free."""
    lanes = []
    for line, (a, b) in doors:
        mid, half = (a + b) / 2, (b - a) / 2
        depth = reach + 0.5
        points = [(line[0] - depth, mid), (line[0] + depth, mid)] if line[0] == line[2] else \
                 [(mid, line[1] - depth), (mid, line[1] + depth)]
        lanes.append(lane(points, half))
    return lanes


def _alcove(rng: np.random.Generator, room: Room, lanes) -> list[float] | None:
    """A wall stub from the room's bottom or top wall, parallel to its left or right wall, that
    makes a dead-end nook ALCOVE_WIDTH_M wide; None when it would close a door's way."""
    width, depth = uniform(rng, ALCOVE_WIDTH_M), uniform(rng, ALCOVE_DEPTH_M)
    if depth > room.y1 - room.y0 - 1.6 or width > room.x1 - room.x0 - 1.6:
        return None
    x = room.x0 + width if rng.random() < 0.5 else room.x1 - width
    y0, y1 = (room.y0, room.y0 + depth) if rng.random() < 0.5 else (room.y1 - depth, room.y1)
    stub = np.array([[x, y0], [x, y1]])
    return [x, y0, x, y1] if keeps_out(np.vstack([stub, stub[::-1]]), lanes) else None


def _furniture(rng: np.random.Generator, room: Room, lanes) -> list[dict]:
    """0–3 boxes against the room's walls and perhaps a table in it, each clear of the lanes."""
    boxes = []
    inner = (room.x0 + CAP, room.y0 + CAP, room.x1 - CAP, room.y1 - CAP)
    for _ in range(int(rng.integers(0, 4)) + int(rng.random() < 0.3)):
        against_wall = len(boxes) < 3
        for _ in range(20):
            w, d = uniform(rng, (0.4, 1.4)), uniform(rng, (0.4, 0.7))
            if against_wall:
                side = int(rng.integers(4))
                size = (w, d) if side < 2 else (d, w)
                cx = uniform(rng, (inner[0] + size[0] / 2, inner[2] - size[0] / 2))
                cy = uniform(rng, (inner[1] + size[1] / 2, inner[3] - size[1] / 2))
                cx, cy = ((cx, inner[1] + size[1] / 2), (cx, inner[3] - size[1] / 2),
                          (inner[0] + size[0] / 2, cy), (inner[2] - size[0] / 2, cy))[side]
            else:
                size = (uniform(rng, (0.6, 1.2)), uniform(rng, (0.6, 1.2)))
                cx, cy = uniform(rng, (inner[0] + 1.0, inner[2] - 1.0)), uniform(rng, (inner[1] + 1.0, inner[3] - 1.0))
            corners = box_corners((cx, cy), size, 0.0)
            if keeps_out(corners, lanes):
                boxes.append({"center": [cx, cy], "size": list(size), "yaw": 0.0})
                lanes = lanes + [(np.vstack([corners, corners[:1]]), 0.0)]
                break
    return boxes


def _pose_in(rng: np.random.Generator, room: Room, reach: float) -> tuple[float, float, float]:
    margin = reach + 0.25
    x = uniform(rng, (room.x0 + margin, max(room.x0 + margin, room.x1 - margin)))
    y = uniform(rng, (room.y0 + margin, max(room.y0 + margin, room.y1 - margin)))
    return x, y, uniform(rng, (-math.pi, math.pi))


def generate(rng: np.random.Generator, robot: str) -> dict:
    shape = ROBOTS[robot]()
    reach = float(np.hypot(*shape.shape.T).max())
    rooms, shared, bounds = _layout(rng)
    tree = random_spanning_tree([(a, b) for a, b, _ in shared], rng)
    doors, links, walls = [], [], []
    for a, b, line in shared:
        opened = [_door(rng, line)] if (a, b) in tree or rng.random() < LOOP_SHARE else []
        walls += _wall_pieces(line, opened)
        doors += [(line, door) for door in opened]
        links += [(a, b)] if opened else []
    start_room = [name for name in rooms if name != "corridor"][int(rng.integers(len(rooms) - ("corridor" in rooms)))]
    away = _doors_away(links, start_room)
    far = sorted(name for name, n in away.items() if DOORS_AWAY[0] <= n <= DOORS_AWAY[1] and name != "corridor")
    if not far:        # a small plan: the farthest room there is (the check refuses a goal beside the start)
        far = [max((name for name in away if name != "corridor"), key=lambda name: (away[name], str(name)))]
    goal_room = far[int(rng.integers(len(far)))]
    start, goal = _pose_in(rng, rooms[start_room], reach), _pose_in(rng, rooms[goal_room], reach)
    lanes = _door_lanes(doors, reach) + [lane([p[:2], p[:2]], reach + 0.2) for p in (start, goal)]
    boxes = []
    for name, room in rooms.items():
        if name == "corridor":
            continue
        if rng.random() < ALCOVE_SHARE:
            stub = _alcove(rng, room, lanes)
            if stub is not None:
                walls.append(stub)
                lanes = lanes + [lane(np.reshape(stub, (2, 2)), CAP)]
        boxes += _furniture(rng, room, lanes)
    return world_mapping(bounds, start, goal, walls=walls, boxes=boxes,
                         robot={"drive": shape.drive, "footprint": shape.shape.tolist()})
