"""Velocity smoother after Nav2's velocity_smoother (open loop): between the planner and the chassis,
run at smoothing_frequency in sim time.

Each step the latest command, clipped to [min_velocity, max_velocity], is approached per axis from
the last output: speeding up (same sign, larger magnitude) by at most max_accel·dt, anything else
(slowing down, reversing) by at most |max_decel|·dt, as Nav2 does. An output component within the
deadband becomes 0. No command for velocity_timeout seconds (sim time) makes the target zero, so
the robot stops at the deceleration limits rather than at once.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..runtime.params import require_positive


@dataclass(frozen=True)
class VelocitySmootherParams:
    """Nav2 velocity_smoother's names and defaults; axes are (vx, vy, wz)."""
    smoothing_frequency: float = 20.0                   # Hz
    # what the chassis allows on every axis: Nav2's defaults are a differential drive's (vy 0), which
    # would stop a mecanum robot strafing
    max_velocity: tuple[float, float, float] = (0.5, 0.5, 2.5)
    min_velocity: tuple[float, float, float] = (-0.5, -0.5, -2.5)
    max_accel: tuple[float, float, float] = (2.5, 2.5, 3.2)
    max_decel: tuple[float, float, float] = (-2.5, -2.5, -3.2)
    deadband_velocity: tuple[float, float, float] = (0.0, 0.0, 0.0)
    velocity_timeout: float = 1.0                       # s without a command → decelerate to a stop

    def __post_init__(self):
        require_positive(self, "smoothing_frequency", "velocity_timeout")
        for name in ("max_velocity", "min_velocity", "max_accel", "max_decel", "deadband_velocity"):
            value = getattr(self, name)
            if len(value) != 3 or not all(math.isfinite(v) for v in value):
                raise ValueError(f"{name} must be three finite numbers [vx, vy, wz], got {value}")
        for i in range(3):
            if self.min_velocity[i] > self.max_velocity[i]:
                raise ValueError(f"min_velocity {self.min_velocity} exceeds max_velocity {self.max_velocity}")
            if self.max_accel[i] < 0 or self.max_decel[i] > 0:
                raise ValueError("max_accel must be ≥ 0 and max_decel ≤ 0 on every axis "
                                 f"(got {self.max_accel}, {self.max_decel})")


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
