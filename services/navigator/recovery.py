"""Recovery behaviours as pure open-loop motions over sim time.

A behaviour is a constant body twist held for a duration. `command(elapsed, period)` gives the
twist to send for the control period starting `elapsed` seconds into the behaviour, or None once
it is over. The last period is scaled down to the time that remains, so a caller stepping at the
period drives exactly twist × duration (the angle turned, the distance backed up) instead of
overshooting by up to one period. clear_costmaps has no motion: the node clears, then it is over.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

from .params import NavigatorParams

Twist3 = tuple[float, float, float]
ZERO: Twist3 = (0.0, 0.0, 0.0)
# Steps are fed float sim times; a remainder below this is rounding, not time left to drive.
TIME_EPS = 1e-9


@dataclass(frozen=True)
class Behaviour:
    name: str
    twist: Twist3 = ZERO
    duration_s: float = 0.0
    reset_distance: float | None = None   # clear_costmaps only: keep obstacles within this square

    def command(self, elapsed_s: float, period_s: float) -> Twist3 | None:
        remaining = self.duration_s - elapsed_s
        if remaining <= TIME_EPS:
            return None
        scale = min(1.0, remaining / period_s)
        return tuple(v * scale for v in self.twist)


def clear_costmaps(reset_distance: float) -> Behaviour:
    return Behaviour("clear_costmaps", reset_distance=reset_distance)


def rotate(angle: float, speed: float) -> Behaviour:
    """Turn in place by `angle` (rad, signed) at |speed| rad/s."""
    speed = abs(speed)
    return Behaviour("rotate", (0.0, 0.0, math.copysign(speed, angle)), abs(angle) / speed)


def back_up(distance: float, escape_vel: float) -> Behaviour:
    """Drive `distance` (m) along x at escape_vel (negative: backwards, as base_local_planner)."""
    return Behaviour("back_up", (escape_vel, 0.0, 0.0), abs(distance) / abs(escape_vel) if distance else 0.0)


def wait(duration: float) -> Behaviour:
    return Behaviour("wait", ZERO, duration)


def behaviour(name: str, params: NavigatorParams) -> Behaviour:
    """The behaviour `name` (one of params.RECOVERY_NAMES) with its settings from params."""
    if name == "clear_costmaps":
        return clear_costmaps(params.conservative_reset_dist)
    if name == "rotate":
        return rotate(params.rotate_angle, params.max_rotational_vel)
    if name == "back_up":
        return back_up(params.backup_dist, params.escape_vel)
    if name == "wait":
        return wait(params.wait_duration)
    raise ValueError(f"unknown recovery behaviour {name!r}")
