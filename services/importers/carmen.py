"""CARMEN log files (the format of the Radish / Freiburg SLAM benchmark logs) as omninav messages.

Each line is one message: a type word, then space-separated fields. The types read here, with the
fields CARMEN's logger documents (angles in rad, distances in m, times in s):

  FLASER / RLASER  n r1..rn  x y theta  odom_x odom_y odom_theta  ipc_timestamp ipc_hostname logger_timestamp
      the front / rear laser; (x, y, theta) is the laser's pose, (odom_x, odom_y, odom_theta) the
      robot's, both by raw odometry. The field of view is not in the line: CARMEN guesses it from
      n (180 or 181 beams: 1 degree apart, 360 or 361: 0.5, 400 or 401: 0.25, else 180 degrees in
      n − 1 steps), starting at −90 degrees.
  ODOM  x y theta tv rv accel  ipc_timestamp ipc_hostname logger_timestamp
  RAWLASER1..4  laser_type start_angle field_of_view angular_resolution maximum_range accuracy
      remission_mode  n r1..rn  m e1..em  ipc_timestamp ipc_hostname logger_timestamp
  ROBOTLASER1..2  (as RAWLASER up to the remissions)  laser_x laser_y laser_theta  robot_x robot_y
      robot_theta  tv rv forward_safety_dist side_safety_dist turn_axis  ipc_timestamp ipc_hostname
      logger_timestamp

Stamps come from ipc_timestamp (converted to integer nanoseconds digit by digit, so they match the
relation files' times). Ranges at or beyond the laser's maximum become +inf (no return, REP 117);
ranges at or below zero become NaN (not a measurement). A laser line that carries the robot's
odometric pose also yields an Odometry at the same stamp, so SLAM can be replayed on a log that
has no ODOM lines.

Lines starting with '#' are comments. Every other line type (PARAM, SYNC, TRUEPOS, ...) is counted
and skipped; a line that cannot be read is counted with its line number, never fatal.
"""
from __future__ import annotations

import math
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ...schemas.messages import Header, LaserScan, Odometry, Pose2D, Twist
from ...geometry.se2 import relative

# The SICK LMS code for "no return" in the FLASER lines of the benchmark logs (81.91 m).
FLASER_MAX_RANGE = 81.91
# laser number -> line types that carry that laser, most complete first
LASER_LINE_TYPES = {1: ("ROBOTLASER1", "FLASER", "RAWLASER1"), 2: ("ROBOTLASER2", "RLASER", "RAWLASER2"),
                    3: ("RAWLASER3",), 4: ("RAWLASER4",)}
NEW_LASER_TYPES = frozenset(t for types in LASER_LINE_TYPES.values() for t in types if t[-1].isdigit())
_LASER_FRAMES = {1: "laser", 2: "rear_laser", 3: "laser3", 4: "laser4"}


class CarmenError(ValueError):
    """A CARMEN log that cannot be read at all (missing file, nothing usable in it)."""


class _BadLine(ValueError):
    pass


@dataclass
class CarmenScan:
    """One laser line: the scan, and where the log says the laser and the robot were."""

    line_type: str
    line_number: int
    laser: int                       # 1 front, 2 rear, 3..4 further lasers
    scan: LaserScan
    robot_pose: np.ndarray | None    # (3,) odometric robot pose, if the line has one
    laser_offset: np.ndarray | None  # (3,) the laser's pose in the robot frame, if the line says


@dataclass
class CarmenLog:
    scans: list[CarmenScan] = field(default_factory=list)
    odometry: list[Odometry] = field(default_factory=list)      # from ODOM and from laser lines
    skipped: Counter = field(default_factory=Counter)          # line type -> lines not converted
    damaged: list[tuple[int, str]] = field(default_factory=list)  # (line number, what is wrong)
    comments: int = 0

    def laser_scans(self, laser: int = 1) -> list[CarmenScan]:
        """The scans of one laser, from the most complete line type the log has for it (new
        CARMEN logs write the same scan as ROBOTLASER1 and FLASER)."""
        for line_type in LASER_LINE_TYPES[laser]:
            chosen = [s for s in self.scans if s.line_type == line_type]
            if chosen:
                return chosen
        return []


