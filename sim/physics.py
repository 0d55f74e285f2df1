"""The simulator's physics: a robot driven by its wheels through a pymunk world, and its sensors.

One `Simulation` holds a pymunk Space with the world's static geometry (walls, boxes, circles and,
for a map world, its occupied cells merged into rectangles), the movers as kinematic bodies that
follow their paths in `world.movers`, and the robot as a dynamic body of its `BodyParams`
(sim/body.py: its collision shapes, mass, wheels, motors and how the floor carries it).
Each mover's state is how long it has moved: a step adds dt unless it yields to the robot (a mover
with a yield distance whose way ahead the footprint is in, decided at the step's start).

A step of dt, in this order:
  1. motors: each wheel approaches its commanded speed, at most the body's `wheel_acc_limit`
     rad/s^2, and holds the result over the step (zero-order hold, like a motor controller's
     speed loop);
  2. slip: the ground sees every wheel's speed times (1 + N(0, wheel_slip_std)); forward kinematics
     of those speeds, scaled as the floor carries it (skid steer, rollers: body.py's Ground), is
     the twist the wheels drive the body with;
  3. contacts, in substeps of at most `max_substep` (2 ms by default: at 2 m/s a graze of 2 mm
     lasts several substeps, where one 20 ms step could jump over it): the body is given the
     velocity that moves it along its twist's exact arc (se2_exp) — the wheels' twist, or with a
     traction limit the twist the floor has brought it to — and pymunk resolves it against
     everything the robot touches, so walls stop it and movers push it; every substep of every
     contact is judged and timed (sim/contacts.py);
  4. sensors: encoders integrate the wheel speeds (not the body motion: that difference is the
     slip), plus a per-step random walk, quantised to ticks; the gyro reports the mean true yaw
     rate over the step plus bias and noise; the follower wheels roll with the true body motion
     (follower_readings) and are read like the encoders.

Why the robot's position is integrated after the solve: pymunk moves bodies first and resolves
contacts afterwards, which would let a velocity we set drive the robot into a wall before the
solver sees it. The robot (and the movers) therefore keep a no-op position function during
`space.step`; the solver resolves the commanded velocity against the contacts where the robot
stands, and only then is the position advanced (pymunk's own update, including its penetration
correction). So a command acts in the very substep it is applied, and with no contact, no noise
and an ideal body the true motion is exactly what wheel odometry integrates.

Contacts: every substep in which the robot touches an object is the robot's when its contact
point moved towards it faster than `fault_speed` (any speed above rounding: the wheels' twist,
turning included, not whatever a push gave the body), or when the object is a mover the robot
could have seen coming `foresight_s` before the contact began (its position and velocity then,
extrapolated, reach the robot where it stands) and the robot did not move away from it;
otherwise the substep is the mover's (it drove into a robot standing or leaving, or shoved it
into a wall). ContactLedger adds them up.

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
from ..geometry.polygons import point_segment_distance, points_in_polygons, polygon_area, transform_points
from ..geometry.se2 import relative, se2_exp, wrap_angle
from ..parameters.declare import Parameters, Rule, param
from ..parameters.from_mapping import load_params
from .body import BodyParams, Ground
from .contacts import STATIC, ContactLedger, MoverHistory
from .people.social_force import Obstacles, RobotShape
from .walkers import Walkers, hold
from .world import World

CONTACT_SLOP = 1e-3          # m of overlap pymunk tolerates before pushing bodies apart
CLEARANCE_BATCH = 64         # poses the gate let through that wait to have their clearance computed together
_ROBOT, _STATIC, _MOVERS = 1, 2, 4   # shape categories: clearance queries look at obstacles only


@dataclass(frozen=True)
class SimParams(Parameters):
    """The simulator's step, its sensors' noise and how contacts are judged (the robot's body:
    BodyParams, sim/body.py).

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
    # contacts are looked for at least this often: Gazebo's BARN steps at 1 ms, and at 2 m/s a
    # corner grazing a 0.075 m cylinder by 2 mm touches it for about 17 ms
    max_substep: float = param(0.002, gt=0)         # s
    # a contact substep is the robot's when its contact point moved towards what it touched faster
    # than this: any speed above rounding (a wheel standing still gives exactly 0)
    fault_speed: float = param(0.001, ge=0)         # m/s
    # ... or when it stayed in the way of a mover it could have seen coming this long before
    foresight_s: float = param(1.0, ge=0)           # s; 0 = never
    seed: int = param(0, ge=0)

    rules = (Rule("dt", lambda p: abs(p.dt * 1e9 - round(p.dt * 1e9)) <= 1e-3, "a whole number of nanoseconds"),)

    def without_noise(self) -> SimParams:
        """The same simulator with exact wheels and sensors."""
        return dataclasses.replace(self, wheel_slip_std=0.0, encoder_noise_std=0.0, encoder_ticks_per_rev=0,
                                   gyro_noise_std=0.0, gyro_bias=0.0)

    @property
    def substeps(self) -> int:
        """Physics substeps per step: the fewest that keep each within max_substep."""
        return max(1, math.ceil(self.dt / self.max_substep - 1e-9))


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


