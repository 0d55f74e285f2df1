"""Odometry fusion: robot_localization's EKF in two_d_mode, and the doubt of doubt.py.

The state is robot_localization's 15-variable state cut to the plane: x, y, yaw in the world frame
(odom), vx, vy, vyaw and ax, ay in the body frame (base_link). The motion model is its
omnidirectional constant-acceleration one: the pose moves by the body velocity and half the body
acceleration, rotated by yaw, times dt (and dt²); the velocities grow by the accelerations; the
accelerations and the yaw rate stay. Covariance: P ← F P Fᵀ + Q·dt, F the model's Jacobian, Q
`process_noise_covariance`. A measurement updates the subset of the state its `*_config` selects
(the 15 booleans [x, y, z, roll, pitch, yaw, vx, vy, vz, vroll, vpitch, vyaw, ax, ay, az]; in two_d_mode
z, roll, pitch, vz, vroll, vpitch, az are ignored), with the Joseph form, after a Mahalanobis gate
(`*_rejection_threshold`, in sigmas: a measurement whose innovation lies further is rejected).
Odometry's pose and twist are gated apart (pose / twist thresholds), the IMU's yaw rate and
acceleration apart, as in robot_localization.

Where ours differs: the accelerometer reads dv/dt + ω × v, so the state's ax, ay are what it reads
and the prediction turns the body velocity with the body, exactly (robot_localization takes the
reading as dv/dt, which on a turn is why the Jackal fuses ax alone); the IMU carries no orientation
(yaw in imu0_config is refused).

Lagged measurements (`smooth_lagged_data`, `history_length` s): every measurement is kept with the
filter's state before it; one stamped before the latest puts the filter back to the state before
it, applies it, and applies the later ones again, so the result does not depend on how late it
came (within the history). Without smoothing a late measurement is applied at the current time.

The fusion (`OdometryFusion`) has three fixed sources: odom0, the wheels (an Odometry per step,
which also advances the filter's time for the output), imu0 (Imu) and odom1, laser odometry
(Odometry, late). Each wheel step, doubt.py judges whether the wheels agree with the gyro, the IMU
and the scans; the wheels' components it holds out are not fused (counted `held_out/odom0`).
"""
from __future__ import annotations

import math
import sys
from collections import Counter
from dataclasses import dataclass, replace

import numpy as np

from ...geometry.se2 import compose, inverse, relative, wrap_angle
from ...parameters.declare import Rule, group, param
from ...schemas.messages import Imu, Odometry, Pose2D
from .doubt import Doubt, DoubtParams, Verdict

NS = 1e-9
X, Y, YAW, VX, VY, VYAW, AX, AY = range(8)
N = 8
# robot_localization's 15 state variables, and where the plane's 8 sit among them
RL_NAMES = ("x", "y", "z", "roll", "pitch", "yaw", "vx", "vy", "vz", "vroll", "vpitch", "vyaw", "ax", "ay", "az")
RL_INDEX = (0, 1, 5, 6, 7, 11, 12, 13)
NEVER = sys.float_info.max       # robot_localization's default threshold: std::numeric_limits<double>::max()
MIN_VARIANCE = 1e-9              # a measured variance below this is raised to it (a singular innovation otherwise)
MAX_SPEED = 50.0                 # m/s: a body velocity beyond this is a filter gone wrong, not a robot
MAX_ACCELERATION = 500.0         # m/s²: likewise (a hard hit is tens)
MAX_VARIANCE = 1e8               # of any state variable: likewise

# robot_localization's defaults (ekf_template.yaml), the 15 diagonal values
PROCESS_NOISE = (0.05, 0.05, 0.06, 0.03, 0.03, 0.06, 0.025, 0.025, 0.04, 0.01, 0.01, 0.02, 0.01, 0.01, 0.015)
INITIAL_ESTIMATE = (1e-9,) * 15

SOURCES = ("imu0", "odom0", "odom1")     # processing order at one stamp: the node's input order


