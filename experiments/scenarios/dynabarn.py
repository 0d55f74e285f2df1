"""dynabarn: worlds drawn as DynaBARN draws them (the BARN Challenge's dynamic worlds 300–359).

Written after DynaBARN's public generator (github aninair1905/DynaBARN: create_plugin_polynomial.py,
polynomial_fit.py, base_boilerplate.world), not copied from it:
- the arena is the square [−10, 10]² walled on three sides by boxes 0.5 m thick centred on x = −10
  (back) and y = ±10, 20 m long; the side at x = +10 is open. No static clutter. The robot, the
  Jackal of BARN, starts outside the open side at (11, 0) facing −x; the goal is (−9, 0), 20 m ahead;
- every obstacle is a cylinder of radius 0.5 m moving on a polynomial: a degree-n polynomial through
  n + 1 random integer points of the arena; its keyframes are the polynomial at 10 evenly spaced x
  across the arena, the n + 1 points and where the curve meets the arena's edge, those inside the
  arena, sorted by x, entering at the leftmost edge point and leaving at the rightmost (edge points
  between are dropped), reversed half of the time;
- each segment between keyframes gets a speed from a 0.1 m/s grid, weighted by a normal density
  around the obstacle's mean speed, and takes its straight length over that speed; keyframes and
  times are rounded to 0.01, as the generator writes them into its Gazebo plugins;
- the obstacle moves as Gazebo's PoseAnimation (interpolation `gazebo`, sim/keyframes.py) and
  loops: at the end it jumps back to where it entered. All start at t = 0 on their first keyframe,
  on the arena's edge, so none stands where the robot starts.

Where this departs from the generator, and why: it draws n + 1 distinct x (a repeated x makes the fit
degenerate); it takes every real crossing of the edge y = ±10, where the generator keeps them only
when all of the polynomial's roots there are real (otherwise a curve could leave the arena between
keyframes) and, short of two edge points, adds random ones — here a polynomial without two edge
points is drawn again; keyframes whose rounded time does not come after the one before are dropped
(Gazebo would have two poses at one time); an obstacle whose curve would leave the world's bounds
(2 m of open ground around walls and start) is drawn again — Gazebo's ground has no end, and the
spline overshoots the arena's edge by up to 1.6 m (measured over 4312 obstacles, none beyond). The generator takes `--difficulty` but uses it nowhere;
its obstacle counts, speeds, orders and spreads are command-line numbers the repository does not
record. The bands here map the issue's 5–24 obstacles and 0.5–2 m/s onto three difficulties
(BANDS); polynomial degree (ORDER) and speed spread (SPEED_STD) are the same for all.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ...sim.barn_world import BOUNDS_MARGIN, JACKAL_DRIVE, JACKAL_FOOTPRINT
from ...sim.keyframes import Keyframes
from .route import world_mapping

ARENA = 10.0                  # m: obstacles move in [−ARENA, ARENA]²
WALL = 0.5                    # m, the walls' thickness (centred on the arena's edge)
RADIUS = 0.5                  # m, every obstacle
START = (11.0, 0.0, math.pi)  # x, y, yaw: outside the open side, facing the arena
GOAL = (-9.0, 0.0, math.pi)   # 20 m ahead, 0.75 m before the back wall's face
SAMPLES = 10                  # the polynomial at this many x, evenly spaced across the arena
SPEED_STEP = 0.1              # m/s between the segment speeds one is drawn from
ORDER = (1, 4)                # the polynomial's degree, drawn per obstacle
SPEED_STD = (0.1, 0.3)        # m/s, the spread of an obstacle's segment speeds around its mean, drawn
DIGITS = 2                    # keyframes and times are rounded to 0.01, as the plugins print them
ROOT_IMAG = 1e-9              # a root with a smaller imaginary part is real
# the world's bounds: the box around the walls and the start, with barn_world's open ground around it
LOW = np.full(2, -ARENA - WALL / 2 - BOUNDS_MARGIN)
HIGH = np.array([START[0] + BOUNDS_MARGIN, ARENA + WALL / 2 + BOUNDS_MARGIN])


@dataclass(frozen=True)
class Band:
    obstacles: tuple[int, int]     # how many, both ends included
    speed: tuple[float, float]     # m/s: the ends (included) of the segment speeds and the means drawn


BANDS = {"easy": Band((5, 10), (0.5, 1.0)), "medium": Band((11, 17), (1.0, 1.5)), "hard": Band((18, 24), (1.5, 2.0))}
DIFFICULTIES = tuple(BANDS)


def _keyframe_points(rng: np.random.Generator, order: int) -> np.ndarray | None:
    """An obstacle's way (N, 2) along a random polynomial, edge to edge; None when the polynomial
    does not meet the arena's edge twice."""
    xs = rng.choice(np.arange(-ARENA, ARENA + 1), order + 1, replace=False)
    ys = rng.integers(-int(ARENA), int(ARENA) + 1, order + 1).astype(np.float64)
    poly = np.poly1d(np.polyfit(xs, ys, order))
    across = np.linspace(-ARENA, ARENA, SAMPLES)
    found = [np.column_stack([across, poly(across)]), np.column_stack([xs, ys])]
    for level in (ARENA, -ARENA):
        roots = (poly - level).roots
        real = roots[np.abs(roots.imag) < ROOT_IMAG].real
        found.append(np.column_stack([real, np.full(len(real), level)]))
    points = np.unique(np.vstack(found), axis=0)                      # sorted by x, then y
    points = points[(np.abs(points) <= ARENA).all(axis=1)]
    edge = (np.abs(points) == ARENA).any(axis=1)
    if edge.sum() < 2:
        return None
    ends = points[edge][[0, -1]]                                      # sorted by x: leftmost, rightmost
    way = np.vstack([ends[:1], points[~edge], ends[1:]])
    return way[::-1] if rng.random() < 0.5 else way


