"""The localizer service: ROS amcl's node around the AMCL core (filter.py).

Inputs, in merge order: odom and scan (synced), then map, initialpose and global_localization
(sporadic). A scan stamped t is used once odometry stamped ≥ t has come: the odometry pose at t is
interpolated between the two odometry messages around it, so the filter sees where the robot was
when the scan was taken, whatever the rates of the two streams.

A sporadic message stamped t takes effect at the first scan stamped after t + request_delay_s (as
the chassis defers cmd_vel): whether it reached the node before or after the scans stamped in
(t, t + delay] cannot change the outputs, so a live run replays byte for byte. An initial pose is
the pose at its stamp and is carried to the scan by the odometry in between, as amcl does.

Outputs, all stamped with the scan's time: `pose` (PoseWithCovariance in the map frame) after each
filter update, `particlecloud` after updates at most gui_publish_rate times per sim second, and on
every scan `pose_fit` (PoseFit: the share of the scan's returns on mapped obstacles at the pose)
and `tf/map_odom` (post-dated by transform_tolerance, as amcl's tf). `get` on the pose
key answers the last pose. With pose_file set, the pose is written there at most save_pose_rate
times per sim second, as amcl's parameters (initial_pose_*, initial_cov_*) plus the odometry pose
at the same stamp (odom_*), and a localizer started with that file resumes from it: the saved pose
carried by the odometry from then to its first scan, so the robot may keep driving while the
localizer is down (the costmap and the planners carry the last map→odom meanwhile).

The map comes from map_file (a map_server YAML, read at start: amcl's static_map service) or from
the map key (the map server's latched map). With map_file, the map key is read only when
use_map_topic is true. first_map_only keeps the first map; any later map restarts the filter at the
last estimate (with the initial covariance), as amcl does.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from ...schemas import MessageError
from ...schemas.messages import (Diagnostic, Header, LaserScan, OccupancyGrid, Odometry, ParticleCloud, Pose2D,
                                 PoseFit, PoseWithCovariance, Transform)
from ..map_server.mapio import MapError, load_map
from ..runtime.deferred import Deferred
from ..runtime.node import NS_PER_S, Node
from ...parameters.declare import ParamError, param
from ..runtime.state_file import read_state, write_state
from ...geometry.odometry_history import OdomHistory
from ...geometry.se2 import compose, relative
from .filter import Amcl, warm_up
from .params import AmclParams
from .sensor import ScanBeams, scan_beams

MAX_PENDING_SCANS = 100     # scans waiting for odometry; beyond this the oldest are dropped
_MAP, _INITIALPOSE, _GLOBAL = 0, 1, 2   # request kinds, in input order (the order of equal stamps)


@dataclass(frozen=True)
class LocalizerParams(AmclParams):
    """ROS amcl's parameters plus what the node needs around the core."""
    map_file: str = ""                         # map_server YAML read at start; "": wait for the map key
    laser_x: float = 0.0                       # m, the laser's pose in base_link (there is no tf tree here)
    laser_y: float = 0.0
    laser_yaw: float = 0.0                     # rad
    seed: int = param(0, ge=0)                 # of the filter's random generator
    pose_file: str = ""                        # where save_pose_rate keeps the last pose; "": nowhere
    request_delay_s: float = param(0.2, ge=0)  # sim s from a map / initialpose / global_localization stamp to its effect
    odom_history_s: float = param(2.0, ge=0)   # sim s of odometry kept for interpolation and initial poses


@dataclass(frozen=True)
class SavedPose:
    """What save_pose_rate writes: the pose under amcl's own parameter names, and where the
    odometry put the robot at the same stamp (to carry the pose over the time the localizer was down)."""
    initial_pose_x: float
    initial_pose_y: float
    initial_pose_a: float
    initial_cov_xx: float
    initial_cov_yy: float
    initial_cov_aa: float
    odom_x: float
    odom_y: float
    odom_a: float


def read_saved_pose(path: str | Path) -> SavedPose:
    """The pose a localizer saved (ParamError naming the file if it is damaged)."""
    return read_state(SavedPose, path)


def write_saved_pose(path: str | Path, pose: SavedPose) -> None:
    write_state(path, pose, "the localizer's last pose (amcl parameters) and the odometry at its stamp")