def config(*names: str) -> tuple[bool, ...]:
    """A robot_localization `*_config` vector with the named variables true."""
    return tuple(name in names for name in RL_NAMES)


def _booleans(name: str) -> Rule:
    return Rule(name, lambda p: all(isinstance(v, bool) for v in getattr(p, name)),
                "15 booleans [" + ", ".join(RL_NAMES) + "]")


def _without(name: str, forbidden: tuple[str, ...], why: str) -> Rule:
    places = [RL_NAMES.index(f) for f in forbidden]
    return Rule(name, lambda p: not any(getattr(p, name)[i] for i in places),
                f"false at {', '.join(forbidden)} ({why})")


def _matrix_size(name: str) -> Rule:
    return Rule(name, lambda p: len(getattr(p, name)) in (15, 15 * 15),
                "15 values (the diagonal) or 225 (robot_localization's 15 × 15 matrix, row by row)",
                shown=lambda p: f"{len(getattr(p, name))} values")


def _not_both(source: str) -> Rule:
    return Rule(f"{source}_relative", lambda p: not (getattr(p, f"{source}_relative") and getattr(p, f"{source}_differential")),
                f"false when {source}_differential is true (one or the other)")


@dataclass(frozen=True)
class EkfParams(DoubtParams):
    """robot_localization's ekf_node parameters, as far as the plane and our three sources need them
    (names and defaults its own, but where the comment says ours)."""
    two_d_mode: bool = param(True, choices=(True,))     # ours: only the plane (robot_localization's default is false)
    # odom0: the wheels' odometry (odom_wheel). As the Jackal's robot_localization.yaml: the velocities
    odom0_config: tuple[bool, ...] = param(config("vx", "vy", "vyaw"), items=15)
    odom0_differential: bool = False
    odom0_relative: bool = False
    odom0_pose_rejection_threshold: float = param(NEVER, gt=0)     # sigmas
    odom0_twist_rejection_threshold: float = param(NEVER, gt=0)
    # odom1: laser odometry (odom_laser): its pose, absolute (docs/odometry_fusion.md says why)
    odom1_config: tuple[bool, ...] = param(config("x", "y", "yaw"), items=15)
    odom1_differential: bool = False
    odom1_relative: bool = False
    odom1_pose_rejection_threshold: float = param(NEVER, gt=0)
    odom1_twist_rejection_threshold: float = param(NEVER, gt=0)
    # imu0: the IMU (imu): the yaw rate and the plane's accelerations (the Jackal takes yaw, vyaw, ax)
    imu0_config: tuple[bool, ...] = param(config("vyaw", "ax", "ay"), items=15)
    imu0_angular_velocity_rejection_threshold: float = param(NEVER, gt=0)
    imu0_linear_acceleration_rejection_threshold: float = param(NEVER, gt=0)
    history_length: float = param(1.0, ge=0)       # s; ours 1 (robot_localization's 0): laser odometry comes late
    smooth_lagged_data: bool = True                # ours true (robot_localization's false), for the same reason
    process_noise_covariance: tuple[float, ...] = param(PROCESS_NOISE, finite=True)
    initial_estimate_covariance: tuple[float, ...] = param(INITIAL_ESTIMATE, finite=True)

    rules = (_booleans("odom0_config"), _booleans("odom1_config"), _booleans("imu0_config"),
             _without("odom0_config", ("ax", "ay"), "Odometry carries no acceleration"),
             _without("odom1_config", ("ax", "ay"), "Odometry carries no acceleration"),
             _without("imu0_config", ("x", "y", "yaw", "vx", "vy"), "the Imu message carries yaw rate and acceleration only"),
             _not_both("odom0"), _not_both("odom1"),
             _matrix_size("process_noise_covariance"), _matrix_size("initial_estimate_covariance"))

    def uses(self, source: str) -> bool:
        """Whether any variable of the plane is fused from this source."""
        vector = getattr(self, f"{source}_config")
        return any(vector[i] for i in RL_INDEX)


