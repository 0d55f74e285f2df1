"""collision_monitor, the second of the two gates between the navigator and the chassis:

    cmd_vel_mux --cmd_vel_mux--> velocity_smoother --cmd_vel_smoothed--> collision_monitor --cmd_vel--> chassis

The monitor (CollisionMonitor, collision.py) follows cmd_vel_smoothed (its only synced input)
and answers every command at once with cmd_vel, stamped the same: no added latency. Scans are
sporadic: a scan stamped t is used from the first command stamped after t + scan_delay_s (the
time a scan may take to arrive, live) until a newer one takes effect; its points are placed in the
robot frame by the laser's mount on the robot (laser_x, laser_y, laser_yaw: the simulated lidar's
mount by default, as the costmap). No scan, or one older than source_timeout, stops the robot:
the monitor cannot see. The scan's points are carried to the command's time by the robot's motion
since the scan's stamp (Nav2's base_shift_correction), dead-reckoned from the monitor's own
commands as the chassis carries them out (geometry/command_response.py: cmd_vel_delay_s late, at
the acceleration limits): the odometry arrives too late for it (held tracks_delay_s, below), and
without it the scan in use is up to 0.15 s old — 7.5 cm at 0.5 m/s, or a corner 0.5 m out swung
4 cm by a turn at 0.5 rad/s, most of the 5 cm stop zone (generated mazes: corners turned into
walls). The commands as sent were not enough: after a stop they say the robot stood, while it was
still turning, and the monitor let the turn go on (maze 35). The same model gives the path each
command is judged by (collision.py): what is on its way, the command, then braking.
The tracker's tracks and the odometry are held tracks_delay_s the same way; the tracks are
predicted to the command's time and placed around the robot where its odometry, carried on by its
twist, puts it then: a command that would meet a track in the stop zone within
time_before_collision, sooner than standing, is slowed or stopped (collision.py).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ...geometry.frames import LASER_MOUNT, twist_message, twist_vector
from ...geometry.command_response import CommandResponse
from ...geometry.polygons import transform_points
from ...geometry.se2 import integrate, inverse
from ...schemas.messages import Odometry, Tracks, Twist
from ...geometry.movers import Movers, movers_at, tracks_problem
from ..runtime.deferred import Deferred
from ..runtime.node import NS_PER_S, Node
from .collision import CollisionMonitor, CollisionMonitorParams, robot_frame_points
from ...parameters.declare import Rule, param


@dataclass(frozen=True)
class CollisionMonitorNodeParams(CollisionMonitorParams):
    laser_x: float = LASER_MOUNT[0]     # m: the laser on the robot (the simulated lidar's mount)
    laser_y: float = LASER_MOUNT[1]
    laser_yaw: float = LASER_MOUNT[2]
    scan_delay_s: float = param(0.05, ge=0)               # sim s from a scan's stamp until it is used
    source_timeout: float = param(1.0, finite=True)              # s: an older scan is no scan (Nav2's name; its default is 2)
    base_shift_correction: bool = True    # Nav2's name: carry the scan by the robot's motion since its stamp
    # the chassis the commands go to (the chassis service's names and defaults): how the robot follows them
    cmd_vel_delay_s: float = param(0.05, ge=0)            # sim s from a command's stamp until it takes effect
    acc_lim_x: float = param(2.5, gt=0)                   # m/s^2
    acc_lim_y: float = param(2.5, gt=0)                   # m/s^2
    acc_lim_theta: float = param(3.2, gt=0)               # rad/s^2
    chassis_period_s: float = param(0.01, gt=0)           # s between the chassis's velocity steps (the sim's dt)
    tracks_delay_s: float = param(0.5, ge=0)              # sim s from a tracks / odom stamp until it is used (live, tracks trailed
                                             # the clock the monitor runs on by more than 0.3 s)

    rules = (Rule("source_timeout", lambda p: p.source_timeout > p.scan_delay_s,
                  "more than scan_delay_s ({p.scan_delay_s})"),)


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
        self.points = np.zeros((0, 2))                        # its points, robot frame at its stamp
        self.response = CommandResponse(p.cmd_vel_delay_s, (p.acc_lim_x, p.acc_lim_y, p.acc_lim_theta),
                                        p.chassis_period_s, p.source_timeout)   # the robot's motion from the commands sent
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

    def _points_at(self, t: int) -> np.ndarray:
        """The scan's points in the robot frame at t."""
        if not self.params.base_shift_correction:
            return self.points
        return transform_points(self.points, inverse(self.response.motion(self.scan_stamp_ns, t)))[0]

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
        twist = twist_vector(msg)
        if self.scan_stamp_ns is None or t - self.scan_stamp_ns > self.timeout_ns:
            action, twist = "no_scan", np.zeros(3)
        else:
            result = self.monitor.check(twist, self._points_at(t), self._movers(t),
                                        lambda command: self.response.path(t, command, self.params.approach_check_s))
            action, twist = result.action, result.twist
        self.counters[f"action/{action}"] += 1
        self.response.add(t, twist)
        self.out_pub.publish(twist_message(twist, t))
