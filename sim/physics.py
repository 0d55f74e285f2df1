"""The simulator's physics: a robot driven by its wheels through a pymunk world, and its sensors.

One `Simulation` holds a pymunk Space with the world's static geometry (walls, boxes, circles and,
for a map world, its occupied cells merged into rectangles), the movers as kinematic bodies that
follow their paths in `world.movers`, and the robot as a dynamic body with the footprint polygon.
Each mover's state is how long it has moved: a step adds dt unless it yields to the robot (a mover
with a yield distance whose way ahead the footprint is in, decided at the step's start).

A step of dt, in this order:
  1. motors: each wheel approaches its commanded speed, at most `wheel_acc_limit` rad/s^2, and
     holds the result over the step (zero-order hold, like a motor controller's speed loop);
  2. slip: the ground sees every wheel's speed times (1 + N(0, wheel_slip_std)); forward kinematics
     of those speeds is the twist the body is driven with;
  3. contacts: the body is given the velocity that moves it along that twist's exact arc
     (se2_exp) and pymunk resolves it against everything the robot touches, so walls stop it and
     movers push it — it never drives through an obstacle;
  4. sensors: encoders integrate the wheel speeds (not the body motion: that difference is the
     slip), plus a per-step random walk, quantised to ticks; the gyro reports the mean true yaw
     rate over the step plus bias and noise; the follower wheels roll with the true body motion
     (follower_readings) and are read like the encoders.

Why the robot's position is integrated after the solve: pymunk moves bodies first and resolves
contacts afterwards, which would let a velocity we set drive the robot into a wall before the
solver sees it. The robot (and the movers) therefore keep a no-op position function during
`space.step`; the solver resolves the commanded velocity against the contacts where the robot
stands, and only then is the position advanced (pymunk's own update, including its penetration
correction). So a command acts in the very step it is applied, and with no contact and no noise
the true motion is exactly what wheel odometry integrates.

Collisions: a collision is the robot starting to touch an object it did not touch (the static
world counts as one object, each mover as one). It is the robot's fault when its contact point
moved towards what it touched faster than `fault_speed` (by the velocity commanded for that step),
and when it touched static geometry without being in a mover's contact; otherwise a mover drove
into a robot standing or leaving, or shoved it into a wall.

Deterministic: everything random comes from the one Generator, drawn in a fixed order per step.
"""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np
import pymunk
from pymunk.autogeometry import convex_decomposition

from ..services.chassis.follower_wheels import follower_readings
from ..services.chassis.kinematics import DRIVES, ChassisParams, Kinematics
from ..geometry.grid import cell_to_world
from ..geometry.se2 import relative, se2_exp, wrap_angle
from .world import World
from ..geometry.polygons import polygon_area, transform_points
from ..parameters.declare import Parameters, Rule, param

ROBOT_MASS = 40.0            # kg; with pymunk's moment it only decides how a contact splits turn and push
CONTACT_SLOP = 1e-3          # m of overlap pymunk tolerates before pushing bodies apart
CLEARANCE_BATCH = 64         # poses the gate let through that wait to have their clearance computed together
_ROBOT, _STATIC, _MOVERS = 1, 2, 4   # shape categories: clearance queries look at obstacles only
STATIC = -1                          # what a contact touched when it is no mover


@dataclass(frozen=True)
class SimParams(Parameters):
    """The simulator's step and its models of motors, slip and sensors.

    Noise defaults are modest, for a well-built indoor robot: 2 % per-wheel speed error each step
    (slip), encoders with 4096 ticks per revolution and a 0.5 mrad per-step random walk, a MEMS-class
    gyro (2 mrad/s noise on each step's mean rate, 1 mrad/s bias). `without_noise()` switches all off.
    """
    dt: float = param(0.01, ge=1e-4, le=0.1)        # s, fixed step
    drive: str = param("", choices=("",) + DRIVES)  # "" = the world's robot.drive; else mecanum | omni3 | diff
    wheel_slip_std: float = param(0.02, ge=0)       # relative per-wheel speed error, drawn each step
    encoder_noise_std: float = param(0.0005, ge=0)  # rad per step, random walk of each encoder (wheels, followers)
    encoder_ticks_per_rev: int = param(4096, ge=0)  # quantisation of every encoder; 0 = none
    gyro_noise_std: float = param(0.002, ge=0)      # rad/s, noise on each step's mean yaw rate
    gyro_bias: float = param(0.001, finite=True)    # rad/s
    # above what any one wheel needs for the chassis's default per-axis acceleration limits
    # (2.5 m/s^2 → 33 rad/s^2, 3.2 rad/s^2 → 23 rad/s^2), so limited commands are tracked
    wheel_acc_limit: float = param(60.0, gt=0)      # rad/s^2, motor response
    contact_friction: float = param(0.3, ge=0)      # friction between the robot and whatever it touches
    # a contact is the robot's fault when its contact point moved towards what it touched faster
    # than this (a static contact also when no mover touched the robot); slower, a mover drove into
    # a robot standing or leaving, or shoved it into the wall
    fault_speed: float = param(0.02, ge=0)          # m/s
    seed: int = param(0, ge=0)

    rules = (Rule("dt", lambda p: abs(p.dt * 1e9 - round(p.dt * 1e9)) <= 1e-3, "a whole number of nanoseconds"),)

    def without_noise(self) -> SimParams:
        """The same simulator with exact wheels and sensors."""
        return dataclasses.replace(self, wheel_slip_std=0.0, encoder_noise_std=0.0, encoder_ticks_per_rev=0,
                                   gyro_noise_std=0.0, gyro_bias=0.0)


