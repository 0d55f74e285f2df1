"""The `sim` service: steps the physics at dt × 1/rate of wall time and publishes what happened.

A source (pace_s/tick): each tick advances one step and publishes, all stamped with the new sim
time, the robot's wheel states, the ground truth, the movers and, last, the Clock — so whoever
sees the clock at t has been sent everything stamped t. Wheel commands are a sporadic input:
the sim applies whichever command has arrived by the time it steps — until none has arrived for
wheel_cmd_timeout_s of sim time (its own steps): then the wheels are commanded to stop, as a motor
driver's watchdog does, so a robot whose chassis process died does not roll on. Counted by arrival,
not by the command's stamp: a chassis lagging behind on a loaded machine still drives.
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from ..schemas.messages import (Clock, Diagnostic, Imu, Obstacles, Odometry, Pose2D, Twist, WheelCommand,
                                WheelState)
from ..services.chassis.kinematics import ChassisParams
from ..services.runtime.node import NS_PER_S, Node
from ..parameters.from_mapping import load_params
from .body import BodyParams
from .imu import ImuModel, ImuParams, ImuReading
from .people.social_force import warm_up as warm_people
from .physics import Readings, SimParams, Simulation
from .world import World, WorldError, load_world, shipped_worlds, world_path
from ..geometry.polygons import polygon_area
from ..parameters.declare import Rule, param


@dataclass(frozen=True)
class SimNodeParams(SimParams):
    world: str = "room"                                         # a shipped world's name or a world file's path
    rate: float = param(1.0, ge=0)                              # sim seconds per wall second; 0: as fast as it may (in lockstep: as the services compute)
    footprint: tuple[tuple[float, float], ...] = param((), min_items=3, or_empty=True)  # m, robot frame (a robot profile's); () = the world's
    chassis: dict = field(default_factory=dict)                 # ChassisParams by name: the wheels the chassis drives
    body: dict = field(default_factory=dict)                    # BodyParams by name (sim/body.py): the robot as it is; {} = ideal
    wheel_cmd_timeout_s: float = param(0.5, ge=0)               # sim s of steps without a wheel command that stop the wheels; 0: never
    imu: dict = field(default_factory=dict)                     # ImuParams by name (sim/imu.py): every robot has one

    def chassis_params(self) -> ChassisParams:
        """The wheels the chassis service drives (the body's own `wheels` override them)."""
        return load_params(ChassisParams, self.chassis, "sim.chassis")

    def body_params(self) -> BodyParams:
        return load_params(BodyParams, self.body, "sim.body")

    def imu_params(self) -> ImuParams:
        return load_params(ImuParams, self.imu, "sim.imu")

    rules = (Rule("footprint", lambda p: not p.footprint or abs(polygon_area(np.array(p.footprint))) >= 1e-6,
                  "a polygon enclosing an area"),
             Rule("chassis", lambda p: bool(p.chassis_params()), "ChassisParams by name"),
             Rule("body", lambda p: bool(p.body_params()), "BodyParams by name"),
             Rule("imu", lambda p: bool(p.imu_params()), "ImuParams by name"))

    def robot_world(self, world: World) -> World:
        """The world with this robot's footprint (counter-clockwise) in place of the world file's."""
        if not self.footprint:
            return world
        outline = np.array(self.footprint, np.float64)
        outline = outline if polygon_area(outline) > 0 else outline[::-1].copy()
        return replace(world, robot=replace(world.robot, footprint=outline))


def open_world(name_or_path: str):
    """Load the world a parameter names; a clear WorldError if there is no such world."""
    path = world_path(name_or_path)
    if not path.is_file():
        raise WorldError(f"world {name_or_path!r}: no such file {path} "
                         f"(shipped worlds: {', '.join(shipped_worlds())})")
    return load_world(path)


class SimNode(Node):
    service = "sim"
    coordinates_lockstep = True
    Params = SimNodeParams

    def setup(self) -> None:
        p = self.params
        self.world = p.robot_world(open_world(p.world))
        self.sim = Simulation(self.world, p, p.chassis_params(), body=p.body_params())
        if len(self.sim.walkers):
            warm_people()       # compile the social force kernels now, never inside a step
        self.step_ns = round(p.dt * NS_PER_S)
        # its own stream of the sim's seeded generator: adding the IMU left every other reading as it was
        self.imu_model = ImuModel(p.imu_params(), p.dt, self.sim.rng.spawn(1)[0])
        self.imu = self.publisher("imu")
        self.wheel_state = self.publisher("wheel_state")
        self.truth = self.publisher("sim/truth")
        self.movers = self.publisher("sim/movers")
        self.clock = self.publisher("sim/clock")
        self.command_key = self.keys.resolve("wheel_cmd")
        self.subscribe("wheel_cmd", self.on_wheel_cmd, synced=False)
        self.queryable("sim/truth", lambda _params: self.last_truth)
        self.last_truth = self._truth(self.sim.pose, np.zeros(3))
        self._logged_problems: set[str] = set()
        self.quiet_steps: int | None = None    # steps since the last wheel command; None: none in effect

    def pace_s(self) -> float:
        return self.params.dt / self.params.rate if self.params.rate else 0.0

    def on_wheel_cmd(self, msg: WheelCommand) -> None:
        wanted = self.sim.command.size
        if msg.drive != self.sim.drive or msg.velocities.shape != (wanted,):
            problem = (f"wheel command for a {msg.drive} drive with {msg.velocities.size} wheels rejected: "
                       f"the simulated robot is a {self.sim.drive} drive with {wanted} wheels")
            self.counters[f"rejected/{self.command_key}"] += 1
            if problem not in self._logged_problems:
                self._logged_problems.add(problem)
                self.log.warning("%s (further ones only counted)", problem)
            return
        self.sim.set_wheel_command(msg.velocities)
        self.quiet_steps = 0

    def _watchdog(self) -> None:
        """Stop the wheels when no command has come for wheel_cmd_timeout_s (the chassis is silent)."""
        p = self.params
        if not p.wheel_cmd_timeout_s or self.quiet_steps is None:
            return
        self.quiet_steps += 1
        if self.quiet_steps * p.dt > p.wheel_cmd_timeout_s:
            self.sim.set_wheel_command(np.zeros(self.sim.command.size))
            self.quiet_steps = None
            self.counters["wheel_cmd_timeouts"] += 1
            self.log.warning("no wheel command for %.2f sim s: stopping the wheels", p.wheel_cmd_timeout_s)

    def tick(self) -> None:
        self._watchdog()
        r = self.sim.step()
        self.now_ns = self.sim.steps * self.step_ns
        self.wheel_state.publish(self._wheel_state(r))
        imu_reading = self.imu_model.step(r.twist)
        if imu_reading is not None:
            self.imu.publish(self._imu(imu_reading))
        self.last_truth = self._truth(r.pose, r.twist)
        self.truth.publish(self.last_truth)
        self.movers.publish(Obstacles(header=self.header("world"), circles=r.mover_circles,
                                      velocities=r.mover_velocities))
        self.clock.publish(Clock(header=self.header(), rate=self.params.rate))

    def _wheel_state(self, r: Readings) -> WheelState:
        return WheelState(header=self.header("base_link"), drive=self.sim.drive, positions=r.encoder_positions,
                          velocities=r.wheel_speeds, follower_positions=r.follower_positions, gyro_z=r.gyro_z)

    def _imu(self, reading: ImuReading) -> Imu:
        model = self.imu_model
        ax, ay = (float(v) for v in reading.linear_acceleration)
        return Imu(header=self.header(model.params.frame_id), angular_velocity_z=reading.angular_velocity_z,
                   linear_acceleration_x=ax, linear_acceleration_y=ay,
                   angular_velocity_z_variance=model.gyro_std ** 2,
                   linear_acceleration_x_variance=model.accel_std ** 2,
                   linear_acceleration_y_variance=model.accel_std ** 2)

    def _truth(self, pose: np.ndarray, twist: np.ndarray) -> Odometry:
        x, y, theta = (float(v) for v in pose)
        vx, vy, wz = (float(v) for v in twist)
        return Odometry(header=self.header("world"), child_frame_id="base_link", pose=Pose2D(x, y, theta),
                        twist=Twist(header=self.header("base_link"), linear_x=vx, linear_y=vy, angular_z=wz),
                        pose_covariance=np.zeros((3, 3)), twist_covariance=np.zeros((3, 3)))

    def diagnostic(self) -> Diagnostic:
        diag = super().diagnostic()
        contacts = self.sim.contacts
        diag.values.update(collisions=self.sim.collisions, robot_fault_collisions=self.sim.robot_fault_collisions,
                           mover_fault_collisions=self.sim.mover_fault_collisions,
                           shoved_collisions=self.sim.shoved_collisions, contact_steps=self.sim.contact_steps,
                           contact_s=contacts.contact_s, robot_contact_s=contacts.robot_contact_s,
                           min_clearance_m=self.sim.min_clearance, world=str(self.world.source),
                           drive=self.sim.drive)
        rejected = sorted(k for k in self.counters if k.startswith("rejected/"))
        if rejected:
            diag.level = max(diag.level, 1)
            note = "rejected wheel commands: " + ", ".join(rejected)
            diag.message = note if diag.message == "ok" else f"{diag.message}; {note}"
        return diag
