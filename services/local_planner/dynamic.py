"""Moving obstacles for the local planner: the tracker's tracks predicted along each rollout, after
Nav2 MPPI's critics (one vectorised call scores the whole batch).

A track (geometry/movers.py) is a circle moving at constant velocity; its position at the time τ a
rollout pose is reached is its position at the tick plus velocity·τ, with the predicted standard
deviation σ(τ). A pose's slack is its footprint's distance to the predicted
circle less dynamic_obstacle_margin (hard), and less also dynamic_obstacle_sigmas·σ(τ) (soft). A
rollout meets a mover at the first pose after the start whose hard slack is negative and below
the start's (moving away from a person who came too near is no meeting); it is illegal when it
meets one sooner than the robot standing still would (people who do not give way walk into a
robot that stopped in their way: braking is no refuge, and what meets them only later is
re-planned next cycle), and with closing_at_once (DwaParams.evade_movers) when it closes in on
one at once (standing would too: a person within the margin walking at the robot). Rollouts are
carried on past sim_time to dynamic_horizon at their last twist (carried_on) for this. Within
dynamic_influence_distance of the soft slack a rollout costs dynamic_obstacle_scale per unit of
intrusion deeper than at its start, and up to as much again the sooner it meets a mover.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

from ...geometry.movers import Movers
from ...geometry.se2 import compose, relative

CARRY_STEP_S = 0.1      # s between the poses a rollout is carried on by past its end


@njit(cache=True, inline="always")
def _polygon_distance(u, v, polygon):
    """Distance from (u, v) to the polygon (0 inside)."""
    inside = False
    best = np.inf
    n = polygon.shape[0]
    for i in range(n):
        ax, ay = polygon[i, 0], polygon[i, 1]
        bx, by = polygon[(i + 1) % n, 0], polygon[(i + 1) % n, 1]
        if (ay > v) != (by > v) and u < ax + (v - ay) * (bx - ax) / (by - ay):
            inside = not inside
        ex, ey = bx - ax, by - ay
        t = ((u - ax) * ex + (v - ay) * ey) / (ex * ex + ey * ey)
        t = min(1.0, max(0.0, t))
        dx, dy = u - (ax + t * ex), v - (ay + t * ey)
        best = min(best, math.sqrt(dx * dx + dy * dy))
    return 0.0 if inside else best


@njit(cache=True)
def _slack(poses, times, footprint, positions, velocities, radii, variance, margin, sigmas, hard, soft):
    """hard, soft (T, S): the least slack over the movers of each pose (pose k reached at times[k]),
    without and with the sigmas of the predicted position."""
    trajectories, steps = poses.shape[0], poses.shape[1]
    for t in range(trajectories):
        for k in range(steps):
            x, y, theta = poses[t, k, 0], poses[t, k, 1], poses[t, k, 2]
            c, s = math.cos(theta), math.sin(theta)
            tau = times[k]
            hard[t, k], soft[t, k] = np.inf, np.inf
            for n in range(radii.shape[0]):
                px = positions[n, 0] + velocities[n, 0] * tau - x
                py = positions[n, 1] + velocities[n, 1] * tau - y
                var = variance[n, 0] + 2.0 * tau * variance[n, 1] + tau * tau * variance[n, 2]
                gap = _polygon_distance(c * px + s * py, -s * px + c * py, footprint) - radii[n] - margin
                hard[t, k] = min(hard[t, k], gap)
                soft[t, k] = min(soft[t, k], gap - sigmas * math.sqrt(max(var, 0.0)))


def slack(poses: np.ndarray, dt, footprint: np.ndarray, movers: Movers, margin: float,
          sigmas: float) -> tuple[np.ndarray, np.ndarray]:
    """(hard, soft), each (T, S), of rollouts (T, S, 3) whose poses are dt apart (or reached at the
    times (S,) dt gives): metres each pose's footprint keeps beyond the margin from the nearest
    predicted mover (negative: too close), and the same less sigmas standard deviations of the
    mover's predicted position."""
    poses = np.ascontiguousarray(poses, np.float64)
    hard, soft = np.empty(poses.shape[:2]), np.empty(poses.shape[:2])
    times = np.arange(poses.shape[1]) * dt if np.isscalar(dt) else np.asarray(dt, np.float64)
    # contiguous (movers_at's positions are a column slice): one compiled variant, as warm_up's
    _slack(poses, np.ascontiguousarray(times, np.float64), np.ascontiguousarray(footprint, np.float64),
           np.ascontiguousarray(movers.positions),
           np.ascontiguousarray(movers.velocities), movers.radii, movers.variance, float(margin), float(sigmas),
           hard, soft)
    return hard, soft


