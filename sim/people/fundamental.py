"""The model against a published speed–density relation: Weidmann's fundamental diagram.

Weidmann (1993) fitted walking speed against density in unidirectional flow:
    v(ρ) = v0 · (1 − exp(−γ · (1/ρ − 1/ρmax))),  v0 = 1.34 m/s, γ = 1.913 m⁻², ρmax = 5.4 m⁻².
`corridor_speed` measures the model's: people at a given density walk along a straight corridor
without ends (what leaves at one end comes in at the other, and people near one end feel those near
the other), with Weidmann's free speeds (or a flow's) and a flow's radii; after a warm-up the mean
speed along the corridor over everyone and every step is the figure.
"""
from __future__ import annotations

import math

import numpy as np

from .plans import RADIUS_RANGE, walking_speeds
from .social_force import Obstacles, PeopleParams, State, accelerations, integrate

WEIDMANN_V0 = 1.34       # m/s
WEIDMANN_GAMMA = 1.913   # m⁻²
WEIDMANN_RHO_MAX = 5.4   # m⁻²
LENGTH = 16.0            # m of corridor before it repeats
WIDTH = 2.5              # m between its walls
REACH = 3.0              # m beyond an end within which people are copied to the other end
# Weidmann's walkers: his free speeds, 1.34 ± 0.26 m/s, untruncated (a flow truncates them to SPEED_RANGE)
WEIDMANN_SPEEDS = (0.0, math.inf)


def weidmann_speed(density: float) -> float:
    """Weidmann's mean walking speed (m/s) at a density (people per m²)."""
    return WEIDMANN_V0 * (1.0 - math.exp(-WEIDMANN_GAMMA * (1.0 / density - 1.0 / WEIDMANN_RHO_MAX)))


def corridor_walls(length: float, width: float) -> Obstacles:
    """Two walls along y = 0 and y = width, reaching REACH beyond both ends, each a segment with the
    corridor on its right-hand side (the edge of a counter-clockwise solid beyond it)."""
    x0, x1 = -REACH - 1.0, length + REACH + 1.0
    return Obstacles(segments=np.array([[x1, 0.0, x0, 0.0], [x0, width, x1, width]]))


def place_in_corridor(rng: np.random.Generator, n: int, length: float, width: float, margin: float) -> np.ndarray:
    """n points (n, 2) picked at random from a hexagonal lattice over the corridor, dense enough to hold
    them with about 15 % to spare, at least `margin` from both walls."""
    spacing = math.sqrt(2 * length * (width - 2 * margin) / (math.sqrt(3) * 1.15 * n))
    while True:
        ys = np.arange(margin, width - margin + 1e-9, spacing * math.sqrt(3) / 2)
        xs = np.arange(0.0, length - spacing / 2, spacing)
        sites = np.array([(x + (k % 2) * spacing / 2, y) for k, y in enumerate(ys) for x in xs])
        if len(sites) >= n:
            return sites[rng.choice(len(sites), n, replace=False)]
        spacing *= 0.97


def with_copies(state: State, length: float) -> State:
    """The people plus copies of those within REACH of an end, shifted by the corridor's length to
    the other end: forces on the first len(state) of it are those of a corridor without ends."""
    x = state.position[:, 0]
    shifted = [(np.flatnonzero(x < REACH), length), (np.flatnonzero(x > length - REACH), -length)]
    index = np.concatenate([np.arange(len(state))] + [i for i, _ in shifted])
    offset = np.concatenate([np.zeros(len(state))] + [np.full(len(i), dx) for i, dx in shifted])
    copy = State(**{name: getattr(state, name)[index] for name in State.__dataclass_fields__})
    copy.position[:, 0] += offset
    copy.target[:, 0] += offset
    return copy


def corridor_speed(density: float, params: PeopleParams = PeopleParams(), seed: int = 0, length: float = LENGTH,
                   width: float = WIDTH, speeds: tuple[float, float] = WEIDMANN_SPEEDS, warm_s: float = 15.0,
                   measure_s: float = 15.0, dt: float = 0.02) -> float:
    """The model's mean walking speed (m/s) along a corridor without ends at `density` people per m²."""
    rng = np.random.default_rng(seed)
    n = round(density * length * width)
    state = State.empty(n)
    state.active[:] = True
    state.radius[:] = RADIUS_RANGE[0] + rng.random(n) * (RADIUS_RANGE[1] - RADIUS_RANGE[0])
    # evenly spread quantiles: a small crowd's mean speed is the distribution's, not a sample's
    state.v0[:] = state.speed[:] = walking_speeds(rng.permutation((np.arange(n) + 0.5) / n), *speeds)
    state.position[:] = place_in_corridor(rng, n, length, width, RADIUS_RANGE[1])
    walls = corridor_walls(length, width)
    warm, total = round(warm_s / dt), round((warm_s + measure_s) / dt)
    along = []
    for step in range(total):
        state.target[:] = state.position + (1.0, 0.0)
        integrate(state, accelerations(with_copies(state, length), walls, None, params)[:n], dt, params)
        state.position[:, 0] %= length
        if step >= warm:
            along.append(float(state.velocity[:, 0].mean()))
    return float(np.mean(along))