def stamp_ns(text: str) -> int:
    """Seconds as written ('1134864629.895182') to integer nanoseconds, without float rounding."""
    whole, _, frac = text.partition(".")
    if not whole.lstrip("-").isdigit() or (frac and not frac.isdigit()):
        raise _BadLine(f"timestamp {text!r} is not a number of seconds")
    sign = -1 if whole.startswith("-") else 1
    return sign * (abs(int(whole)) * 1_000_000_000 + int((frac + "000000000")[:9]))


class _Fields:
    """The fields of one line, read left to right; every read names what was expected."""

    def __init__(self, tokens: list[str]):
        self.tokens, self.pos = tokens, 1

    def take(self, what: str) -> str:
        if self.pos >= len(self.tokens):
            raise _BadLine(f"line ends before {what}")
        self.pos += 1
        return self.tokens[self.pos - 1]

    def real(self, what: str) -> float:
        raw = self.take(what)
        try:
            value = float(raw)
        except ValueError:
            raise _BadLine(f"{what} {raw!r} is not a number") from None
        if not math.isfinite(value):
            raise _BadLine(f"{what} {raw!r} is not finite")
        return value

    def count(self, what: str) -> int:
        raw = self.take(what)
        if not raw.isdigit():
            raise _BadLine(f"{what} {raw!r} is not a count")
        return int(raw)

    def reals(self, n: int, what: str) -> np.ndarray:
        if self.pos + n > len(self.tokens):
            raise _BadLine(f"{what}: {n} values announced, {len(self.tokens) - self.pos} fields left")
        try:
            values = np.array(self.tokens[self.pos:self.pos + n], np.float64)
        except ValueError:
            raise _BadLine(f"{what}: a value is not a number") from None
        self.pos += n
        return values

    def pose(self, what: str) -> np.ndarray:
        return np.array([self.real(f"{what} x"), self.real(f"{what} y"), self.real(f"{what} theta")])

    def stamps(self) -> int:
        """ipc_timestamp ipc_hostname logger_timestamp, which end every line; returns the first."""
        ipc = stamp_ns(self.take("ipc_timestamp"))
        self.take("ipc_hostname")
        self.real("logger_timestamp")
        if self.pos != len(self.tokens):
            raise _BadLine(f"{len(self.tokens) - self.pos} unexpected fields after logger_timestamp")
        return ipc


def guess_fov_and_increment(n: int) -> tuple[float, float]:
    """CARMEN's guess for a laser line that does not state its geometry (a SICK scanner)."""
    increments = {180: 1.0, 181: 1.0, 360: 0.5, 361: 0.5, 400: 0.25, 401: 0.25}
    fov = math.radians(100.0) if n in (400, 401) else math.pi
    if n in increments:
        return fov, math.radians(increments[n])
    return fov, fov / max(n - 1, 1)


def _ranges(raw: np.ndarray, max_range: float) -> np.ndarray:
    ranges = raw.astype(np.float32)
    ranges[raw >= max_range] = np.inf
    ranges[raw <= 0.0] = np.nan
    return ranges


def _laser_scan(stamp: int, frame: str, angle_min: float, increment: float, raw: np.ndarray,
                max_range: float, remissions: np.ndarray | None = None) -> LaserScan:
    return LaserScan(header=Header(stamp_ns=stamp, frame_id=frame), angle_min=angle_min,
                     angle_max=angle_min + (len(raw) - 1) * increment, angle_increment=increment,
                     range_min=0.0, range_max=max_range, ranges=_ranges(raw, max_range),
                     intensities=np.asarray(remissions if remissions is not None else [], np.float32))


def _odometry(stamp: int, pose: np.ndarray, tv: float = 0.0, rv: float = 0.0) -> Odometry:
    return Odometry(header=Header(stamp_ns=stamp, frame_id="odom"), pose=Pose2D(*map(float, pose)),
                    twist=Twist(header=Header(stamp_ns=stamp, frame_id="base_link"), linear_x=tv, angular_z=rv))


