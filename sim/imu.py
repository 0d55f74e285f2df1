"""The simulated IMU: a planar gyro and accelerometer that read the body's true motion (docs/sim.md).

The simulator gives, each step, the body's true mean twist over that step (vx, vy, wz in the body
frame). From two consecutive twists:
  - the yaw rate is wz;
  - the acceleration in the body frame is the change of the body-frame velocity plus the
    centripetal term ω × v (the frame turns under the velocity): ax = dvx/dt − wz·vy,
    ay = dvy/dt + wz·vx, at the two steps' mean. So a contact that changes the body's velocity
    shows in the step it happens, whatever the wheels say.
A reading averages its steps (update_rate: the nearest whole number of steps, at least one) and
adds a bias and white noise, as Kalibr's IMU noise model (and its parameter names) has it: white
noise of density σ is σ/√period on a reading; the bias starts at its given value and drifts as a
random walk of density σ_b, σ_b·√period per reading. The IMU sits at base_link's origin with its
axes along base_link's (a mount offset would add the lever arm's ω̇ × r − ω² r: not modelled).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..parameters.declare import Parameters, param

DEG = math.pi / 180.0
G = 9.80665                 # m/s^2 per g, as the datasheets count


@dataclass(frozen=True)
class ImuParams(Parameters):
    """A MEMS IMU of the Bosch BMI088 class (datasheet BST-BMI088-DS001: gyro rate noise density
    0.014 °/s/√Hz, accelerometer noise density 175 µg/√Hz). The datasheet gives no σ for the
    biases' drift nor the bias left after a driver's at-rest calibration: those are assumed."""
    frame_id: str = param("base_link", nonempty=True)
    update_rate: float = param(100.0, gt=0)                         # Hz; a step longer than 1/update_rate: every step
    gyroscope_noise_density: float = param(0.014 * DEG, ge=0)       # rad/s/√Hz
    gyroscope_random_walk: float = param(1e-5, ge=0)                # rad/s^2/√Hz, the bias's drift (assumed)
    gyroscope_bias: float = param(0.001, finite=True)               # rad/s at start (assumed)
    accelerometer_noise_density: float = param(175e-6 * G, ge=0)    # m/s^2/√Hz
    accelerometer_random_walk: float = param(1e-4, ge=0)            # m/s^3/√Hz, the bias's drift (assumed)
    accelerometer_bias: tuple[float, float] = param((0.02, -0.02), items=2, finite=True)  # m/s^2, x y at start (assumed)


@dataclass(frozen=True)
class ImuReading:
    angular_velocity_z: float       # rad/s
    linear_acceleration: np.ndarray  # (2,) m/s^2, body x, y, without gravity


def body_acceleration(previous: np.ndarray, current: np.ndarray, dt: float) -> np.ndarray:
    """The body-frame acceleration (ax, ay) between two consecutive steps' mean twists (vx, vy, wz):
    the change of the body-frame velocity plus ω × v, taken at the two steps' mean."""
    vx, vy, wz = (previous + current) / 2.0
    dvx, dvy = (current[:2] - previous[:2]) / dt
    return np.array([dvx - wz * vy, dvy + wz * vx])


class ImuModel:
    """Feed it every step's true mean twist; it answers a reading when one is due."""

    def __init__(self, params: ImuParams, dt: float, rng: np.random.Generator):
        self.params, self.dt, self.rng = params, dt, rng
        self.steps_per_reading = max(1, round(1.0 / (params.update_rate * dt)))
        period = self.steps_per_reading * dt
        self.gyro_std = params.gyroscope_noise_density / math.sqrt(period)
        self.accel_std = params.accelerometer_noise_density / math.sqrt(period)
        self._gyro_drift = params.gyroscope_random_walk * math.sqrt(period)
        self._accel_drift = params.accelerometer_random_walk * math.sqrt(period)
        self.gyro_bias = params.gyroscope_bias
        self.accel_bias = np.array(params.accelerometer_bias, np.float64)
        self._twist = np.zeros(3)       # the previous step's twist: the robot starts at rest
        self._sum = np.zeros(3)         # ax, ay, wz summed over the steps of the reading under way
        self._steps = 0

    def step(self, twist: np.ndarray) -> ImuReading | None:
        """Take one step's true mean body twist (vx, vy, wz); a reading at the end of its period."""
        twist = np.asarray(twist, np.float64)
        self._sum[:2] += body_acceleration(self._twist, twist, self.dt)
        self._sum[2] += twist[2]
        self._twist = twist
        self._steps += 1
        if self._steps < self.steps_per_reading:
            return None
        ax, ay, wz = self._sum / self._steps
        self._sum[:] = 0.0
        self._steps = 0
        noise = self.rng.standard_normal(6)    # one draw, fixed order: white gyro, x, y; drift gyro, x, y
        reading = ImuReading(angular_velocity_z=float(wz + self.gyro_bias + self.gyro_std * noise[0]),
                             linear_acceleration=np.array([ax, ay]) + self.accel_bias + self.accel_std * noise[1:3])
        self.gyro_bias += self._gyro_drift * float(noise[3])
        self.accel_bias = self.accel_bias + self._accel_drift * noise[4:6]
        return reading
