"""The chassis service: wheel states in, odometry and wheel commands out.

Every wheel_state (the sim's step, or a motor driver's reading) advances the wheel odometry (and
the follower-wheel + gyro odometry) and produces the wheel command for the next interval, stamped
with the reading's time. cmd_vel is sporadic: a command stamped t takes effect from the first
wheel_state stamped after t + cmd_vel_delay_s, not from whichever reading happened to come next.
That fixed delay is what makes a live run replayable: whether the command reached the node before
or after the readings stamped in (t, t + delay] cannot change the outputs (see docs/teleop_and_report.md).

With odom_file set, the odometry's state (stamp, poses, encoder positions) is written there at most
save_odom_rate times per sim second, and a chassis started with that file carries on from it: the
encoders' change over the time it was down is one odometry step, so a restarted chassis does not
put the robot back at the odometry's origin under the localizer, the costmap and the planners.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ...schemas import MessageError
from ...schemas.messages import Header, Odometry, Pose2D, Transform, Twist, WheelCommand, WheelState
from ..runtime.deferred import Deferred
from ..runtime.node import NS_PER_S, Node
from ...parameters.declare import ParamError, Rule, param
from ..runtime.state_file import read_state, write_state
from .follower_wheels import follower_odometry
from .kinematics import ChassisParams, Kinematics
from .odometry import OdomEstimate, wheel_odometry

N_FOLLOWERS = 2


@dataclass(frozen=True)
class ChassisNodeParams(ChassisParams):
    """ChassisParams plus what the node needs around the core."""
    cmd_vel_timeout_s: float = param(0.5, ge=0)  # sim s: a command older than this is replaced by zero
    cmd_vel_delay_s: float = param(0.05, ge=0)   # sim s from a command's stamp until it takes effect
    odom_frame_id: str = param("odom", nonempty=True)
    base_frame_id: str = param("base_link", nonempty=True)
    follower_odometry: bool = True               # also publish odom_follower (needs two follower encoders)
    # what odom and tf/odom_base carry: the driven wheels' encoders, or the follower wheels and gyro,
    # which roll with the ground and so also measure slip and a robot pushed by someone
    odom_source: str = param("wheels", choices=("wheels", "followers"))
    # true beside an odometry fusion (services/ekf): odom goes out as odom_wheel and no tf/odom_base,
    # the fusion publishes both (as diff_drive_controller's enable_odom_tf: false beside robot_localization)
    fused_odometry: bool = False
    odom_file: str = ""                          # where save_odom_rate keeps the odometry's state; "": nowhere
    save_odom_rate: float = param(10.0, ge=0)    # Hz of sim time

    rules = (Rule("cmd_vel_delay_s", lambda p: p.cmd_vel_delay_s < p.cmd_vel_timeout_s,
                  "shorter than cmd_vel_timeout_s ({p.cmd_vel_timeout_s}), or no command is ever fresh"),
             Rule("odom_source", lambda p: p.odom_source != "followers" or p.follower_odometry,
                  "wheels unless follower_odometry is true"))


@dataclass(frozen=True)
class SavedOdometry:
    """What odom_file holds: each odometry's last update (EncoderOdometry.state)."""
    stamp_ns: int
    pose: tuple[float, float, float]
    positions: tuple[float, ...]
    follower_pose: tuple[float, ...] = ()       # () without follower odometry
    follower_positions: tuple[float, ...] = ()


