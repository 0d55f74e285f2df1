"""The world's people as bodies in the simulator's pymunk Space, walked by the social force model.

sim/people holds who walks where and what accelerates them; this module gives each slot of that
population a 70 kg body (the model's `mass`) while the person is in the world, so a person and the
robot push each other as their masses say — a person walking into the robot shoves it as a body
would, not as a wall — and people bump into walls, movers and each other by pymunk's contacts
(the model's own contact forces are switched off: pymunk resolves contacts, once).

Per simulator step `plan(t, robot)` moves the parties along their routes (spawns, waits, leaving:
Crowd.update); per substep `push(h, robot)` gives every body the velocity the model's acceleration
brings it to (capped at its speed limit), and after pymunk's solve `advance(h)` moves them by the
velocity the contacts left them and reads it back into the model's state.
"""
from __future__ import annotations

import dataclasses

import numpy as np
import pymunk

from .people.plans import Crowd, PeopleSpec
from .people.social_force import Obstacles, PeopleParams, RobotShape, accelerations, cap_speed

FAR = 1.0e6          # m: where an empty slot is said to be (radius 0), so arrays keep one row per slot


def hold(body: pymunk.Body, dt: float) -> None:
    """Position function that keeps a body where it is during space.step: pymunk would move it by
    the velocity we set before its solver saw the contacts (sim/physics.py)."""


class Walkers:
    """The people's bodies; `bodies[i]` is slot i's, in the Space while the slot is active."""

    def __init__(self, spec: PeopleSpec, space: pymunk.Space, obstacles: Obstacles, category: int,
                 params: PeopleParams = PeopleParams()):
        self.params = dataclasses.replace(params, body_stiffness=0.0, sliding_friction=0.0)
        self.crowd = Crowd(spec, self.params)
        self.space, self.obstacles = space, obstacles
        self.bodies, self.shapes = [], []
        for _ in range(len(self.crowd.state)):
            body = pymunk.Body(self.params.mass, float("inf"))
            body.position_func = hold
            shape = pymunk.Circle(body, 0.25)
            shape.friction = 1.0
            shape.filter = pymunk.ShapeFilter(categories=category)
            self.bodies.append(body)
            self.shapes.append(shape)
        self._in_space = np.zeros(len(self.bodies), bool)

    def __len__(self) -> int:
        return len(self.bodies)

    @property
    def state(self):
        return self.crowd.state

    def plan(self, t: float, robot: RobotShape) -> None:
        """Parties on along their routes at sim time t; bodies in and out of the Space as people come and go."""
        self.crowd.update(t, robot)
        active = self.state.active
        for i in np.flatnonzero(active & ~self._in_space):
            body, shape = self.bodies[i], self.shapes[i]
            body.position = tuple(self.state.position[i])
            body.velocity = tuple(self.state.velocity[i])
            shape.unsafe_set_radius(float(self.state.radius[i]))
            self.space.add(body, shape)
        for i in np.flatnonzero(~active & self._in_space):
            self.space.remove(self.bodies[i], self.shapes[i])
        self._in_space = active.copy()

    def push(self, h: float, robot: RobotShape) -> None:
        """Before a substep of h: each body gets the velocity the model accelerates it to."""
        s, active = self.state, np.flatnonzero(self._in_space)
        if not len(active):
            return
        a = accelerations(s, self.obstacles, robot, self.params)
        velocity = cap_speed(s.velocity[active] + a[active] * h, s.v0[active], self.params)
        for i, (vx, vy) in zip(active, velocity.tolist()):
            self.bodies[i].velocity = (vx, vy)

    def advance(self, h: float) -> None:
        """After the substep's solve: move the bodies, and tell the model where they are and how fast."""
        s = self.state
        for i in np.flatnonzero(self._in_space):
            body = self.bodies[i]
            pymunk.Body.update_position(body, h)
            s.position[i] = body.position
            s.velocity[i] = body.velocity

    def circles(self) -> np.ndarray:
        """The people in the world (M, 3): x, y, r."""
        s, active = self.state, self._in_space
        return np.column_stack([s.position[active], s.radius[active]]).reshape(-1, 3)

    def velocities(self) -> np.ndarray:
        return self.state.velocity[self._in_space].reshape(-1, 2)

    def slots(self) -> tuple[np.ndarray, np.ndarray]:
        """Every slot's position and velocity (N, 2), an empty slot FAR away and still."""
        s, empty = self.state, ~self._in_space
        position, velocity = s.position.copy(), s.velocity.copy()
        position[empty], velocity[empty] = FAR, 0.0
        return position, velocity