def _old_laser(f: _Fields, line_type: str, number: int, max_range: float):
    n = f.count("num_readings")
    raw = f.reals(n, "range_readings")
    laser_pose, robot_pose = f.pose("laser pose"), f.pose("odom")
    stamp = f.stamps()
    laser = 1 if line_type == "FLASER" else 2
    fov, increment = guess_fov_and_increment(n)
    scan = _laser_scan(stamp, _LASER_FRAMES[laser], -fov / 2, increment, raw, max_range)
    return CarmenScan(line_type, number, laser, scan, robot_pose, relative(robot_pose, laser_pose))


def _new_laser(f: _Fields, line_type: str, number: int):
    """RAWLASERn and ROBOTLASERn share their first fields; ROBOTLASER adds poses and motion."""
    f.real("laser_type")
    start_angle = f.real("start_angle")
    f.real("field_of_view")  # implied by the beam count and the resolution
    resolution, max_range = f.real("angular_resolution"), f.real("maximum_range")
    f.real("accuracy")
    f.real("remission_mode")
    raw = f.reals(f.count("num_readings"), "range_readings")
    remissions = f.reals(f.count("num_remissions"), "remission_values")
    if len(remissions) != len(raw):
        remissions = None  # intensities must be per beam or absent
    robot_pose = offset = None
    if line_type.startswith("ROBOTLASER"):
        laser_pose, robot_pose = f.pose("laser pose"), f.pose("robot pose")
        for what in ("tv", "rv", "forward_safety_dist", "side_safety_dist", "turn_axis"):
            f.real(what)
        offset = relative(robot_pose, laser_pose)
    stamp = f.stamps()
    laser = int(line_type[-1])
    scan = _laser_scan(stamp, _LASER_FRAMES[laser], start_angle, resolution, raw, max_range, remissions)
    return CarmenScan(line_type, number, laser, scan, robot_pose, offset)


def parse_lines(lines, flaser_max_range: float = FLASER_MAX_RANGE) -> CarmenLog:
    """Read CARMEN log lines (an iterable of str) into a CarmenLog."""
    log = CarmenLog()
    for number, line in enumerate(lines, start=1):
        tokens = line.split()
        if not tokens:
            continue
        if tokens[0].startswith("#"):
            log.comments += 1
            continue
        line_type, f = tokens[0], _Fields(tokens)
        try:
            if line_type in ("FLASER", "RLASER"):
                item = _old_laser(f, line_type, number, flaser_max_range)
            elif line_type in NEW_LASER_TYPES:
                item = _new_laser(f, line_type, number)
            elif line_type == "ODOM":
                pose = f.pose("odom")
                tv, rv = f.real("tv"), f.real("rv")
                f.real("accel")
                log.odometry.append(_odometry(f.stamps(), pose, tv, rv))
                continue
            else:
                log.skipped[line_type] += 1
                continue
        except _BadLine as exc:
            log.damaged.append((number, f"{line_type}: {exc}"))
            continue
        log.scans.append(item)
        if item.robot_pose is not None:
            log.odometry.append(_odometry(item.scan.header.stamp_ns, item.robot_pose))
    log.odometry.sort(key=lambda o: o.header.stamp_ns)
    return log


def read_log(path: str | Path, flaser_max_range: float = FLASER_MAX_RANGE) -> CarmenLog:
    """Parse a CARMEN log file; CarmenError if it is missing or holds no laser or odometry line."""
    path = Path(path)
    if not path.is_file():
        raise CarmenError(f"{path}: no such file")
    with open(path, encoding="utf-8", errors="replace") as lines:
        log = parse_lines(lines, flaser_max_range)
    if not log.scans and not log.odometry:
        what = f"; {len(log.damaged)} damaged lines, first: line {log.damaged[0][0]}: {log.damaged[0][1]}" \
            if log.damaged else ""
        raise CarmenError(f"{path}: no laser or odometry lines in this file{what}")
    return log