def plane_matrix(values: tuple[float, ...]) -> np.ndarray:
    """The plane's 8 × 8 block of a robot_localization 15-diagonal or 15 × 15 matrix."""
    full = np.diag(values) if len(values) == 15 else np.asarray(values, float).reshape(15, 15)
    return full[np.ix_(RL_INDEX, RL_INDEX)].astype(float)


class Ekf:
    """The filter alone: state, covariance, prediction and gated partial updates."""

    def __init__(self, process_noise: np.ndarray, initial_covariance: np.ndarray):
        self.q = process_noise
        self.x = np.zeros(N)
        self.p = initial_covariance.copy()
        self.stamp_ns: int | None = None

    def predict(self, stamp_ns: int) -> None:
        """Move the state to stamp_ns (nothing for a stamp not after the state's)."""
        if self.stamp_ns is None:
            self.stamp_ns = stamp_ns
            return
        dt = (stamp_ns - self.stamp_ns) * NS
        if dt <= 0:
            return
        self.stamp_ns = stamp_ns
        x = self.x
        c, s = math.cos(x[YAW]), math.sin(x[YAW])
        half = 0.5 * dt * dt
        f = np.eye(N)
        f[X, VX], f[X, VY], f[X, AX], f[X, AY] = c * dt, -s * dt, c * half, -s * half
        f[Y, VX], f[Y, VY], f[Y, AX], f[Y, AY] = s * dt, c * dt, s * half, c * half
        f[YAW, VYAW] = dt
        f[X, YAW] = (-s * x[VX] - c * x[VY]) * dt + (-s * x[AX] - c * x[AY]) * half
        f[Y, YAW] = (c * x[VX] - s * x[VY]) * dt + (c * x[AX] - s * x[AY]) * half
        # the body velocity turns with the body: v' = R(−ω·dt) v + a·dt with (ax, ay) the specific force
        # the accelerometer reads (ours; robot_localization adds a·dt alone). The exact turn keeps |v|:
        # fed back through the IMU's ω × v the first-order one grew 4 % a step at 14 rad/s (a hit)
        # whenever the wheels were held out, to thousands of m/s
        cw, sw = math.cos(x[VYAW] * dt), math.sin(x[VYAW] * dt)
        f[VX, VX], f[VX, VY], f[VY, VX], f[VY, VY] = cw, sw, -sw, cw
        f[VX, VYAW] = dt * (-sw * x[VX] + cw * x[VY])
        f[VY, VYAW] = dt * (-cw * x[VX] - sw * x[VY])
        f[VX, AX] = f[VY, AY] = dt
        moved = f @ x
        moved[X] = x[X] + (c * x[VX] - s * x[VY]) * dt + (c * x[AX] - s * x[AY]) * half
        moved[Y] = x[Y] + (s * x[VX] + c * x[VY]) * dt + (s * x[AX] + c * x[AY]) * half
        moved[VX] = cw * x[VX] + sw * x[VY] + x[AX] * dt
        moved[VY] = -sw * x[VX] + cw * x[VY] + x[AY] * dt
        moved[YAW] = wrap_angle(moved[YAW])
        self.x = moved
        self.p = f @ self.p @ f.T + self.q * dt

    def update(self, indices: list[int], z: np.ndarray, r: np.ndarray, threshold: float) -> tuple[bool, float]:
        """Update the state variables `indices` with measurement z (covariance r), unless its squared
        Mahalanobis distance reaches threshold²: (accepted, that distance²)."""
        r = r.copy()
        np.fill_diagonal(r, np.maximum(np.diag(r), MIN_VARIANCE))
        innovation = z - self.x[indices]
        for k, i in enumerate(indices):
            if i == YAW:
                innovation[k] = wrap_angle(innovation[k])
        h = np.zeros((len(indices), N))
        h[np.arange(len(indices)), indices] = 1.0
        ph = self.p[:, indices]
        s = ph[indices] + r
        try:
            s_inv = np.linalg.inv(s)
        except np.linalg.LinAlgError:
            return False, math.inf
        d2 = float(innovation @ s_inv @ innovation)
        if d2 >= threshold * threshold:
            return False, d2
        k = ph @ s_inv
        self.x = self.x + k @ innovation
        self.x[YAW] = wrap_angle(self.x[YAW])
        a = np.eye(N) - k @ h
        self.p = a @ self.p @ a.T + k @ r @ k.T
        return True, d2


