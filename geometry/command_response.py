"""How a chassis carries out velocity commands, for a service that must know how the robot moves
before its odometry can say so (the collision monitor).

A command stamped t takes effect from the first chassis step after t + delay, and each axis of the
velocity moves towards it by at most its acceleration limit per second: what the chassis service
does (cmd_vel_delay_s, acc_lim_x/y/theta, a step per wheel reading). So after a stop the robot
still rolls or turns until it has decelerated, and a command sent now moves it only from a delay
later: the commands alone say the robot stood at once and turned at once.
"""
from __future__ import annotations

import bisect

import numpy as np

from .se2 import se2_exp

MAX_PREDICTION_S = 10.0   # a path is never followed further than this (a robot stops long before)


def limit_acceleration(requested, previous, dt: float, acc_limits) -> np.ndarray:
    """Clip each axis of the change from `previous` to `acc_limits * dt` (batches broadcast).

    Axes within their limit come back bit for bit, so callers can tell whether anything clipped.
    """
    if dt < 0:
        raise ValueError(f"dt must not be negative, got {dt}")
    requested = np.asarray(requested, dtype=float)
    previous = np.asarray(previous, dtype=float)
    step = np.asarray(acc_limits, dtype=float) * dt
    change = requested - previous
    return np.where(np.abs(change) > step, previous + np.sign(change) * step, requested)


def _approach(target: list[float], velocity: list[float], steps: list[float]) -> list[float]:
    """limit_acceleration for one velocity, in plain floats (it runs every step of every path)."""
    return [v + max(-s, min(s, g - v)) for g, v, s in zip(target, velocity, steps)]


def poses_along(velocities: np.ndarray, durations: np.ndarray) -> np.ndarray:
    """(K + 1, 3) poses, in the frame of the first, reached by driving each body twist of
    velocities (K, 3) for its duration (K,) in turn (the first pose is zero)."""
    increments = se2_exp(velocities * durations[:, None])                    # (K, 3) in each step's frame
    headings = np.concatenate([[0.0], np.cumsum(increments[:, 2])])
    c, s = np.cos(headings[:-1]), np.sin(headings[:-1])
    moves = np.column_stack([c * increments[:, 0] - s * increments[:, 1], s * increments[:, 0] + c * increments[:, 1]])
    xy = np.vstack([np.zeros((1, 2)), np.cumsum(moves, axis=0)])
    return np.column_stack([xy, headings])


class CommandResponse:
    """The velocity a chassis has at each of its steps (a grid of step_s from zero) given the
    commands sent to it, and the motion that follows: since a stamp, or ahead for a new command."""

    def __init__(self, delay_s: float, acc_limits, step_s: float, keep_s: float):
        self.delay_ns = round(delay_s * 1e9)
        self.step_ns = round(step_s * 1e9)
        self.keep_ns = round(keep_s * 1e9)
        self.acc_steps = [float(a) * step_s for a in acc_limits]
        self.command_stamps: list[int] = []
        self.commands: list[list[float]] = []
        self.step_starts: list[int] = []           # each step's start; its velocity holds one step
        self.velocities: list[list[float]] = []

    def add(self, stamp_ns: int, twist) -> None:
        """A command sent, stamped after every earlier one."""
        self.command_stamps.append(stamp_ns)
        self.commands.append([float(v) for v in twist])
        old = bisect.bisect_right(self.command_stamps, stamp_ns - self.keep_ns - self.delay_ns) - 1
        if old > 0:
            del self.command_stamps[:old], self.commands[:old]

    def _command_at(self, step_ns: int, stamps: list[int], commands: list[list[float]]) -> list[float]:
        """The command in effect at a step: the last stamped before step − delay (the chassis's rule)."""
        i = bisect.bisect_left(stamps, step_ns - self.delay_ns) - 1
        return commands[i] if i >= 0 else [0.0, 0.0, 0.0]

    def _advance(self, until_ns: int) -> None:
        """Steps up to the one that holds until_ns."""
        if not self.step_starts:
            if not self.command_stamps:
                return
            first = self.command_stamps[0] // self.step_ns * self.step_ns     # at rest before any command
            self.step_starts.append(first)
            self.velocities.append([0.0, 0.0, 0.0])
        while self.step_starts[-1] + self.step_ns <= until_ns:
            start = self.step_starts[-1] + self.step_ns
            target = self._command_at(start, self.command_stamps, self.commands)
            self.step_starts.append(start)
            self.velocities.append(_approach(target, self.velocities[-1], self.acc_steps))
        old = bisect.bisect_right(self.step_starts, until_ns - self.keep_ns) - 1
        if old > 0:
            del self.step_starts[:old], self.velocities[:old]

    def velocity(self, at_ns: int) -> list[float]:
        """The velocity at at_ns (zero before the first command)."""
        self._advance(at_ns)
        i = bisect.bisect_right(self.step_starts, at_ns) - 1
        return list(self.velocities[i]) if i >= 0 else [0.0, 0.0, 0.0]

    def motion(self, since_ns: int, until_ns: int) -> np.ndarray:
        """The robot's pose at until_ns in its own frame at since_ns."""
        self._advance(until_ns)
        if until_ns <= since_ns or not self.step_starts:
            return np.zeros(3)
        first = max(bisect.bisect_right(self.step_starts, since_ns) - 1, 0)
        starts = np.maximum(np.array(self.step_starts[first:]), since_ns)
        ends = np.minimum(np.append(self.step_starts[first + 1:], until_ns), until_ns)
        keep = ends > starts
        return poses_along(np.array(self.velocities[first:])[keep], (ends - starts)[keep] / 1e9)[-1]

    def path(self, now_ns: int, twist, hold_s: float) -> np.ndarray:
        """(K, 3) poses, in the robot's frame at now_ns, a step apart until the robot stands: the
        commands already sent take effect, then twist sent now and held for hold_s, then zero."""
        current = self.velocity(now_ns)
        hold_ns = round(hold_s * 1e9)
        stamps = self.command_stamps + [now_ns, now_ns + hold_ns]
        commands = self.commands + [[float(v) for v in twist], [0.0, 0.0, 0.0]]
        step_end = (now_ns // self.step_ns + 1) * self.step_ns
        durations, velocities = [step_end - now_ns], [current]
        last_change = now_ns + hold_ns + self.delay_ns
        while step_end <= last_change or any(velocities[-1]):
            if step_end - now_ns > MAX_PREDICTION_S * 1e9:
                break
            velocities.append(_approach(self._command_at(step_end, stamps, commands), velocities[-1], self.acc_steps))
            durations.append(self.step_ns)
            step_end += self.step_ns
        return poses_along(np.array(velocities), np.array(durations) / 1e9)