@dataclass(frozen=True)
class Readings:
    """One step's outputs: what the robot's sensors report, and the truth they came from."""
    time: float                     # s, sim time at the end of the step
    encoder_positions: np.ndarray   # (n_wheels,) rad, cumulative, as the encoders report them
    wheel_speeds: np.ndarray        # (n_wheels,) rad/s, the motors' speeds over the step
    follower_positions: np.ndarray  # (2,) follower encoders A, B (rad), cumulative
    gyro_z: float                   # rad/s, mean yaw rate over the step as the gyro reports it
    pose: np.ndarray                # (3,) true x, y, theta in the world frame
    twist: np.ndarray               # (3,) true mean body twist over the step (vx, vy, wz)
    mover_circles: np.ndarray       # (K, 3) x, y, r at `time`
    mover_velocities: np.ndarray    # (K, 2) world frame, mean over the step (what the contacts used)
    in_contact: bool                # the robot touched something during the step


def _sin_over(x: float) -> float:
    """sin(x)/x for one number (np.sinc costs more than the rest of se2_log on a scalar)."""
    return math.sin(x) / x if x != 0.0 else 1.0


def se2_log(increment) -> np.ndarray:
    """The motion (vx*dt, vy*dt, wz*dt) whose exact arc is the pose increment: se2_exp inverted."""
    x, y, phi = (float(v) for v in increment)
    along = _sin_over(phi)
    across = math.sin(phi / 2) * _sin_over(phi / 2)
    norm = along * along + across * across
    return np.array([(along * x + across * y) / norm, (along * y - across * x) / norm, phi])


def occupied_rectangles(occupied: np.ndarray) -> np.ndarray:
    """Cover the True cells of a grid with few rectangles: runs along each row, then identical runs
    of consecutive rows merged. Returns (R, 4) row0, row1, col0, col1 (ends exclusive)."""
    height = occupied.shape[0]
    rects, open_runs = [], {}          # (col0, col1) -> first row of the rectangle growing there
    for row in range(height + 1):
        runs = set()
        if row < height:
            edges = np.flatnonzero(np.diff(np.concatenate([[0], occupied[row].astype(np.int8), [0]])))
            runs = set(zip(edges[0::2].tolist(), edges[1::2].tolist()))
        for run in sorted(open_runs.keys() - runs):
            rects.append((open_runs.pop(run), row, *run))
        for run in sorted(runs - open_runs.keys()):
            open_runs[run] = row
    return np.array(rects, dtype=np.int64).reshape(-1, 4)


def _convex_parts(polygon: np.ndarray) -> list[np.ndarray]:
    """pymunk collides convex polygons only: a concave footprint is split into convex pieces."""
    edges = np.roll(polygon, -1, axis=0) - polygon
    turns = edges[:, 0] * np.roll(edges[:, 1], -1) - edges[:, 1] * np.roll(edges[:, 0], -1)
    if np.all(turns >= -1e-12) or np.all(turns <= 1e-12):
        return [polygon]
    closed = [tuple(p) for p in polygon] + [tuple(polygon[0])]
    return [np.array([tuple(v) for v in part[:-1]]) for part in convex_decomposition(closed, 0.0)]


def _hold(body: pymunk.Body, dt: float) -> None:
    """Position function that keeps a body where it is during space.step (see the module notes)."""