class LocalizerNode(Node):
    service = "localizer"
    Params = LocalizerParams
    state_files = ("pose_file",)

    def setup(self) -> None:
        p = self.params
        warm_up()   # compile (or load) the filter's kernels now, never inside a cycle
        self.rng = np.random.default_rng(p.seed)
        self.amcl: Amcl | None = None
        self.laser_pose = (p.laser_x, p.laser_y, p.laser_yaw)
        self.odom = OdomHistory(round((p.odom_history_s + p.request_delay_s) * NS_PER_S))
        self.scans: list[tuple[int, ScanBeams]] = []          # waiting for odometry past their stamp
        self.requests = Deferred(p.request_delay_s)   # map, initial pose and global localization requests not yet due
        self.resumed: tuple | None = None                      # (pose, covariance, odometry) read from pose_file
        self.start: tuple | None = self._resume()              # how the next filter starts, if not as params say
        self.last_pose: PoseWithCovariance | None = None
        self.last_cloud_ns: int | None = None
        self.last_save_ns: int | None = None
        self.std_high = False
        self.pose_pub = self.publisher("pose")
        self.cloud_pub = self.publisher("particlecloud")
        self.tf_pub = self.publisher("tf/map_odom")
        self.fit_pub = self.publisher("pose_fit")
        self.beam_fit: float | None = None   # of the last scan
        self.keys_in = {name: self.keys.resolve(name) for name in ("odom", "scan", "map")}
        self.subscribe("odom", self.on_odom)
        self.subscribe("scan", self.on_scan)
        if not p.map_file or p.use_map_topic:
            self.subscribe_deferred("map", self.requests, _MAP)
        self.subscribe_deferred("initialpose", self.requests, _INITIALPOSE, self._initialpose_problem)
        self.subscribe_deferred("global_localization", self.requests, _GLOBAL)
        self.queryable("pose", lambda _params: self.last_pose)
        if p.map_file:
            try:
                self._set_map(load_map(p.map_file))
            except MapError as exc:
                raise ValueError(f"parameter 'map_file': {exc}") from None

    def _resume(self) -> tuple | None:
        path = self.params.pose_file
        if not path or not Path(path).exists():
            return None
        try:
            saved = read_saved_pose(path)
        except ParamError as exc:
            self.log.warning("not resuming from the saved pose: %s", exc)
            return None
        self.log.info("resuming from the pose saved in %s", path)
        self.counters["resumed_from_pose_file"] += 1
        p = self.params
        # no more certain than a fresh start: a filter begun on a cloud much tighter than its initial
        # covariance (a converged one's, ~3 cm) loses its weights and injects random poses until lost
        variances = np.maximum([saved.initial_cov_xx, saved.initial_cov_yy, saved.initial_cov_aa],
                               [p.initial_cov_xx, p.initial_cov_yy, p.initial_cov_aa])
        self.resumed = (np.array([saved.initial_pose_x, saved.initial_pose_y, saved.initial_pose_a]),
                        np.diag(variances), np.array([saved.odom_x, saved.odom_y, saved.odom_a]))
        return ("pose", *self.resumed[:2])

    # ------------------------------------------------------------ inputs

    def on_odom(self, msg: Odometry) -> None:
        stamp, latest = msg.header.stamp_ns, self.odom.latest
        if latest is not None and stamp < latest:
            self.reject(self.keys_in["odom"], MessageError(
                f"stamp {stamp} ns is before the previous odometry's {latest} ns", type_name="Odometry",
                key=self.keys_in["odom"]))
            return
        self.odom.add(stamp, np.array([msg.pose.x, msg.pose.y, msg.pose.theta]))
        self._localize_waiting_scans()

    def on_scan(self, msg: LaserScan) -> None:
        key = self.keys_in["scan"]
        try:
            if msg.ranges.size < 2 or not msg.angle_increment:
                raise ValueError(f"{msg.ranges.size} ranges with angle_increment {msg.angle_increment}: "
                                 "not a scan the laser model can use")
            beams = scan_beams(msg, self.params, self.laser_pose)
        except ValueError as exc:
            self.reject(key, MessageError(str(exc), type_name="LaserScan", key=key))
            return
        self.scans.append((msg.header.stamp_ns, beams))
        if len(self.scans) > MAX_PENDING_SCANS:
            self.scans.pop(0)
            self.counters["scans_dropped_waiting_for_odometry"] += 1
        self._localize_waiting_scans()   # odometry at the scan's stamp may have come first

    def _localize_waiting_scans(self) -> None:
        latest = self.odom.latest
        while self.scans and latest is not None and self.scans[0][0] <= latest:
            scan_stamp, beams = self.scans.pop(0)
            odom = self.odom.at(scan_stamp)
            if odom is None:
                self.counters["scans_before_odometry"] += 1
            else:
                self._localize(scan_stamp, beams, odom)

    def _initialpose_problem(self, msg: PoseWithCovariance) -> str:
        if msg.header.frame_id not in ("", self.params.global_frame_id):
            return f"frame {msg.header.frame_id!r}, but the localizer works in {self.params.global_frame_id!r}"
        if not np.allclose(msg.covariance, msg.covariance.T) or np.linalg.eigvalsh(msg.covariance).min() < -1e-12:
            return "covariance is not symmetric positive semi-definite"
        return ""

    # ------------------------------------------------------------ the filter

    def _carry_resumed_pose(self, odom: np.ndarray) -> None:
        """At the first scan after resuming: the saved pose moved on by the odometry since it was saved
        (the robot drove on while no localizer ran), as an initial pose is carried to its scan."""
        (pose, cov, then), self.resumed = self.resumed, None
        self._start_filter(("pose", compose(pose, relative(then, odom)), cov))

    def _apply_requests(self, stamp_ns: int, odom: np.ndarray) -> None:
        for kind, msg in self.requests.due(stamp_ns):
            sent = msg.header.stamp_ns
            if kind == _MAP:
                self._set_map(msg)
            elif kind == _GLOBAL:
                self.counters["global_localizations"] += 1
                self._start_filter(("global",))
            else:
                self.counters["initial_poses"] += 1
                pose = np.array([msg.pose.x, msg.pose.y, msg.pose.theta])
                then = self.odom.at(sent)
                if then is None:
                    self.counters["initial_poses_without_odometry_at_stamp"] += 1
                else:   # where that pose has got to by now
                    pose = compose(pose, relative(then, odom))
                self._start_filter(("pose", pose, msg.covariance.copy()))

    def _set_map(self, grid: OccupancyGrid) -> None:
        key = self.keys_in["map"]
        if self.amcl is not None and self.params.first_map_only:
            self.counters["maps_ignored_first_map_only"] += 1
            return
        if self.amcl is not None and self.last_pose is not None:
            p = self.params
            self.start = ("pose", np.array([self.last_pose.pose.x, self.last_pose.pose.y, self.last_pose.pose.theta]),
                          np.diag([p.initial_cov_xx, p.initial_cov_yy, p.initial_cov_aa]))
        try:
            self.amcl = Amcl(self._start_params(), grid, self.rng)
        except ValueError as exc:
            self.reject(key, MessageError(str(exc), type_name="OccupancyGrid", key=key))
            return
        self.counters["maps"] += 1
        if self.start is not None and self.start[0] == "global":
            self.amcl.global_localization()
        self.start = None
        if self.params.force_update_after_set_map:
            self.amcl.request_nomotion_update()

    def _start_params(self) -> AmclParams:
        if self.start is None or self.start[0] != "pose":
            return self.params
        (x, y, a), cov = self.start[1], self.start[2]
        variances = np.maximum(np.diag(cov), 0.0)   # rounding can leave a zero variance at −1e-17
        return replace(self.params, initial_pose_x=float(x), initial_pose_y=float(y), initial_pose_a=float(a),
                       initial_cov_xx=float(variances[0]), initial_cov_yy=float(variances[1]),
                       initial_cov_aa=float(variances[2]))

    def _start_filter(self, how: tuple) -> None:
        """Re-initialise the particles now, or remember how to when the map comes."""
        if self.amcl is None:
            self.start = how
        elif how[0] == "global":
            self.amcl.global_localization()
        else:
            self.amcl.set_initial_pose(how[1], how[2])

    def _localize(self, stamp_ns: int, beams: ScanBeams, odom: np.ndarray) -> None:
        if self.resumed is not None:
            self._carry_resumed_pose(odom)
        self._apply_requests(stamp_ns, odom)
        if self.amcl is None:
            self.counters["scans_without_map"] += 1
            return
        amcl, p = self.amcl, self.params
        if amcl.update(odom, beams, stamp_ns / NS_PER_S):
            self.counters["filter_updates"] += 1
            if amcl.resampled and amcl.injected:
                self.counters["random_poses_injected"] += amcl.injected
            self._publish_pose(stamp_ns, odom)
            if p.gui_publish_rate > 0 and (self.last_cloud_ns is None
                                           or stamp_ns - self.last_cloud_ns >= NS_PER_S / p.gui_publish_rate):
                self.last_cloud_ns = stamp_ns
                self.cloud_pub.publish(ParticleCloud(header=Header(stamp_ns=stamp_ns, frame_id=p.global_frame_id),
                                                     poses=amcl.poses.copy(), weights=amcl.weights.copy()))
        self._publish_fit(stamp_ns, beams, amcl.pose_at(odom))
        if p.tf_broadcast:
            x, y, theta = (float(v) for v in amcl.map_to_odom())
            self.tf_pub.publish(Transform(
                header=Header(stamp_ns=stamp_ns + round(p.transform_tolerance * NS_PER_S), frame_id=p.global_frame_id),
                child_frame_id=p.odom_frame_id, transform=Pose2D(x, y, theta)))

    def _publish_fit(self, stamp_ns: int, beams: ScanBeams, pose: np.ndarray) -> None:
        """How well this scan fits the map where the localizer puts the robot now (the estimate
        carried by the odometry), so a shove shows at the next scan, filter update or not."""
        fit, count = self.amcl.laser.beam_fit(pose, beams)
        if not count:
            return
        self.beam_fit = fit
        self.fit_pub.publish(PoseFit(header=Header(stamp_ns=stamp_ns, frame_id=self.params.global_frame_id),
                                     beam_fit=fit, beams=count))

    def _publish_pose(self, stamp_ns: int, odom: np.ndarray) -> None:
        p, estimate = self.params, self.amcl.estimate()
        x, y, theta = (float(v) for v in estimate.pose)
        self.last_pose = PoseWithCovariance(header=Header(stamp_ns=stamp_ns, frame_id=p.global_frame_id),
                                            pose=Pose2D(x, y, theta), covariance=estimate.covariance.copy())
        self.pose_pub.publish(self.last_pose)
        cov = estimate.covariance
        high = (cov[0, 0] > p.std_warn_level_x ** 2 or cov[1, 1] > p.std_warn_level_y ** 2
                or cov[2, 2] > p.std_warn_level_yaw ** 2)
        if high:
            self.counters["pose_std_above_warn_level"] += 1
            if not self.std_high:
                self.log.warning("pose uncertain: std x %.2f m, y %.2f m, yaw %.2f rad (std_warn_level_*)",
                                 math.sqrt(max(cov[0, 0], 0.0)), math.sqrt(max(cov[1, 1], 0.0)), math.sqrt(cov[2, 2]))
        self.std_high = high
        if p.pose_file and p.save_pose_rate > 0 and (
                self.last_save_ns is None or stamp_ns - self.last_save_ns >= NS_PER_S / p.save_pose_rate):
            self.last_save_ns = stamp_ns
            try:
                write_saved_pose(p.pose_file, SavedPose(x, y, theta, *np.maximum(np.diag(cov), 0.0), *odom))
            except OSError as exc:
                self.counters["pose_file_errors"] += 1
                if self.counters["pose_file_errors"] == 1:
                    self.log.warning("cannot save the pose to %s: %s", p.pose_file, exc)

    def diagnostic(self) -> Diagnostic:
        diag = super().diagnostic()
        if self.amcl is not None:
            diag.values.update(particles=self.amcl.n, w_slow=self.amcl.w_slow, w_fast=self.amcl.w_fast)
        if self.beam_fit is not None:
            diag.values["beam_fit"] = self.beam_fit
        return diag