def _times(rng: np.random.Generator, way: np.ndarray, band: Band) -> np.ndarray:
    """When the obstacle reaches each point of its way: each segment at a speed drawn around the
    obstacle's mean speed."""
    speeds = np.arange(round(band.speed[0] / SPEED_STEP), round(band.speed[1] / SPEED_STEP) + 1) * SPEED_STEP
    mean = round(float(rng.uniform(*band.speed)), 1)
    spread = round(float(rng.uniform(*SPEED_STD)), 2)
    weights = np.exp(-0.5 * ((speeds - mean) / spread) ** 2)
    drawn = rng.choice(speeds, len(way) - 1, p=weights / weights.sum())
    return np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(way, axis=0).T) / drawn)])


def obstacle(rng: np.random.Generator, band: Band) -> dict:
    """One obstacle's mover: its keyframes, looping, Gazebo's interpolation; one whose curve would
    take it outside the world's bounds (LOW, HIGH) is drawn again."""
    while True:
        way = _keyframe_points(rng, int(rng.integers(ORDER[0], ORDER[1] + 1)))
        if way is None:
            continue
        frames = np.round(np.column_stack([_times(rng, way, band), way]), DIGITS) + 0.0
        frames = frames[np.r_[frames[:-1, 0] < frames[1:, 0], True]]     # of keyframes at one rounded time, the last
        trace = Keyframes(frames[:, 0], frames[:, 1:], True, "gazebo").trace()
        if (trace - RADIUS >= LOW).all() and (trace + RADIUS <= HIGH).all():
            return {"radius": RADIUS, "keyframes": frames, "loop": True, "interpolation": "gazebo"}


def generate(rng: np.random.Generator, difficulty: str) -> dict:
    band = BANDS[difficulty]
    movers = [obstacle(rng, band) for _ in range(int(rng.integers(band.obstacles[0], band.obstacles[1] + 1)))]
    walls = [{"center": (-ARENA, 0.0), "size": (WALL, 2 * ARENA)},
             {"center": (0.0, ARENA), "size": (2 * ARENA, WALL)},
             {"center": (0.0, -ARENA), "size": (2 * ARENA, WALL)}]
    return world_mapping(HIGH - LOW, START, GOAL, origin=LOW, boxes=walls, movers=movers,
                         robot={"drive": JACKAL_DRIVE, "footprint": JACKAL_FOOTPRINT})