def carried_on(poses: np.ndarray, dt: float, horizon: float) -> tuple[np.ndarray, np.ndarray]:
    """(poses (T, S', 3), times (S',)): rollouts (T, S+1, 3) of poses dt apart carried on at their
    last step's twist, every CARRY_STEP_S, until `horizon` s — a robot at 2 m/s meets a person
    coming at 1 m/s 3 m off within a second of a 1.2 s rollout's end, too late to turn then (DynaBARN
    easy-24). A rollout stopped at its first illegal pose stays there."""
    steps = poses.shape[1] - 1
    times = np.arange(steps + 1) * dt
    extra = int(math.ceil((horizon - steps * dt) / CARRY_STEP_S - 1e-9)) if steps else 0
    if extra <= 0:
        return poses, times
    per_step = relative(poses[:, -2], poses[:, -1])
    hop = np.zeros_like(per_step)
    repeats = max(1, int(round(CARRY_STEP_S / dt)))
    for _ in range(repeats):
        hop = compose(hop, per_step)
    carried = [poses[:, -1]]
    for _ in range(extra):
        carried.append(compose(carried[-1], hop))
    return (np.concatenate([poses, np.stack(carried[1:], axis=1)], axis=1),
            np.concatenate([times, steps * dt + np.arange(1, extra + 1) * repeats * dt]))


def first_contact(hard: np.ndarray) -> np.ndarray:
    """(T,) the first step after the start at which each rollout comes closer than the margin and
    closer than at its start (moving away from a mover already too near is no contact); the
    number of steps when none does."""
    closing = (hard[:, 1:] < 0) & (hard[:, 1:] < hard[:, :1])
    return np.where(closing.any(axis=1), np.argmax(closing, axis=1) + 1, hard.shape[1])


def critic(hard: np.ndarray, soft: np.ndarray, standing: np.ndarray, influence: float,
           scale: float, closing_at_once: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """(legal (T,), cost (T,)) of rollouts from their slacks (T, S), `standing` (1, S) the hard slack
    of the robot standing where it is: a rollout that meets a mover sooner than standing still
    would is illegal (standing in a person's way is no refuge: what reaches them later is
    legal, and the next cycle looks again); the cost grows with how much deeper than at the start
    the uncertain prediction intrudes into the influence distance (a mover already near cost all
    rollouts alike, and drowned the difference between leaving its way and lingering in it)."""
    contact = first_contact(hard)
    standing_contact = first_contact(standing)[0]
    # closing in on a mover already within the margin is met at once whether standing or driving
    # on: only a way that does not close in is legal then (driving on into a person who walks at
    # the robot made the contact the robot's)
    legal = contact >= standing_contact
    if closing_at_once:
        legal &= (contact > 1) | (standing_contact > 1)
    intrusion = np.clip(1.0 - soft / influence, 0.0, None)
    deeper = np.clip(intrusion[:, 1:].max(axis=1, initial=0.0) - intrusion[:, 0], 0.0, None)
    sooner = (hard.shape[1] - contact) / hard.shape[1]      # 0 without a meeting, towards 1 the sooner
    return legal, scale * (deeper + sooner)


def warm_up() -> None:
    square = np.array([[0.1, 0.1], [-0.1, 0.1], [-0.1, -0.1], [0.1, -0.1]])
    movers = Movers(np.ones((1, 2)), np.zeros((1, 2)), np.full(1, 0.2), np.zeros((1, 3)))
    slack(np.zeros((1, 2, 3)), 0.1, square, movers, 0.1, 2.0)
