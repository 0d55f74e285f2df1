"""The two gates between the navigator and the chassis: velocity_smoother and collision_monitor.

    cmd_vel_mux --cmd_vel_mux--> velocity_smoother --cmd_vel_smoothed--> collision_monitor --cmd_vel--> chassis

(the mux takes the navigator's cmd_vel_nav and teleop's cmd_vel_teleop: services/cmd_vel_mux/)

velocity_smoother (VelocitySmoother, smoother.py) runs on the sim clock: a smoothing tick falls on
the clock stamped at or first after each multiple of 1/smoothing_frequency of sim time, and every
tick publishes the smoothed command (zeros while there is nothing to do, so the collision monitor
downstream always has a stream to follow). cmd_vel_mux is sporadic: a command stamped t takes
effect at the first tick after t + command_delay_s — the time the navigator's command may take to
get here (through the mux), live, behind the clock; whether it arrives before or after the clocks stamped in
(t, t + delay] then cannot change the output. Added latency: with the local planner and the
smoother both at 20 Hz (ticks on the same multiples of 50 ms) and the default 0.04 s delay, one
period, 50 ms. No command for velocity_timeout seconds of sim time → the output decelerates to zero.

collision_monitor (CollisionMonitor, collision.py) follows cmd_vel_smoothed (its only synced input)
and answers every command at once with cmd_vel, stamped the same: no added latency. Scans are
sporadic: a scan stamped t is used from the first command stamped after t + scan_delay_s (the
time a scan may take to arrive, live) until a newer one takes effect; its points are placed in the
robot frame by the laser's mount on the robot (laser_x, laser_y, laser_yaw: the simulated lidar's
mount by default, as the costmap). No scan, or one older than source_timeout, stops the robot:
the monitor cannot see. The zones do not account for the robot's motion since the scan (as Nav2's
without its source_timeout shift), so at 0.5 m/s the scan in use is up to 7.5 cm behind.
The tracker's tracks and the odometry are held tracks_delay_s the same way; the tracks are
predicted to the command's time and placed around the robot where its odometry, carried on by its
twist, puts it then: a command that would meet a track in the stop zone within
time_before_collision, sooner than standing, is slowed or stopped (collision.py).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ...schemas.messages import Clock, Header, Odometry, Tracks, Twist
from ..runtime.deferred import Deferred
from ..runtime.node import NS_PER_S, Node, Ticks
from ..runtime.params import require_nonnegative
from ...geometry.frames import LASER_MOUNT
from ...geometry.se2 import integrate, inverse
from .collision import CollisionMonitor, robot_frame_points
from .dynamic import Movers, movers_at, tracks_problem
from .params import CollisionMonitorParams, VelocitySmootherParams
from .smoother import VelocitySmoother


def _twist(msg: Twist) -> np.ndarray:
    return np.array([msg.linear_x, msg.linear_y, msg.angular_z])


def _message(twist: np.ndarray, stamp_ns: int) -> Twist:
    vx, vy, wz = (float(v) for v in twist)
    return Twist(header=Header(stamp_ns=stamp_ns, frame_id="base_link"), linear_x=vx, linear_y=vy, angular_z=wz)


@dataclass(frozen=True)
class VelocitySmootherNodeParams(VelocitySmootherParams):
    """Nav2's velocity_smoother names; the limits default to what the chassis allows on every axis
    (Nav2's defaults are a differential drive's, vy 0, which would stop a mecanum robot strafing)."""
    max_velocity: tuple[float, float, float] = (0.5, 0.5, 2.5)
    min_velocity: tuple[float, float, float] = (-0.5, -0.5, -2.5)
    max_accel: tuple[float, float, float] = (2.5, 2.5, 3.2)
    max_decel: tuple[float, float, float] = (-2.5, -2.5, -3.2)
    command_delay_s: float = 0.04       # sim s from a command's stamp until it takes effect

    def __post_init__(self):
        super().__post_init__()
        require_nonnegative(self, "command_delay_s")


class VelocitySmootherNode(Node):
    service = "velocity_smoother"
    Params = VelocitySmootherNodeParams

    def setup(self) -> None:
        p = self.params
        self.smoother = VelocitySmoother(p)
        self.ticks = Ticks(p.smoothing_frequency)
        self.pending = Deferred(p.command_delay_s)   # commands not yet in effect
        self.out_pub = self.publisher("cmd_vel_smoothed")
        self.subscribe("sim/clock", self.on_clock)
        self.subscribe_deferred("cmd_vel_mux", self.pending)

    def on_clock(self, msg: Clock) -> None:
        t = msg.header.stamp_ns
        if not self.ticks.due(t):
            return
        for _, command in self.pending.due(t):
            self.smoother.command(_twist(command), command.header.stamp_ns)
            self.counters["commands"] += 1
        out = self.smoother.step(t)
        self.counters["timed_out_ticks" if out.timed_out else "ticks"] += 1
        self.out_pub.publish(_message(out.twist, t))


@dataclass(frozen=True)
class CollisionMonitorNodeParams(CollisionMonitorParams):
    laser_x: float = LASER_MOUNT[0]     # m: the laser on the robot (the simulated lidar's mount)
    laser_y: float = LASER_MOUNT[1]
    laser_yaw: float = LASER_MOUNT[2]
    scan_delay_s: float = 0.05               # sim s from a scan's stamp until it is used
    source_timeout: float = 1.0              # s: an older scan is no scan (Nav2's name; its default is 2)
    tracks_delay_s: float = 0.5              # sim s from a tracks / odom stamp until it is used (live, tracks trailed
                                             # the clock the monitor runs on by more than 0.3 s)

    def __post_init__(self):
        super().__post_init__()
        require_nonnegative(self, "scan_delay_s", "tracks_delay_s")
        if not (np.isfinite(self.source_timeout) and self.source_timeout > self.scan_delay_s):
            raise ValueError(f"source_timeout must exceed scan_delay_s ({self.scan_delay_s}), "
                             f"got {self.source_timeout}")


_ODOM, _TRACKS = range(2)     # the collision monitor's held inputs besides scans, in input order


class CollisionMonitorNode(Node):
    service = "collision_monitor"
    Params = CollisionMonitorNodeParams

    def setup(self) -> None:
        p = self.params
        self.monitor = CollisionMonitor(p)
        self.laser = np.array([p.laser_x, p.laser_y, p.laser_yaw])
        self.timeout_ns = round(p.source_timeout * NS_PER_S)
        self.pending = Deferred(p.scan_delay_s)              # scans not yet in effect
        self.scan_stamp_ns: int | None = None                 # of the scan in effect
        self.points = np.zeros((0, 2))                        # its points, robot frame
        self.pending_tracks = Deferred(p.tracks_delay_s)     # tracks and odometry not yet in effect
        self.tracks: Tracks | None = None
        self.odom: Odometry | None = None
        self.out_pub = self.publisher("cmd_vel")
        self.subscribe("cmd_vel_smoothed", self.on_command)
        self.subscribe_deferred("scan", self.pending)
        self.subscribe_deferred("odom", self.pending_tracks, _ODOM)
        self.subscribe_deferred("tracks", self.pending_tracks, _TRACKS, tracks_problem)

    def _movers(self, t: int) -> Movers | None:
        """The tracks in effect at the command's time, robot frame (the robot carried from its last
        odometry in effect by that odometry's twist; tracks and odometry share the odom frame)."""
        if self.tracks is None or self.odom is None:
            return None
        o = self.odom
        age = max(0.0, (t - o.header.stamp_ns) / NS_PER_S)
        robot = integrate((o.pose.x, o.pose.y, o.pose.theta), (o.twist.linear_x, o.twist.linear_y, o.twist.angular_z),
                          age)
        return movers_at(self.tracks, t / NS_PER_S, inverse(robot), 0.0)

    def on_command(self, msg: Twist) -> None:
        t = msg.header.stamp_ns
        for _, scan in self.pending.due(t):
            self.scan_stamp_ns = scan.header.stamp_ns
            self.points = robot_frame_points(scan, self.laser)
        for kind, held in self.pending_tracks.due(t):
            if kind == _ODOM:
                self.odom = held
            else:
                self.tracks = held
        twist = _twist(msg)
        if self.scan_stamp_ns is None or t - self.scan_stamp_ns > self.timeout_ns:
            action, twist = "no_scan", np.zeros(3)
        else:
            result = self.monitor.check(twist, self.points, self._movers(t))
            action, twist = result.action, result.twist
        self.counters[f"action/{action}"] += 1
        self.out_pub.publish(_message(twist, t))