class Simulation:
    """The robot in its world; `set_wheel_command`, then `step()` once per dt."""

    def __init__(self, world: World, params: SimParams = SimParams(),
                 chassis_params: ChassisParams = ChassisParams(), rng: np.random.Generator | None = None,
                 body: BodyParams = BodyParams()):
        if body.outline:
            world = dataclasses.replace(world, robot=dataclasses.replace(
                world.robot, footprint=body.collision_outline(world.robot.footprint)))
        self.world, self.params, self.body = world, params, body
        self.drive = params.drive or world.robot.drive
        self.chassis = load_params(ChassisParams, {**dataclasses.asdict(chassis_params), **body.wheels,
                                                   "drive": self.drive}, "body.wheels")
        self.kinematics = Kinematics(self.chassis)
        self.rng = rng if rng is not None else np.random.default_rng(params.seed)
        n = self.kinematics.n_wheels
        self.command = np.zeros(n)
        self.wheel_speeds = np.zeros(n)
        self._encoders = np.zeros(n)          # true angle plus the encoders' random walk
        self._followers = np.zeros(2)
        self._tick = 2 * math.pi / params.encoder_ticks_per_rev if params.encoder_ticks_per_rev else 0.0
        self.steps = 0
        self.substeps = params.substeps
        self._now_s = 0.0                     # sim time at the start of the substep being stepped
        self.contacts = ContactLedger()
        self.contact_steps = 0                # steps in which it touched something
        self.clearance_queries = 0            # poses whose exact clearance was computed
        self._touching: dict[int, int] = {}   # object touched (STATIC or mover index) -> robot shapes on it
        self._shares: dict[int, bool] = {}    # this substep: object touched -> whether the substep was the robot's
        self._demand = np.zeros(3)            # the twist the wheels drive the body with this step
        self._twist = np.zeros(3)             # the body's twist (body frame) where the floor has brought it

        self.space = pymunk.Space()
        self.space.collision_slop = CONTACT_SLOP
        self._mover_of_shape: dict[pymunk.Shape, int] = {}
        self._add_static_geometry()
        self._movers = self._add_movers()
        self._mover_steps = np.zeros(len(world.movers), np.int64)   # steps each mover has moved
        self._mover_xy = world.movers.pose_after(0.0)
        self.robot = self._add_robot()
        self.walkers = Walkers(world.people, self.space, Obstacles(world.segments, world.circles), _MOVERS)
        for slot, shape in enumerate(self.walkers.shapes):          # people are movers after the world's movers
            self._mover_of_shape[shape] = len(world.movers) + slot
        self._mover_history = MoverHistory(max(1, round(params.foresight_s / params.dt)),
                                           len(world.movers) + len(self.walkers))
        self.ground = Ground.of(body, self.drive, self._wheel_reach(), self.robot.moment)
        self.space.on_collision(_ROBOT, None, begin=self._on_begin, pre_solve=self._on_touch,
                                separate=self._on_separate)

        self._probe_body = pymunk.Body(body_type=pymunk.Body.KINEMATIC)   # never added to the space
        self._probes = [pymunk.Poly(self._probe_body, [tuple(p) for p in part]) for part in self._parts]
        for probe in self._probes:
            probe.filter = pymunk.ShapeFilter(categories=_ROBOT, mask=_STATIC | _MOVERS)
        self._min_clearance = float(world.footprint_clearance(self.pose, self.mover_circles))
        self._waiting_poses: list[np.ndarray] = []      # poses the gate let through, not yet computed
        self._waiting_movers = np.zeros((0, 3))         # the mover circles at those poses

    # ------------------------------------------------------------ building the space

    def _static_shape(self, shape: pymunk.Shape) -> None:
        shape.friction = 1.0    # pymunk multiplies frictions: the body's contact_friction decides
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
            body.position_func = hold
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
        mass = self.body.mass
        body = pymunk.Body(mass, self.body.inertia or pymunk.moment_for_poly(mass, [tuple(p) for p in footprint]))
        x, y, yaw = (float(v) for v in self.world.robot.start)
        body.position, body.angle = (x, y), yaw
        body.position_func = hold
        self.space.add(body)
        for part in self._parts:
            shape = pymunk.Poly(body, [tuple(p) for p in part])
            shape.friction = self.body.contact_friction
            shape.collision_type = _ROBOT
            shape.filter = pymunk.ShapeFilter(categories=_ROBOT)
            self.space.add(shape)
        return body

    def _wheel_reach(self) -> float:
        """Mean distance (m) of the wheels' contact points from the body's centre."""
        c = self.chassis
        if self.drive == "omni3":
            return c.omni_wheel_distance
        return math.hypot(c.l1, c.l2) if self.drive == "mecanum" else c.l2

    # ------------------------------------------------------------ contacts

    def _touched(self, arbiter: pymunk.Arbiter) -> int:
        """What the robot's shape touches: a mover's index, or STATIC for all static geometry (one
        object, so sliding along a wall built of several map boxes is one contact)."""
        return self._mover_of_shape.get(arbiter.shapes[1], STATIC)

    def _on_begin(self, arbiter: pymunk.Arbiter, space: pymunk.Space, data) -> None:
        touched = self._touched(arbiter)
        if self._touching.get(touched, 0) == 0:
            foreseen = touched != STATIC and self._foreseen(touched)
            self.contacts.begin(touched, self._now_s, foreseen=foreseen)
        self._touching[touched] = self._touching.get(touched, 0) + 1

    def _on_touch(self, arbiter: pymunk.Arbiter, space: pymunk.Space, data) -> None:
        """Every substep of every touching pair: whose substep it is (see the module notes)."""
        touched = self._touched(arbiter)
        approach = self._robot_approach_speed(arbiter)
        own = approach > self.params.fault_speed
        contact = self.contacts.open.get(touched)
        if contact is not None and contact.foreseen:
            own = own or approach >= -self.params.fault_speed        # stayed in the way it saw coming
        self._shares[touched] = self._shares.get(touched, False) or own

    def _on_separate(self, arbiter: pymunk.Arbiter, space: pymunk.Space, data) -> None:
        touched = self._touched(arbiter)
        self._touching[touched] = max(0, self._touching.get(touched, 0) - 1)
        if self._touching[touched] == 0:
            self.contacts.end(touched, self._now_s)

    def _robot_approach_speed(self, arbiter: pymunk.Arbiter) -> float:
        """How fast the wheels move the robot's contact point along the contact normal towards
        what it touches (m/s; negative: away), turning included — not the body's velocity, which
        holds whatever a push gave it."""
        contact = arbiter.contact_point_set
        normal = contact.normal             # from the robot's shape (shapes[0]) to the other one
        point = contact.points[0].point_a if contact.points else self.robot.position
        vx, vy, wz = self._demand
        c, s = math.cos(self.robot.angle), math.sin(self.robot.angle)
        rx, ry = point.x - self.robot.position.x, point.y - self.robot.position.y
        velocity = (c * vx - s * vy - wz * ry, s * vx + c * vy + wz * rx)
        return float(velocity[0] * normal.x + velocity[1] * normal.y)

    def _foreseen(self, mover: int) -> bool:
        """Whether mover k, as it was foresight_s ago and moving on as it then moved, reaches the
        robot where it stands now: a contact the robot could have got out of the way of."""
        then = self._mover_history.oldest()
        if then is None or self.params.foresight_s == 0:
            return False
        xy, velocity = then
        centre = xy[mover] + velocity[mover] * self.params.foresight_s
        movers = len(self.world.movers)
        radius = float(self.world.movers.radius[mover] if mover < movers else self.walkers.state.radius[mover - movers])
        for part in self._parts:
            outline = transform_points(part, self.pose)[0]
            inside = points_in_polygons(centre[None], outline[None])[0, 0]
            if inside or point_segment_distance(centre, outline, np.roll(outline, -1, axis=0)).min() < radius:
                return True
        return False

    # ------------------------------------------------------------ state

    @property
    def collisions(self) -> int:
        """Contacts begun: times the robot started touching an object (the static world, or a mover)."""
        return self.contacts.contacts

    @property
    def robot_fault_collisions(self) -> int:
        """Contacts with at least one substep of the robot's."""
        return self.contacts.robot_contacts

    @property
    def mover_fault_collisions(self) -> int:
        """Contacts in which no substep was the robot's."""
        return self.contacts.mover_contacts

    @property
    def shoved_collisions(self) -> int:
        """Static contacts begun while a mover touched the robot."""
        return self.contacts.shoved_contacts

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
        """The world's movers, then the people in the world (M, 3): x, y, r."""
        movers = np.column_stack([self._mover_xy, self.world.movers.radius]).reshape(-1, 3)
        return np.vstack([movers, self.walkers.circles()]) if len(self.walkers) else movers

    def _robot_shape(self) -> RobotShape:
        """The robot as people see it: its outline where it is, its velocity."""
        velocity = self.robot.velocity
        return RobotShape(self.footprint_outline, np.array([velocity.x, velocity.y]))

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
        self._twist = np.zeros(3)
        self.space.reindex_shapes_for_body(self.robot)
        self._update_clearance(force=True)

    # ------------------------------------------------------------ stepping

    def step(self) -> Readings:
        p, dt = self.params, self.params.dt
        n = self.command.size
        noise = self.rng.standard_normal(2 * n + 3)   # one draw, fixed order: slip, encoders, followers, gyro

        limit, accel = self.chassis.max_wheel_speed, self.body.wheel_acc_limit
        change = np.clip(self.command - self.wheel_speeds, -accel * dt, accel * dt)
        self.wheel_speeds = np.clip(self.wheel_speeds + change, -limit, limit)
        ground = self.wheel_speeds * (1.0 + p.wheel_slip_std * noise[:n])
        self._demand = self.ground.twist_scale * self.kinematics.fk(ground)

        before = (*self.robot.position, self.robot.angle)
        if len(self.walkers):
            self.walkers.plan(self.time, self._robot_shape())
        start_xy, moving = self._mover_xy, np.ones(len(self._movers), bool)
        if self._movers:
            moving = ~self.world.movers.yielding(self._mover_steps * dt, self.footprint_outline)
        touched = False
        for k in range(1, self.substeps + 1):
            substep_xy = (self.world.movers.pose_after((self._mover_steps + moving * (k / self.substeps)) * dt)
                          if self._movers else self._mover_xy)
            touched |= self._substep(dt / self.substeps, substep_xy)
        self._mover_steps += moving
        self.steps += 1
        self._now_s = self.time             # no drift from adding up substeps
        mover_velocities = (self._mover_xy - start_xy) / dt
        people_xy, people_velocities = self.walkers.slots()
        self._mover_history.push(np.vstack([self._mover_xy, people_xy]),
                                 np.vstack([mover_velocities, people_velocities]))
        mover_velocities = np.vstack([mover_velocities, self.walkers.velocities()])
        self.contact_steps += touched

        after = (*self.robot.position, self.robot.angle)
        motion = se2_log(relative(before, after))
        self._encoders += self.wheel_speeds * dt + p.encoder_noise_std * noise[n:2 * n]
        self._followers += follower_readings(self.chassis, motion) + p.encoder_noise_std * noise[2 * n:2 * n + 2]
        gyro_z = (after[2] - before[2]) / dt + p.gyro_bias + p.gyro_noise_std * noise[-1]
        self._update_clearance(touched=touched)
        return Readings(time=self.time, encoder_positions=self._quantise(self._encoders),
                        wheel_speeds=self.wheel_speeds.copy(), follower_positions=self._quantise(self._followers),
                        gyro_z=float(gyro_z), pose=self.pose, twist=motion / dt,
                        mover_circles=self.mover_circles, mover_velocities=mover_velocities,
                        in_contact=bool(touched))

    def _substep(self, h: float, next_xy: np.ndarray) -> bool:
        """Move everything on by h, with contacts resolved and judged; whether the robot touched anything."""
        twist = self._twist = self.ground.carry(self._twist, self._demand, h)
        chord = se2_exp(twist * h)                     # body frame, the exact arc's end point
        c, s = math.cos(self.robot.angle), math.sin(self.robot.angle)
        self.robot.velocity = ((c * chord[0] - s * chord[1]) / h, (s * chord[0] + c * chord[1]) / h)
        self.robot.angular_velocity = float(twist[2])
        # movers stay where they are during space.step; the solver sees their velocity
        for body, xy, xy_next in zip(self._movers, self._mover_xy, next_xy):
            body.velocity = (float(xy_next[0] - xy[0]) / h, float(xy_next[1] - xy[1]) / h)
        if len(self.walkers):
            self.walkers.push(h, self._robot_shape())
        self._shares = {}
        self.space.step(h)
        if self._shares:                  # a contact changed the body's velocity: the floor starts from there
            velocity = self.robot.velocity
            c, s = math.cos(self.robot.angle), math.sin(self.robot.angle)
            self._twist = np.array([c * velocity.x + s * velocity.y, -s * velocity.x + c * velocity.y,
                                    self.robot.angular_velocity])
        pymunk.Body.update_position(self.robot, h)
        self.walkers.advance(h)
        for body, xy in zip(self._movers, next_xy):
            body.position = (float(xy[0]), float(xy[1]))
            self.space.reindex_shapes_for_body(body)
        self._mover_xy = next_xy
        self.contacts.substep(self._shares, h)
        self._now_s += h
        return bool(self._shares) or any(self._touching.values())

    def _quantise(self, angles: np.ndarray) -> np.ndarray:
        return np.round(angles / self._tick) * self._tick if self._tick else angles.copy()

    @property
    def min_clearance(self) -> float:
        """The smallest distance between the footprint and an obstacle or a mover over every step."""
        self._compute_waiting_clearances()
        return self._min_clearance

    def _update_clearance(self, force: bool = False, touched: bool = False) -> None:
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
        if touched:                       # between two steps: the poses at steps may all keep clear
            self._compute_waiting_clearances()
            self._min_clearance = 0.0
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
