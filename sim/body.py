"""The robot as the simulator moves it: what it collides with, what it weighs, how its wheels
drive it over the floor (a robot profile's `body`, docs/sim.md).

This is the simulator's robot, never the navigation stack's: the planners and the collision
monitor are configured with their own footprint and limits (a profile's `footprint` and `params`)
and must not read these. The defaults are the ideal robot the simulator had before bodies were
data: the footprint it is given, 40 kg, wheels that carry the body wherever they turn, no
skid-steer slip and no roller slip.

The ground model, per axis of the body twist:
  - skid steer (a four-wheel differential drive turns by dragging its wheels sideways): the
    instantaneous centres of rotation of the two wheel sides lie `track_multiplier` × the track
    apart, so a wheel-speed difference turns the body 1/track_multiplier as fast as an ideal
    differential drive with that track would (the same multiplier the Jackal's
    diff_drive_controller is given, wheel_separation_multiplier 1.5);
  - rollers (mecanum, omni): the free rollers lose part of a sideways motion, vy × lateral_efficiency;
  - traction: the floor can change the body's velocity by at most traction_mu · g per second (and
    the yaw rate by the torque that friction at the wheels' contact points gives, over the body's
    moment of inertia); beyond that the wheels spin or skid and the encoders no longer tell the
    body's motion. traction_mu 0 means wheels that never lose the floor.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ..geometry.polygons import polygon_area
from ..parameters.declare import Parameters, Rule, param

GRAVITY = 9.81      # m/s^2


@dataclass(frozen=True)
class BodyParams(Parameters):
    """The simulated robot's body. `outline` is what the world collides with: one polygon in
    base_link, concave if need be (the chassis and its wheels). `wheels` are ChassisParams by name
    (wheel_radius, l1, l2, max_wheel_speed, ...): the real wheels, {} = the ones the chassis
    service assumes."""
    outline: tuple[tuple[float, float], ...] = param((), min_items=3, or_empty=True)  # m, base_link; () = the footprint
    mass: float = param(40.0, gt=0)                          # kg
    inertia: float = param(0.0, ge=0)                        # kg m^2 about z; 0 = a uniform plate of the shapes
    wheels: dict = field(default_factory=dict)               # ChassisParams by name: the real wheel geometry
    wheel_acc_limit: float = param(60.0, gt=0)               # rad/s^2, how fast a motor reaches its commanded speed
    contact_friction: float = param(0.3, ge=0)               # between the body and whatever it touches
    traction_mu: float = param(0.0, ge=0)                    # wheels on the floor; 0 = they never lose it
    track_multiplier: float = param(1.0, ge=1.0)             # skid steer (diff): ICR spread over the track
    lateral_efficiency: float = param(1.0, gt=0, le=1)       # rollers (mecanum, omni3): vy achieved / commanded

    rules = (Rule("outline", lambda p: not p.outline or abs(polygon_area(np.array(p.outline))) >= 1e-6,
                  "a polygon enclosing an area"),)

    def collision_outline(self, footprint: np.ndarray) -> np.ndarray:
        """The body's outline (P, 2), counter-clockwise; `footprint` when it has none."""
        outline = np.array(self.outline, np.float64) if self.outline else np.asarray(footprint, np.float64)
        return outline if polygon_area(outline) > 0 else outline[::-1].copy()


@dataclass(frozen=True)
class Ground:
    """How the floor carries a body twist the wheels ask for (see the module notes)."""
    twist_scale: np.ndarray         # (3,) the part of (vx, vy, wz) the floor delivers
    linear_accel: float             # m/s^2 the floor can give the body; inf = no limit
    yaw_accel: float                # rad/s^2

    @classmethod
    def of(cls, body: BodyParams, drive: str, wheel_reach: float, inertia: float) -> Ground:
        """The ground for a body on `drive` wheels whose contact points lie `wheel_reach` (m) from
        its centre on average, with this moment of inertia (kg m^2)."""
        scale = np.ones(3)
        if drive == "diff":
            scale[2] = 1.0 / body.track_multiplier
        else:
            scale[1] = body.lateral_efficiency
        if body.traction_mu == 0.0:
            return cls(scale, math.inf, math.inf)
        force = body.traction_mu * body.mass * GRAVITY
        return cls(scale, force / body.mass, force * wheel_reach / inertia)

    def carry(self, twist: np.ndarray, demand: np.ndarray, dt: float) -> np.ndarray:
        """The body twist after dt of the floor pulling `twist` towards the wheels' `demand`
        (both already scaled by twist_scale)."""
        if math.isinf(self.linear_accel):
            return demand
        change = demand - twist
        linear = math.hypot(change[0], change[1])
        reach = self.linear_accel * dt
        if linear > reach:
            change[:2] *= reach / linear
        change[2] = min(max(change[2], -self.yaw_accel * dt), self.yaw_accel * dt)
        return twist + change