class ChassisNode(Node):
    service = "chassis"
    Params = ChassisNodeParams
    state_files = ("odom_file",)

    def setup(self) -> None:
        p = self.params
        self.kinematics = Kinematics(p)
        self.wheel_odom = wheel_odometry(p)
        self.follower_odom = follower_odometry(p) if p.follower_odometry else None
        self.odom_pub = self.publisher("odom_wheel" if p.fused_odometry else "odom")
        self.tf_pub = None if p.fused_odometry else self.publisher("tf/odom_base")
        self.follower_pub = self.publisher("odom_follower") if p.follower_odometry else None
        self.wheel_cmd_pub = self.publisher("wheel_cmd")
        self.wheel_state_key = self.keys.resolve("wheel_state")
        self.timeout_ns = round(p.cmd_vel_timeout_s * NS_PER_S)
        self.pending = Deferred(p.cmd_vel_delay_s)             # cmd_vel not yet in effect
        self.subscribe("wheel_state", self.on_wheel_state)
        self.subscribe_deferred("cmd_vel", self.pending)
        self.queryable("odom_wheel" if p.fused_odometry else "odom", lambda _params: self.last_odom)
        self.last_odom: Odometry | None = None
        self.command: tuple[int, np.ndarray] | None = None     # (stamp, twist) in effect
        self.previous = np.zeros(3)                            # the twist last commanded
        self.last_stamp: int | None = None                     # of the last accepted wheel_state
        self.last_save_ns: int | None = None
        self._resume()

    def _resume(self) -> None:
        path = self.params.odom_file
        if not path or not Path(path).exists():
            return
        try:
            saved = read_state(SavedOdometry, path)
            self.wheel_odom.resume(saved.stamp_ns, saved.pose, saved.positions)
            if self.follower_odom is not None and saved.follower_positions:
                self.follower_odom.resume(saved.stamp_ns, saved.follower_pose, saved.follower_positions)
        except (ParamError, ValueError) as exc:
            self.log.warning("not resuming from the saved odometry: %s", exc)
            return
        self.counters["resumed_from_odom_file"] += 1
        self.log.info("resuming the odometry saved in %s", path)

    def _save(self, t: int) -> None:
        p = self.params
        if not p.odom_file or p.save_odom_rate <= 0 or (
                self.last_save_ns is not None and t - self.last_save_ns < NS_PER_S / p.save_odom_rate):
            return
        self.last_save_ns = t
        stamp, pose, positions = self.wheel_odom.state()
        follower = self.follower_odom.state() if self.follower_odom is not None else None
        state = SavedOdometry(stamp, tuple(pose), tuple(positions),
                              *((tuple(follower[1]), tuple(follower[2])) if follower is not None else ()))
        try:
            write_state(p.odom_file, state, "the chassis's odometry at its last save")
        except OSError as exc:
            self.counters["odom_file_errors"] += 1
            if self.counters["odom_file_errors"] == 1:
                self.log.warning("cannot save the odometry to %s: %s", p.odom_file, exc)

    # ------------------------------------------------------------ inputs

    def on_wheel_state(self, msg: WheelState) -> None:
        problem = self._check(msg)
        if problem:
            self.reject(self.wheel_state_key, MessageError(problem, type_name="WheelState", key=self.wheel_state_key))
            return
        t = msg.header.stamp_ns
        dt = 0.0 if self.last_stamp is None else (t - self.last_stamp) / NS_PER_S
        self.last_stamp = t
        wheels = self._odometry(self.wheel_odom.update(t, msg.positions, msg.gyro_z))
        followers = None
        if self.follower_odom is not None:
            followers = self._odometry(self.follower_odom.update(t, msg.follower_positions, msg.gyro_z))
        self.last_odom = followers if self.params.odom_source == "followers" else wheels
        self.odom_pub.publish(self.last_odom)
        if self.tf_pub is not None:
            self.tf_pub.publish(Transform(header=Header(stamp_ns=t, frame_id=self.params.odom_frame_id),
                                          child_frame_id=self.params.base_frame_id,
                                          transform=self.last_odom.pose))
        if followers is not None:
            self.follower_pub.publish(followers)
        self._save(t)
        self._command(t, dt)

    def _check(self, msg: WheelState) -> str:
        """Why this reading cannot be used, or ''."""
        p = self.params
        n = self.kinematics.n_wheels
        if msg.drive != p.drive:
            return f"drive {msg.drive!r}, but the chassis is configured for {p.drive!r} (parameter drive)"
        if msg.positions.shape != (n,):
            return f"positions: {msg.positions.shape[0]} wheels, a {p.drive} chassis has {n}"
        if self.follower_odom is not None and msg.follower_positions.shape != (N_FOLLOWERS,):
            return (f"follower_positions: {msg.follower_positions.shape[0]} encoders, follower odometry needs "
                    f"{N_FOLLOWERS} (set follower_odometry: false for a robot without follower wheels)")
        if self.last_stamp is not None and msg.header.stamp_ns < self.last_stamp:
            return (f"stamp {msg.header.stamp_ns} ns is before the previous reading's {self.last_stamp} ns "
                    "(did the sim restart? restart the chassis with it)")
        return ""

    # ------------------------------------------------------------ outputs

    def _odometry(self, est: OdomEstimate) -> Odometry:
        p = self.params
        x, y, theta = (float(v) for v in est.pose)
        vx, vy, wz = (float(v) for v in est.twist)
        return Odometry(header=Header(stamp_ns=est.stamp_ns, frame_id=p.odom_frame_id),
                        child_frame_id=p.base_frame_id, pose=Pose2D(x, y, theta),
                        twist=Twist(header=Header(stamp_ns=est.stamp_ns, frame_id=p.base_frame_id),
                                    linear_x=vx, linear_y=vy, angular_z=wz),
                        pose_covariance=est.pose_covariance, twist_covariance=est.twist_covariance)

    def _target(self, t: int) -> np.ndarray:
        """The latest command in effect at t (stamped before t - delay), or zero if it is stale."""
        for _, msg in self.pending.due(t):
            # a command that arrived after a newer one took effect is already superseded
            if self.command is None or msg.header.stamp_ns >= self.command[0]:
                self.command = (msg.header.stamp_ns, np.array([msg.linear_x, msg.linear_y, msg.angular_z]))
        if self.command is None or t - self.command[0] > self.timeout_ns:
            return np.zeros(3)
        return self.command[1]

    def _command(self, t: int, dt: float) -> None:
        limited = self.kinematics.limit(self._target(t), self.previous, dt)
        self.previous = limited.twist
        if limited.dropped_vy:
            self.counters["dropped_vy"] += 1
        if limited.saturation < 1.0:
            self.counters["saturated"] += 1
        if limited.accel_limited:
            self.counters["accel_limited"] += 1
        self.wheel_cmd_pub.publish(WheelCommand(header=Header(stamp_ns=t, frame_id=self.params.base_frame_id),
                                                drive=self.params.drive, velocities=limited.wheels))