@dataclass
class _Entry:
    key: tuple[int, int, int]       # stamp, source order, seq: the processing order
    source: str
    msg: Odometry | Imu
    held_out: tuple[bool, bool, bool]       # the wheels' vx, vy, vyaw doubt held out (odom0 only)
    before: tuple = ()                      # the fusion's state before this entry


@dataclass(frozen=True)
class Estimate:
    stamp_ns: int
    pose: np.ndarray                # x, y, yaw (odom frame)
    twist: np.ndarray               # vx, vy, vyaw (body frame)
    pose_covariance: np.ndarray     # 3 × 3
    twist_covariance: np.ndarray    # 3 × 3


class OdometryFusion:
    """robot_localization's EKF over the wheels (odom0), the IMU (imu0) and laser odometry (odom1),
    with lagged laser measurements and the wheels' doubt. Counts in `counters`: rejected/<source>
    (gated out), held_out/odom0 (wheel steps the doubt held something out of), too_old/<source>
    (lagged beyond history_length), slip_events."""

    def __init__(self, params: EkfParams):
        self.params = params
        self.ekf = Ekf(plane_matrix(params.process_noise_covariance), plane_matrix(params.initial_estimate_covariance))
        self.doubt = Doubt(group(params, DoubtParams), params.history_length, laser=params.uses("odom1"))
        self.counters: Counter[str] = Counter()
        self.history: list[_Entry] = []
        self.history_ns = round(params.history_length / NS)
        self._previous: dict[str, tuple[int, np.ndarray, np.ndarray]] = {}     # differential: the source's last pose
        self._first: dict[str, np.ndarray] = {}                                 # relative: the source's first pose
        self._laser_offset = np.zeros(3)            # laser track -> the filter's frame: moved by each interval set aside
        self._laser_fused: np.ndarray | None = None  # the last laser pose, through the offset
        self._replaying = False

    # ------------------------------------------------------------ inputs

    def step(self, wheels: Odometry, imus: list[Imu] = ()) -> Verdict:
        """The IMU readings up to a wheel odometry step, then the step; the doubt's verdict after it."""
        if self.ekf.stamp_ns is None and not self.history:
            # start where the wheel odometry stands: at the origin with the robot, or, for a fusion
            # restarted mid-mission, where the chassis resumed it (its state file), not back at the origin
            self.ekf.x[[X, Y, YAW]] = (wheels.pose.x, wheels.pose.y, wheels.pose.theta)
        for imu in imus:
            if self.params.uses("imu0"):
                self.doubt.imu(imu.header.stamp_ns, imu.angular_velocity_z, imu.linear_acceleration_x,
                               imu.linear_acceleration_y, imu.angular_velocity_z_variance,
                               imu.linear_acceleration_x_variance, imu.linear_acceleration_y_variance)
                self._insert("imu0", imu)
        t = wheels.header.stamp_ns
        twist = (wheels.twist.linear_x, wheels.twist.linear_y, wheels.twist.angular_z)
        pose = (wheels.pose.x, wheels.pose.y, wheels.pose.theta)
        verdict = self.doubt.wheels(t, pose, twist, wheels.twist_covariance)
        held_out = self.doubt.held_out()
        if any(held_out):
            self.counters["held_out/odom0"] += 1
        self._insert("odom0", wheels, held_out)
        self.counters["slip_events"] = self.doubt.slip_events
        return verdict

    def laser(self, msg: Odometry) -> Verdict:
        """A laser odometry pose, stamped at its scan (in the past): fused at its stamp, unless the
        doubt set its interval aside as the laser's error; then the laser track is carried on from
        where the last pose fused put it by the wheels' travel over the interval (the track's offset
        from the filter's frame changes, and later poses are fused through it)."""
        pose = np.array([msg.pose.x, msg.pose.y, msg.pose.theta])
        verdict = self.doubt.laser(msg.header.stamp_ns, pose, msg.pose_covariance)
        self.counters["slip_events"] = self.doubt.slip_events
        if self.doubt.laser_set_aside and self._laser_fused is not None:
            self._laser_offset = compose(compose(self._laser_fused, self.doubt.wheel_travel), inverse(pose))
            self.counters["laser_set_aside/odom1"] += 1
        fused = compose(self._laser_offset, pose)
        self._laser_fused = fused
        if self.params.uses("odom1") and not self.doubt.laser_set_aside:
            self._insert("odom1", replace(msg, pose=Pose2D(*map(float, fused)),
                                          pose_covariance=_rotated(np.asarray(msg.pose_covariance, float),
                                                                   float(self._laser_offset[2]))))
        return verdict

    def estimate(self) -> Estimate:
        x, p = self.ekf.x, (self.ekf.p + self.ekf.p.T) / 2
        pose_idx, twist_idx = [X, Y, YAW], [VX, VY, VYAW]
        return Estimate(self.ekf.stamp_ns or 0, x[pose_idx].copy(), x[twist_idx].copy(),
                        p[np.ix_(pose_idx, pose_idx)].copy(), p[np.ix_(twist_idx, twist_idx)].copy())

    # ------------------------------------------------------------ history

    def _insert(self, source: str, msg, held_out: tuple[bool, bool, bool] = (False, False, False)) -> None:
        entry = _Entry((msg.header.stamp_ns, SOURCES.index(source), msg.header.seq), source, msg, held_out)
        history = self.history
        if not history or entry.key > history[-1].key:
            entry.before = self._state()
            self._apply(entry)
            history.append(entry)
            self._prune()
            return
        if not self.params.smooth_lagged_data:
            self.counters[f"lagged/{source}"] += 1
            self._apply(entry)          # at the filter's time, as robot_localization does without smoothing
            return
        if any(e.key == entry.key for e in history):
            self.counters[f"duplicates/{source}"] += 1       # the same source, stamp and seq again
            return
        place = next(i for i, e in enumerate(history) if e.key > entry.key)
        if place == 0:
            self.counters[f"too_old/{source}"] += 1
            return
        self._restore(history[place].before)
        history.insert(place, entry)
        self._replaying = False
        for later in history[place:]:
            later.before = self._state()
            self._apply(later)
            self._replaying = True      # only the new entry counts its rejection
        self._replaying = False

    def _prune(self) -> None:
        oldest = self.history[-1].key[0] - self.history_ns
        drop = 0
        while drop < len(self.history) - 1 and self.history[drop].key[0] < oldest:
            drop += 1
        if drop:
            del self.history[:drop]

    def _state(self) -> tuple:
        return (self.ekf.x.copy(), self.ekf.p.copy(), self.ekf.stamp_ns, dict(self._previous), dict(self._first))

    def _restore(self, state: tuple) -> None:
        x, p, stamp, previous, first = state
        self.ekf.x, self.ekf.p, self.ekf.stamp_ns = x.copy(), p.copy(), stamp
        self._previous, self._first = dict(previous), dict(first)

    # ------------------------------------------------------------ measurements

    def _apply(self, entry: _Entry) -> None:
        before = entry.before or self._state()
        self.ekf.predict(entry.key[0])
        if entry.source == "imu0":
            self._imu(entry.msg)
        else:
            self._odometry(entry.source, entry.msg, entry.held_out)
        if not (np.isfinite(self.ekf.x).all() and np.isfinite(self.ekf.p).all()):
            # values no filter survives (a stamp decades away, an absurd reading): as if it never came
            self._restore(before)
            if not self._replaying:
                self.counters[f"non_finite/{entry.source}"] += 1
        elif (np.abs(self.ekf.x[[VX, VY]]).max() > MAX_SPEED or np.abs(self.ekf.x[[AX, AY]]).max() > MAX_ACCELERATION
              or np.diag(self.ekf.p).max() > MAX_VARIANCE):
            # finite but no robot's: a filter gone unstable must not hand the stack an absurd pose
            self._restore(before)
            if not self._replaying:
                self.counters[f"beyond_bounds/{entry.source}"] += 1

    def _update(self, source: str, indices: list[int], z, r, threshold: float) -> None:
        if not indices:
            return
        accepted, _ = self.ekf.update(indices, np.asarray(z, float), np.asarray(r, float), threshold)
        if not accepted and not self._replaying:
            self.counters[f"rejected/{source}"] += 1

    def _odometry(self, source: str, msg: Odometry, held_out: tuple[bool, bool, bool]) -> None:
        p = self.params
        vector = getattr(p, f"{source}_config")
        pose_sel = [k for k, rl in enumerate((0, 1, 5)) if vector[rl]]
        if pose_sel:
            pose = np.array([msg.pose.x, msg.pose.y, msg.pose.theta])
            cov = np.asarray(msg.pose_covariance, float)
            if getattr(p, f"{source}_relative"):
                first = self._first.setdefault(source, pose)
                pose, cov = relative(first, pose), _rotated(cov, -first[2])
            threshold = getattr(p, f"{source}_pose_rejection_threshold")
            if getattr(p, f"{source}_differential"):
                self._differential(source, msg.header.stamp_ns, pose, cov, pose_sel, threshold)
            else:
                self._update(source, [(X, Y, YAW)[k] for k in pose_sel], pose[pose_sel],
                             cov[np.ix_(pose_sel, pose_sel)], threshold)
        twist_sel = [k for k, rl in enumerate((6, 7, 11)) if vector[rl] and not held_out[k]]
        if twist_sel:
            twist = np.array([msg.twist.linear_x, msg.twist.linear_y, msg.twist.angular_z])
            cov = np.asarray(msg.twist_covariance, float)
            self._update(source, [(VX, VY, VYAW)[k] for k in twist_sel], twist[twist_sel],
                         cov[np.ix_(twist_sel, twist_sel)], getattr(p, f"{source}_twist_rejection_threshold"))

    def _differential(self, source: str, stamp_ns: int, pose: np.ndarray, cov: np.ndarray, sel: list[int],
                      threshold: float) -> None:
        """A pose turned into the velocity since the source's previous pose (in the body frame there)."""
        previous = self._previous.get(source)
        self._previous[source] = (stamp_ns, pose, cov)
        if previous is None or stamp_ns <= previous[0]:
            return
        dt = (stamp_ns - previous[0]) * NS
        velocity = relative(previous[1], pose) / dt
        velocity[2] = wrap_angle(relative(previous[1], pose)[2]) / dt
        r = _rotated(previous[2] + cov, -previous[1][2]) / (dt * dt)
        self._update(source, [(VX, VY, VYAW)[k] for k in sel], velocity[sel], r[np.ix_(sel, sel)], threshold)

    def _imu(self, msg: Imu) -> None:
        p = self.params
        vector = p.imu0_config
        if vector[11]:
            self._update("imu0", [VYAW], [msg.angular_velocity_z], [[msg.angular_velocity_z_variance]],
                         p.imu0_angular_velocity_rejection_threshold)
        accel = [(AX, msg.linear_acceleration_x, msg.linear_acceleration_x_variance, 12),
                 (AY, msg.linear_acceleration_y, msg.linear_acceleration_y_variance, 13)]
        chosen = [a for a in accel if vector[a[3]]]
        if chosen:      # the state's ax, ay are what the accelerometer reads (predict turns v with ω)
            self._update("imu0", [a[0] for a in chosen], [a[1] for a in chosen],
                         np.diag([a[2] for a in chosen]), p.imu0_linear_acceleration_rejection_threshold)


def _rotated(cov: np.ndarray, angle: float) -> np.ndarray:
    """A 3 × 3 (x, y, yaw) covariance with its x, y block turned by angle."""
    c, s = math.cos(angle), math.sin(angle)
    rot = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    return rot @ cov @ rot.T
