"""Do the wheels, the gyro and the scans agree? The odometry fusion's doubt (issue 36).

robot_localization only rejects a measurement that lies too far from its estimate. A push, a slip
or a wheel off the ground is more than one bad measurement: the wheels go on being wrong, and a
robot that believes it is somewhere else is unsafe. So the wheels are compared, each step, with
what the other sources say they should read, each comparison a Mahalanobis distance with the
sources' own noise and a tolerance for what no sensor model holds (a floor's small slip):

- yaw rate: the wheels' mean yaw rate over the last `doubt_window` against the gyro's;
- change of speed: the wheels' change of body velocity over the window against the IMU's
  acceleration summed over it (plus the centripetal term ω × v, which an accelerometer reads);
  a robot shoved while its wheels stand still shows here within the window;
- travel: the wheels' motion between two consecutive laser odometry poses against the laser's,
  with both poses' covariance (a featureless corridor's large variance along it weakens the check
  there and nowhere else), judged when the laser pose is applied, late. It alone sees a wheel
  spinning on a robot that stands (the IMU's acceleration is zero, as is the wheels' change).

Any comparison beyond `doubt_threshold` sigmas makes the estimate doubtful, with a reason naming
the sources and the size; the doubt clears after `doubt_clear_time` of sim time in which no
comparison disagreed. Each change from agreeing to doubtful is one slip event. Where laser odometry
is fused, agreement alone does not clear a doubt: the wheels, gyro and IMU agree again as soon as
the push is over, while the pose it left wrong is put right only by the scans. So the doubt clears
only once a laser interval judged after the last disagreement agreed, and never while the laser
track that began before the doubt has broken since (two consecutive laser poses more than
`doubt_laser_gap` apart: matches refused, a local map started afresh at the wheels' guess) — then
nothing has measured what the push did, and the pose stays doubtful (a navigator claims no goal on it). While a comparison
disagrees, the wheels' share of the state it tested is held out of the filter (`held_out`): the
yaw rate for the gyro, the velocities for the IMU, the whole twist for the laser (until a laser
interval agrees again), so the filter follows the gyro and the scans.

Pure: numpy and the poses' algebra; fed in processing order by the fusion (ekf.py).
"""
from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass

import numpy as np

from ...geometry.se2 import compose, relative, wrap_angle
from ...parameters.declare import Parameters, param

NS = 1e-9
MAX_DISTANCE2 = 1e12    # a squared distance beyond any doubt: what is published for a larger one (finite)


@dataclass(frozen=True)
class DoubtParams(Parameters):
    """When the fusion doubts its estimate (ours: robot_localization has no such thing)."""
    doubt_threshold: float = param(5.0, gt=0)           # sigmas (Mahalanobis distance) beyond which sources disagree
    doubt_window: float = param(0.2, gt=0)              # s of sim time the yaw rates are averaged and the accelerations summed over
    doubt_clear_time: float = param(1.0, ge=0)          # s of agreement before a doubt clears
    doubt_yaw_rate_tolerance: float = param(0.05, ge=0)  # rad/s: yaw rate differences the floor allows (a std, added to the noise)
    doubt_speed_tolerance: float = param(0.05, ge=0)    # m/s: differences in the change of speed over the window the floor allows
    doubt_acceleration_bias: float = param(0.05, ge=0)   # m/s²: the accelerometer's bias the IMU's change of speed allows
    doubt_travel_tolerance: float = param(0.02, ge=0)   # m (and rad) per laser interval, plus ...
    doubt_travel_fraction: float = param(0.1, ge=0)     # ... this share of the wheels' travel (and turn) in it
    doubt_laser_gap: float = param(0.3, gt=0)           # s between laser poses beyond which the laser track is broken
    # a laser interval that disagrees with the wheels while the gyro and the IMU agree with them is the
    # laser's error (a scan matched to a body that moved), not the wheels': set aside, not held against them
    doubt_laser_needs_inertia: bool = True


@dataclass(frozen=True)
class Verdict:
    doubtful: bool
    reason: str             # the latest disagreement, while doubtful; '' otherwise
    mahalanobis: float      # squared distance of the worst comparison of the last judgment


@dataclass
class _Check:
    """One comparison's last outcome."""
    distance2: float = 0.0
    reason: str = ""
    disagrees: bool = False


