"""Velocity smoother after Nav2's velocity_smoother (open loop): between the planner and the chassis,
run at smoothing_frequency in sim time.

Each step the latest command, clipped to [min_velocity, max_velocity], is approached per axis from
the last output: speeding up (same sign, larger magnitude) by at most max_accel·dt, anything else
(slowing down, reversing) by at most |max_decel|·dt, as Nav2 does. An output component within the
deadband becomes 0. No command for velocity_timeout seconds (sim time) makes the target zero, so
the robot stops at the deceleration limits rather than at once.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ...parameters.declare import Parameters, Rule, param


@dataclass(frozen=True)
class VelocitySmootherParams(Parameters):
    """Nav2 velocity_smoother's names and defaults; axes are (vx, vy, wz)."""
    smoothing_frequency: float = param(20.0, gt=0)  # Hz
    # what the chassis allows on every axis: Nav2's defaults are a differential drive's (vy 0), which
    # would stop a mecanum robot strafing
    max_velocity: tuple[float, float, float] = param((0.5, 0.5, 2.5), items=3, finite=True)
    min_velocity: tuple[float, float, float] = param((-0.5, -0.5, -2.5), items=3, finite=True)
    max_accel: tuple[float, float, float] = param((2.5, 2.5, 3.2), items=3, ge=0)
    max_decel: tuple[float, float, float] = param((-2.5, -2.5, -3.2), items=3, le=0)
    deadband_velocity: tuple[float, float, float] = param((0.0, 0.0, 0.0), items=3, finite=True)
    velocity_timeout: float = param(1.0, gt=0)      # s without a command → decelerate to a stop

    rules = (Rule("max_velocity", lambda p: all(low <= high for low, high in zip(p.min_velocity, p.max_velocity)),
                  "at least min_velocity ({p.min_velocity}) on every axis"),)


def smooth_step(target, current, dt: float, params: VelocitySmootherParams) -> np.ndarray:
    """One step from `current` towards `target` (both (3,)) within the acceleration limits."""
    target = np.clip(np.asarray(target, float), params.min_velocity, params.max_velocity)
    current = np.asarray(current, float)
    speeding_up = (np.abs(target) >= np.abs(current)) & (target * current >= 0)
    step = np.where(speeding_up, np.asarray(params.max_accel), -np.asarray(params.max_decel)) * dt
    out = current + np.clip(target - current, -step, step)
    return np.where(np.abs(out) < np.asarray(params.deadband_velocity), 0.0, out)


@dataclass(frozen=True)
class SmootherOutput:
    twist: np.ndarray     # (3,) to send
    timed_out: bool       # no command within velocity_timeout: stopping


class VelocitySmoother:
    def __init__(self, params: VelocitySmootherParams):
        self.params = params
        self._target = np.zeros(3)
        self._last_command_ns: int | None = None
        self._output = np.zeros(3)

    def command(self, twist, stamp_ns: int) -> None:
        """A new command from the planner, stamped in sim time."""
        self._target = np.asarray(twist, float).copy()
        self._last_command_ns = int(stamp_ns)

    def step(self, stamp_ns: int) -> SmootherOutput:
        """The output at sim time stamp_ns (called every 1/smoothing_frequency seconds)."""
        p = self.params
        timed_out = (self._last_command_ns is None
                     or (stamp_ns - self._last_command_ns) * 1e-9 > p.velocity_timeout)
        target = np.zeros(3) if timed_out else self._target
        self._output = smooth_step(target, self._output, 1.0 / p.smoothing_frequency, p)
        return SmootherOutput(self._output.copy(), timed_out)