class Simulation:
    """The robot in its world; `set_wheel_command`, then `step()` once per dt."""

    def __init__(self, world: World, params: SimParams = SimParams(),
                 chassis_params: ChassisParams = ChassisParams(), rng: np.random.Generator | None = None):
        self.world, self.params = world, params
        self.drive = params.drive or world.robot.drive
        self.chassis = dataclasses.replace(chassis_params, drive=self.drive)
        self.kinematics = Kinematics(self.chassis)
        self.rng = rng if rng is not None else np.random.default_rng(params.seed)
        n = self.kinematics.n_wheels
        self.command = np.zeros(n)
        self.wheel_speeds = np.zeros(n)
        self._encoders = np.zeros(n)          # true angle plus the encoders' random walk
        self._followers = np.zeros(2)
        self._tick = 2 * math.pi / params.encoder_ticks_per_rev if params.encoder_ticks_per_rev else 0.0
        self.steps = 0
        self.robot_fault_collisions = 0       # contacts begun while the robot moved towards what it hit
        self.mover_fault_collisions = 0       # a mover drove into a robot standing still or moving away
        self.shoved_collisions = 0            # of those, static contacts while a mover shoved the robot
        self.contact_steps = 0                # steps in which it touched something
        self.clearance_queries = 0            # poses whose exact clearance was computed
        self._touching: dict[int, int] = {}   # object touched (STATIC or mover index) -> robot shapes on it

        self.space = pymunk.Space()
        self.space.collision_slop = CONTACT_SLOP
        self._mover_of_shape: dict[pymunk.Shape, int] = {}
        self._add_static_geometry()
        self._movers = self._add_movers()
        self._mover_steps = np.zeros(len(world.movers), np.int64)   # steps each mover has moved
        self._mover_xy = world.movers.pose_after(0.0)
        self.robot = self._add_robot()
        self.space.on_collision(_ROBOT, None, begin=self._on_begin, separate=self._on_separate)

        self._probe_body = pymunk.Body(body_type=pymunk.Body.KINEMATIC)   # never added to the space
        self._probes = [pymunk.Poly(self._probe_body, [tuple(p) for p in part]) for part in self._parts]
        for probe in self._probes:
            probe.filter = pymunk.ShapeFilter(categories=_ROBOT, mask=_STATIC | _MOVERS)
        self._min_clearance = float(world.footprint_clearance(self.pose, self.mover_circles))
        self._waiting_poses: list[np.ndarray] = []      # poses the gate let through, not yet computed
        self._waiting_movers = np.zeros((0, 3))         # the mover circles at those poses

    # ------------------------------------------------------------ building the space

    def _static_shape(self, shape: pymunk.Shape) -> None:
        shape.friction = 1.0    # pymunk multiplies frictions: the robot's contact_friction decides
        shape.filter = pymunk.ShapeFilter(categories=_STATIC)
        self.space.add(shape)

    def _add_static_geometry(self) -> None:
        body = self.space.static_body
        for quad in self.world.solids:
            self._static_shape(pymunk.Poly(body, [tuple(p) for p in quad]))
        for x, y, r in self.world.circles:
            self._static_shape(pymunk.Circle(body, float(r), (float(x), float(y))))
        if self.world.grid is not None:
            info = self.world.grid.info
            for row0, row1, col0, col1 in occupied_rectangles(self.world.grid_occupied):
                xs, ys = cell_to_world(info, np.array([row0, row0, row1, row1]) - 0.5,
                                       np.array([col0, col1, col1, col0]) - 0.5)
                self._static_shape(pymunk.Poly(body, list(zip(xs.tolist(), ys.tolist()))))

    def _add_movers(self) -> list[pymunk.Body]:
        bodies = []
        for k, (radius, (x, y)) in enumerate(zip(self.world.movers.radius, self.world.movers.pose_after(0.0))):
            body = pymunk.Body(body_type=pymunk.Body.KINEMATIC)
            body.position = (float(x), float(y))
            body.position_func = _hold
            shape = pymunk.Circle(body, float(radius))
            shape.friction = 1.0
            shape.filter = pymunk.ShapeFilter(categories=_MOVERS)
            self._mover_of_shape[shape] = k
            self.space.add(body, shape)
            bodies.append(body)
        return bodies

    def _add_robot(self) -> pymunk.Body:
        footprint = self.world.robot.footprint
        self._parts = [part for part in _convex_parts(footprint) if abs(polygon_area(part)) > 1e-12]
        body = pymunk.Body(ROBOT_MASS, pymunk.moment_for_poly(ROBOT_MASS, [tuple(p) for p in footprint]))
        x, y, yaw = (float(v) for v in self.world.robot.start)
        body.position, body.angle = (x, y), yaw
        body.position_func = _hold
        self.space.add(body)
        for part in self._parts:
            shape = pymunk.Poly(body, [tuple(p) for p in part])
            shape.friction = self.params.contact_friction
            shape.collision_type = _ROBOT
            shape.filter = pymunk.ShapeFilter(categories=_ROBOT)
            self.space.add(shape)
        return body

    def _touched(self, arbiter: pymunk.Arbiter) -> int:
        """What the robot's shape touches: a mover's index, or STATIC for all static geometry (one
        object, so sliding along a wall built of several map boxes is one collision)."""
        return self._mover_of_shape.get(arbiter.shapes[1], STATIC)

    def _on_begin(self, arbiter: pymunk.Arbiter, space: pymunk.Space, data) -> None:
        touched = self._touched(arbiter)
        if self._touching.get(touched, 0) == 0:
            shoved = touched == STATIC and any(n for k, n in self._touching.items() if k != STATIC)
            own = self._robot_approach_speed(arbiter) > self.params.fault_speed
            if own or (touched == STATIC and not shoved):
                self.robot_fault_collisions += 1
            else:
                self.mover_fault_collisions += 1
                self.shoved_collisions += shoved
        self._touching[touched] = self._touching.get(touched, 0) + 1

    def _on_separate(self, arbiter: pymunk.Arbiter, space: pymunk.Space, data) -> None:
        touched = self._touched(arbiter)
        self._touching[touched] = max(0, self._touching.get(touched, 0) - 1)

    def _robot_approach_speed(self, arbiter: pymunk.Arbiter) -> float:
        """How fast the robot's contact point moves along the contact normal towards what it touches
        (m/s; negative: away), from the velocity it was commanded for this step, turning included."""
        contact = arbiter.contact_point_set
        normal = contact.normal             # from the robot's shape (shapes[0]) to the other one
        point = contact.points[0].point_a if contact.points else self.robot.position
        velocity = self.robot.velocity_at_world_point(point)
        return float(velocity.x * normal.x + velocity.y * normal.y)

    # ------------------------------------------------------------ state

    @property
    def collisions(self) -> int:
        """Times the robot started touching an object (the static world, or a mover) it did not touch."""
        return self.robot_fault_collisions + self.mover_fault_collisions

    @property
    def time(self) -> float:
        return self.steps * self.params.dt

    @property
    def pose(self) -> np.ndarray:
        """The robot's true pose (x, y, theta) in the world frame, theta in [-pi, pi)."""
        (x, y), angle = self.robot.position, self.robot.angle
        return np.array([x, y, float(wrap_angle(angle))])

    @property
    def footprint_outline(self) -> np.ndarray:
        """The robot's footprint polygon (P, 2) at its true pose, in the world frame."""
        return transform_points(self.world.robot.footprint, self.pose)[0]

    @property
    def mover_circles(self) -> np.ndarray:
        return np.column_stack([self._mover_xy, self.world.movers.radius]).reshape(-1, 3)

    def set_wheel_command(self, wheel_speeds) -> None:
        """Hold these wheel speeds (rad/s, in Kinematics.wheel_names order) until the next command."""
        speeds = np.asarray(wheel_speeds, dtype=float)
        if speeds.shape != self.command.shape:
            raise ValueError(f"a {self.drive} robot has {self.command.size} wheels, got {speeds.shape} speeds")
        if not np.all(np.isfinite(speeds)):
            raise ValueError("wheel speeds must be finite")
        self.command = speeds.copy()

    def teleport(self, pose) -> None:
        """Put the robot at a pose without turning its wheels (a kidnapped robot): encoders,
        followers and the gyro do not see the jump."""
        x, y, yaw = (float(v) for v in pose)
        self.robot.position, self.robot.angle = (x, y), yaw
        self.robot.velocity, self.robot.angular_velocity = (0.0, 0.0), 0.0
        self.space.reindex_shapes_for_body(self.robot)
        self._update_clearance(force=True)

    # ------------------------------------------------------------ stepping

    def step(self) -> Readings:
        p, dt = self.params, self.params.dt
        n = self.command.size
        noise = self.rng.standard_normal(2 * n + 3)   # one draw, fixed order: slip, encoders, followers, gyro

        limit = self.chassis.max_wheel_speed
        change = np.clip(self.command - self.wheel_speeds, -p.wheel_acc_limit * dt, p.wheel_acc_limit * dt)
        self.wheel_speeds = np.clip(self.wheel_speeds + change, -limit, limit)
        ground = self.wheel_speeds * (1.0 + p.wheel_slip_std * noise[:n])
        twist = self.kinematics.fk(ground)

        before = (*self.robot.position, self.robot.angle)
        chord = se2_exp(twist * dt)                     # body frame, the exact arc's end point
        c, s = math.cos(before[2]), math.sin(before[2])
        self.robot.velocity = ((c * chord[0] - s * chord[1]) / dt, (s * chord[0] + c * chord[1]) / dt)
        self.robot.angular_velocity = float(twist[2])
        # movers stay where they are during space.step; the solver sees their velocity
        next_xy = self._mover_xy
        if self._movers:
            yielding = self.world.movers.yielding(self._mover_steps * dt, self.footprint_outline)
            self._mover_steps += ~yielding
            next_xy = self.world.movers.pose_after(self._mover_steps * dt)
        for body, xy, xy_next in zip(self._movers, self._mover_xy, next_xy):
            body.velocity = (float(xy_next[0] - xy[0]) / dt, float(xy_next[1] - xy[1]) / dt)

        self.space.step(dt)
        pymunk.Body.update_position(self.robot, dt)
        self.steps += 1
        for body, xy in zip(self._movers, next_xy):
            body.position = (float(xy[0]), float(xy[1]))
            self.space.reindex_shapes_for_body(body)
        mover_velocities = (next_xy - self._mover_xy) / dt
        self._mover_xy = next_xy
        in_contact = any(self._touching.values())   # begin/separate ran in this step's collision detection
        self.contact_steps += in_contact

        after = (*self.robot.position, self.robot.angle)
        motion = se2_log(relative(before, after))
        self._encoders += self.wheel_speeds * dt + p.encoder_noise_std * noise[n:2 * n]
        self._followers += follower_readings(self.chassis, motion) + p.encoder_noise_std * noise[2 * n:2 * n + 2]
        gyro_z = (after[2] - before[2]) / dt + p.gyro_bias + p.gyro_noise_std * noise[-1]
        self._update_clearance()
        return Readings(time=self.time, encoder_positions=self._quantise(self._encoders),
                        wheel_speeds=self.wheel_speeds.copy(), follower_positions=self._quantise(self._followers),
                        gyro_z=float(gyro_z), pose=self.pose, twist=motion / dt,
                        mover_circles=self.mover_circles, mover_velocities=mover_velocities,
                        in_contact=bool(in_contact))

    def _quantise(self, angles: np.ndarray) -> np.ndarray:
        return np.round(angles / self._tick) * self._tick if self._tick else angles.copy()

    @property
    def min_clearance(self) -> float:
        """The smallest distance between the footprint and an obstacle or a mover over every step."""
        self._compute_waiting_clearances()
        return self._min_clearance

    def _update_clearance(self, force: bool = False) -> None:
        """Lower the minimum clearance if the footprint came closer than ever to an obstacle.

        The exact query (World.footprint_clearance) costs about a millisecond, so a pose only goes
        to it when pymunk says it can give a new minimum: the footprint grown by the minimum known
        so far (a rounded polygon) overlaps an obstacle or a mover. World's clearance is never below
        the true one, so this gate cannot hide a new minimum, for map cells too; the minimum known
        may be above the true one while poses wait, which only lets more poses through. The
        waiting poses are computed together (one vectorised query costs about a tenth per pose of
        single ones) once CLEARANCE_BATCH wait, the movers moved, or min_clearance is read.
        """
        if self._min_clearance <= 0.0 and not force:
            return
        if not force:
            self._probe_body.position, self._probe_body.angle = self.robot.position, self.robot.angle
            for probe in self._probes:
                probe.unsafe_set_radius(self._min_clearance)
            if not any(self.space.shape_query(probe) for probe in self._probes):
                return
        movers = self.mover_circles
        if self._waiting_poses and not np.array_equal(movers, self._waiting_movers):
            self._compute_waiting_clearances()
        self._waiting_poses.append(self.pose)
        self._waiting_movers = movers
        if len(self._waiting_poses) >= CLEARANCE_BATCH:
            self._compute_waiting_clearances()

    def _compute_waiting_clearances(self) -> None:
        if not self._waiting_poses:
            return
        self.clearance_queries += len(self._waiting_poses)
        clearance = self.world.footprint_clearance(np.array(self._waiting_poses), self._waiting_movers)
        self._min_clearance = min(self._min_clearance, float(clearance.min()))
        self._waiting_poses.clear()