class Doubt:
    """Feed it, in processing order, every wheel odometry step (`wheels`, after the IMU readings up
    to its stamp: `imu`) and every laser odometry pose as it is applied (`laser`)."""

    wheel_vx, wheel_vy, wheel_vyaw = 0, 1, 2       # positions in `held_out`

    def __init__(self, params: DoubtParams, history_s: float, laser: bool = False):
        self.params = params
        self.expects_laser = laser                      # laser odometry is fused: only it clears a doubt
        self.threshold2 = params.doubt_threshold ** 2
        self.window_ns = round(params.doubt_window / NS)
        self.history_ns = round(max(history_s, params.doubt_window) / NS) + self.window_ns
        self._wheels: deque[tuple[int, np.ndarray, np.ndarray, np.ndarray]] = deque()   # stamp, pose, twist, twist variances
        self._imu: deque[tuple[int, float, float, float, float, float, float]] = deque()  # stamp, wz, ax, ay, variances
        self._laser: tuple[int, np.ndarray, np.ndarray] | None = None    # the previous laser pose: stamp, pose, covariance
        self.yaw, self.speed, self.travel = _Check(), _Check(), _Check()
        # (stamp, velocity, its variances, the IMU's change of speed and its variance since, last reading) where the
        # wheels' and the IMU's change of speed began to disagree
        self._anchor: tuple | None = None
        self._agreed_since_ns = -(1 << 62)
        self.doubtful = False
        self.reason = ""
        self.last_disagreement_ns: int | None = None
        self.slip_events = 0
        self.now_ns = 0
        self.laser_agreed_ns: int | None = None    # when a laser interval last agreed
        self.track_broken = False                  # the laser track broke during this doubt
        self._felt: deque[int] = deque()            # wheel steps at which the gyro or the IMU disagreed with the wheels
        self.laser_set_aside = False               # the last laser interval was the laser's error (see laser())
        self.wheel_travel: np.ndarray | None = None     # the wheels' motion over the last laser interval

    # ------------------------------------------------------------ inputs

    def imu(self, stamp_ns: int, wz: float, ax: float, ay: float, var_wz: float, var_ax: float, var_ay: float) -> None:
        self._imu.append((stamp_ns, wz, ax, ay, var_wz, var_ax, var_ay))

    def wheels(self, stamp_ns: int, pose, twist, twist_covariance) -> Verdict:
        """A wheel odometry step: judge yaw rate and change of speed over the window ending here."""
        self.now_ns = stamp_ns
        self._wheels.append((stamp_ns, np.asarray(pose, float), np.asarray(twist, float),
                             np.diag(np.asarray(twist_covariance, float)).copy()))
        while self._wheels and self._wheels[0][0] < stamp_ns - self.history_ns:
            self._wheels.popleft()
        while self._imu and self._imu[0][0] < stamp_ns - self.history_ns:
            self._imu.popleft()
        while self._felt and self._felt[0] < stamp_ns - self.history_ns:
            self._felt.popleft()
        self._judge_rates(stamp_ns)
        if self.yaw.disagrees or self.speed.disagrees:
            self._felt.append(stamp_ns)
        return self._verdict(stamp_ns)

    def laser(self, stamp_ns: int, pose, covariance) -> Verdict:
        """A laser odometry pose (stamped in the past): the wheels' travel since the previous one
        against the laser's. Where they disagree and neither the gyro nor the IMU felt anything the
        wheels did not (from a window before the interval to a window after it), the laser is wrong -
        a push or a slip moves the body, and the body's motion is what those two feel - and the
        interval is set aside (`laser_set_aside`; the fusion counts it) instead of being held
        against the wheels: the fusion then carries the laser track on by the wheels' travel."""
        pose, covariance = np.asarray(pose, float), np.asarray(covariance, float)
        previous, self._laser = self._laser, (stamp_ns, pose, covariance)
        self.laser_set_aside, self.wheel_travel = False, None
        if self.doubtful and (previous is None or (stamp_ns - previous[0]) * NS > self.params.doubt_laser_gap):
            self.track_broken = True
        if previous is not None and previous[0] < stamp_ns:
            start, end = self.wheel_pose_at(previous[0]), self.wheel_pose_at(stamp_ns)
            if start is not None and end is not None:
                self.wheel_travel = relative(start, end)
                self._judge_travel(stamp_ns - previous[0], self.wheel_travel, relative(previous[1], pose),
                                   previous[2] + covariance)
                if self.travel.disagrees and self.params.doubt_laser_needs_inertia \
                        and not self._felt_between(previous[0] - self.window_ns, stamp_ns + self.window_ns):
                    self.travel = _Check(self.travel.distance2, self.travel.reason + " (the laser's: nothing felt)")
                    self.laser_set_aside = True
        return self._verdict(self.now_ns)

    def _felt_between(self, start_ns: int, end_ns: int) -> bool:
        return any(start_ns <= t <= end_ns for t in self._felt)

    # ------------------------------------------------------------ what the fusion asks

    def held_out(self) -> tuple[bool, bool, bool]:
        """Which of the wheels' vx, vy, vyaw the filter must not take now."""
        velocities = self.speed.disagrees or self.travel.disagrees
        turn = self.yaw.disagrees or self.travel.disagrees
        return velocities, velocities, turn

    def verdict(self) -> Verdict:
        worst = max(self.yaw.distance2, self.speed.distance2, self.travel.distance2)
        return Verdict(self.doubtful, self.reason if self.doubtful else "", min(worst, MAX_DISTANCE2))

    def wheel_pose_at(self, stamp_ns: int) -> np.ndarray | None:
        """The wheel odometry's pose at a stamp within its history, interpolated; None outside it."""
        wheels = self._wheels
        if not wheels or stamp_ns < wheels[0][0] or stamp_ns > wheels[-1][0]:
            return None
        for (t0, p0, *_), (t1, p1, *_) in zip(reversed(list(wheels)[:-1]), reversed(wheels)):
            if t0 <= stamp_ns <= t1:
                f = 0.0 if t1 == t0 else (stamp_ns - t0) / (t1 - t0)
                step = relative(p0, p1)
                return p0 if f == 0.0 else _compose_fraction(p0, step, f)
        return wheels[-1][1]

    # ------------------------------------------------------------ the comparisons

    def _judge_rates(self, now_ns: int) -> None:
        p = self.params
        # a window starts after the end of the last disagreement of the change of speed: what was in it is judged
        start = max(now_ns - self.window_ns, self._agreed_since_ns)
        wheels = [w for w in self._wheels if w[0] >= start]
        imu = [i for i in self._imu if start < i[0] <= now_ns]
        if len(wheels) < 2 or not imu:
            self.yaw, self.speed = _Check(), _Check()
            return
        # yaw rate: means over the window
        wheel_wz = float(np.mean([w[2][2] for w in wheels]))
        gyro_wz = float(np.mean([i[1] for i in imu]))
        var = (float(np.mean([w[3][2] for w in wheels])) / len(wheels) + float(np.mean([i[4] for i in imu])) / len(imu)
               + p.doubt_yaw_rate_tolerance ** 2)
        diff = wheel_wz - gyro_wz
        d2 = diff * diff / max(var, 1e-18)
        self.yaw = _Check(d2, f"wheels vs gyro: yaw rate {wheel_wz:+.2f} vs {gyro_wz:+.2f} rad/s", d2 > self.threshold2)
        # change of speed: the wheels' against the IMU's acceleration summed since the window's first wheel
        # step; once they disagree, since the wheels' velocity where the disagreement began (the anchor),
        # until the wheels' velocity and that one agree again
        _, _, v1, var1 = wheels[-1]
        if self._anchor is None:
            t0, _, v0, var0 = wheels[0]
            dv, var_imu, last = self._integrate(imu, t0, t0, None)
        else:
            t0, v0, var0, dv, var_imu, last = self._anchor
            dv, var_imu, last = self._integrate(imu, last, t0, (v0, dv, var_imu))
        dv_wheels = v1[:2] - v0[:2]
        span = (now_ns - t0) * NS
        var = (var0[:2] + var1[:2] + var_imu + p.doubt_speed_tolerance ** 2
               + (p.doubt_acceleration_bias * span) ** 2)
        d2 = float(np.sum((dv_wheels - dv) ** 2 / np.maximum(var, 1e-18)))
        # hysteresis: a disagreement ends when the two are within one sigma again, not just under the threshold
        disagrees = d2 > (1.0 if self._anchor is not None else self.threshold2)
        self.speed = _Check(d2, f"wheels vs IMU: change of speed ({dv_wheels[0]:+.2f}, {dv_wheels[1]:+.2f}) vs "
                                f"({dv[0]:+.2f}, {dv[1]:+.2f}) m/s over {span:.2f} s", disagrees)
        if self._anchor is not None and not disagrees:
            self._agreed_since_ns = now_ns
        self._anchor = (t0, v0, var0, dv, var_imu, last) if disagrees else None

    def _integrate(self, imu, after_ns: int, start_ns: int, anchored) -> tuple[np.ndarray, np.ndarray, int]:
        """The IMU's change of body velocity from readings stamped after `after_ns` (the sum so far when
        anchored), its variance, and the last reading's stamp. The accelerometer reads dv/dt + ω × v:
        the rotation of the frame is taken out with the wheels' velocity, or, anchored (the wheels in
        doubt), with the anchor's velocity plus the change so far - turned by the step's rotation, not
        a first-order term: fed back over a long doubt, ω·dt = 0.14 (a robot spun at 14 rad/s by a
        hit) grew the first-order sum 1 % a step until it overflowed."""
        dv, var = (np.zeros(2), np.zeros(2)) if anchored is None else (anchored[1].copy(), anchored[2].copy())
        previous = after_ns
        for stamp, wz, ax, ay, _, var_ax, var_ay in imu:
            if stamp <= after_ns:
                continue
            dt = (stamp - max(previous, start_ns)) * NS
            previous = stamp
            v = self._wheel_twist_at(stamp)[:2] if anchored is None else anchored[0][:2] + dv
            c, s = math.cos(wz * dt), math.sin(wz * dt)
            dv += np.array([c * v[0] + s * v[1] + ax * dt, c * v[1] - s * v[0] + ay * dt]) - v
            var += np.array([var_ax, var_ay]) * dt * dt
        return dv, var, previous

    def _wheel_twist_at(self, stamp_ns: int) -> np.ndarray:
        for w in reversed(self._wheels):
            if w[0] <= stamp_ns:
                return w[2]
        return self._wheels[0][2]

    def _judge_travel(self, span_ns: int, wheels: np.ndarray, laser: np.ndarray, covariance: np.ndarray) -> None:
        p = self.params
        error = wheels - laser
        error[2] = float(wrap_angle(error[2]))
        tolerance = np.array([p.doubt_travel_tolerance + p.doubt_travel_fraction * math.hypot(wheels[0], wheels[1])] * 2
                             + [p.doubt_travel_tolerance + p.doubt_travel_fraction * abs(wheels[2])])
        s = covariance + np.diag(tolerance ** 2)
        d2 = float(error @ np.linalg.solve(s, error))
        self.travel = _Check(d2, f"wheels vs laser odometry: {math.hypot(error[0], error[1]):.2f} m, "
                                 f"{abs(error[2]):.2f} rad apart over {span_ns * NS:.2f} s", d2 > self.threshold2)
        if not self.travel.disagrees:
            self.laser_agreed_ns = self.now_ns

    def _verdict(self, now_ns: int) -> Verdict:
        disagreeing = [c for c in (self.yaw, self.speed, self.travel) if c.disagrees]
        if disagreeing:
            worst = max(disagreeing, key=lambda c: c.distance2)
            self.reason = f"{worst.reason} ({math.sqrt(worst.distance2):.1f} sigma)"
            self.last_disagreement_ns = now_ns
            if not self.doubtful:
                self.doubtful, self.track_broken = True, False
                self.slip_events += 1
        elif self.doubtful and now_ns - self.last_disagreement_ns >= round(self.params.doubt_clear_time / NS) \
                and self._confirmed_by_the_scans():
            self.doubtful = False
        if self.doubtful and self.track_broken and "scans lost track" not in self.reason:
            self.reason += "; the scans lost track since, nothing has measured what it did"
        return self.verdict()

    def _confirmed_by_the_scans(self) -> bool:
        if not self.expects_laser:
            return True
        return (not self.track_broken and self.laser_agreed_ns is not None
                and self.laser_agreed_ns > self.last_disagreement_ns)


def _compose_fraction(pose: np.ndarray, step: np.ndarray, f: float) -> np.ndarray:
    """The pose a fraction f along a (short) step from `pose`: linear in the step's components."""
    return compose(pose, step * f)
