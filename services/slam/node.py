"""The slam service: gmapping's node around the RBPF core (rbpf.py), or hector_mapping's around
hector's (hector.py) with `method: hector`.

Inputs, in merge order: odom and scan (synced). With `method: hector` the node subscribes to odom
only when use_tf_pose_start_estimate (hector_mapping's name) asks for odometry as the match's first
guess; otherwise each scan is processed as it comes and no map → odom is published. A scan
stamped t is used once odometry stamped ≥ t has come; the odometry pose at t is interpolated
between the two odometry messages around it (OdomHistory, shared with the localizer), so the filter
sees where the robot was when the scan was taken. In the sim both come at every step, so the odometry at the scan's own stamp is used as is.

The filter is built at the first usable scan (its beam angles and range_max fix the laser model);
a later scan with another beam count is rejected as malformed, as are scans no laser model can use
and odometry that goes back in time.

Outputs: on every scan, `pose` (the best particle's PoseWithCovariance in the map frame; the
covariance is the particles' weighted spread, or hector's Gauss-Newton's) and `tf/map_odom`; every
map_update_interval of sim time, `map` (the best particle's OccupancyGrid, or hector's finest grid,
cropped to what was seen), as gmapping does. `get` on map answers the current map, `get` on pose the last pose.

The map frame: the core's convention is the robot's pose at the first scan. initial_pose_x/y/a
place that first pose elsewhere; in the sim, set them to the world's start pose (`omninav map
build` does) and the map frame is the world frame, so the map lines up with the true occupancy.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ...schemas import MessageError
from ...schemas.messages import Header, LaserScan, OccupancyGrid, Odometry, Pose2D, PoseWithCovariance, Transform
from ...geometry.odometry_history import OdomHistory, WaitingForOdometry
from ..runtime.node import NS_PER_S, Node
from .hector import HectorParams, HectorSlam
from .params import SlamParams
from .rbpf import Rbpf
from ...parameters.declare import param

METHODS = ("rbpf", "hector")


@dataclass(frozen=True)
class SlamNodeParams(SlamParams, HectorParams):
    """SlamParams and HectorParams plus what the node needs around the cores (gmapping's frame names)."""
    method: str = param("rbpf", choices=METHODS)     # the gmapping-class filter, or hector mapping
    use_tf_pose_start_estimate: bool = False         # hector: odometry as each match's first guess
    initial_pose_x: float = param(0.0, finite=True)  # m, m, rad: the map-frame pose of the robot at the first scan
    initial_pose_y: float = param(0.0, finite=True)
    initial_pose_a: float = param(0.0, finite=True)
    map_frame: str = param("map", nonempty=True)
    odom_frame: str = param("odom", nonempty=True)
    odom_history_s: float = param(2.0, ge=0)         # sim s of odometry kept for interpolation
    map_update_interval: float = param(5.0, gt=0)    # s of sim time between published maps


class SlamNode(Node):
    service = "slam"
    Params = SlamNodeParams

    def setup(self) -> None:
        p = self.params
        self.slam: Rbpf | HectorSlam | None = None
        self.uses_odometry = p.method == "rbpf" or p.use_tf_pose_start_estimate
        self.n_beams = 0
        self.odom = OdomHistory(round(p.odom_history_s * NS_PER_S))
        self.scans = WaitingForOdometry(self.odom)               # ranges waiting for odometry past their stamp
        self.last_pose: PoseWithCovariance | None = None
        self._map: tuple[int, OccupancyGrid] | None = None      # (filter updates, map) of the last map made
        self.map_pub = self.publisher("map")
        self.pose_pub = self.publisher("pose")
        self.tf_pub = self.publisher("tf/map_odom")
        self.keys_in = {name: self.keys.resolve(name) for name in ("odom", "scan")}
        if self.uses_odometry:
            self.subscribe("odom", self.on_odom)
        self.subscribe("scan", self.on_scan)
        self.queryable("map", lambda _params: self.current_map())
        self.queryable("pose", lambda _params: self.last_pose)
        self.every(p.map_update_interval, self.publish_map)

    # ------------------------------------------------------------ inputs

    def on_odom(self, msg: Odometry) -> None:
        stamp, latest = msg.header.stamp_ns, self.odom.latest
        if latest is not None and stamp < latest:
            self._reject("odom", f"stamp {stamp} ns is before the previous odometry's {latest} ns", "Odometry")
            return
        self.odom.add(stamp, np.array([msg.pose.x, msg.pose.y, msg.pose.theta]))
        self._process_waiting_scans()

    def on_scan(self, msg: LaserScan) -> None:
        problem = self._scan_problem(msg)
        if problem:
            self._reject("scan", problem, "LaserScan")
            return
        if self.slam is None:
            p = self.params
            angles = msg.angle_min + np.arange(msg.ranges.size) * msg.angle_increment
            start = (p.initial_pose_x, p.initial_pose_y, p.initial_pose_a)
            if p.method == "hector":
                self.slam = HectorSlam(p, angles, msg.range_max, (p.laser_x, p.laser_y, p.laser_yaw), start)
            else:
                self.slam = Rbpf(p, angles, msg.range_max, msg.range_min, start=start)
            self.n_beams = msg.ranges.size
        if not self.uses_odometry:
            self._update(msg.header.stamp_ns, None, np.asarray(msg.ranges, np.float64))
            return
        if not self.scans.add(msg.header.stamp_ns, np.asarray(msg.ranges, np.float64)):
            self.counters["scans_dropped_waiting_for_odometry"] += 1
        self._process_waiting_scans()   # odometry at the scan's stamp may have come first

    def _scan_problem(self, msg: LaserScan) -> str:
        if msg.ranges.size < 2 or not msg.angle_increment or not math.isfinite(msg.angle_increment):
            return f"{msg.ranges.size} ranges with angle_increment {msg.angle_increment}: not a usable scan"
        if not (math.isfinite(msg.range_max) and msg.range_max > 0):
            return f"range_max {msg.range_max} is not a positive distance"
        if self.slam is not None and msg.ranges.size != self.n_beams:
            return f"{msg.ranges.size} beams, but the laser had {self.n_beams} (restart slam for another laser)"
        return ""

    def _reject(self, name: str, problem: str, type_name: str) -> None:
        key = self.keys_in[name]
        self.reject(key, MessageError(problem, type_name=type_name, key=key))

    def _process_waiting_scans(self) -> None:
        for stamp, ranges, odom in self.scans.ready():
            if odom is None:
                self.counters["scans_before_odometry"] += 1
            else:
                self._update(stamp, odom, ranges)

    # ------------------------------------------------------------ the filter and its outputs

    def _update(self, stamp_ns: int, odom: np.ndarray | None, ranges: np.ndarray) -> None:
        p, slam = self.params, self.slam
        updates = slam.updates
        slam.process(stamp_ns, odom, ranges)
        self.counters["scans"] += 1
        self.counters["filter_updates"] += slam.updates - updates
        x, y, theta = (float(v) for v in slam.pose())
        self.last_pose = PoseWithCovariance(header=Header(stamp_ns=stamp_ns, frame_id=p.map_frame),
                                            pose=Pose2D(x, y, theta), covariance=slam.covariance())
        self.pose_pub.publish(self.last_pose)
        if odom is not None:
            tx, ty, ttheta = (float(v) for v in slam.map_to_odom())
            self.tf_pub.publish(Transform(header=Header(stamp_ns=stamp_ns, frame_id=p.map_frame),
                                          child_frame_id=p.odom_frame, transform=Pose2D(tx, ty, ttheta)))

    def current_map(self) -> OccupancyGrid | None:
        """The best particle's map, or hector's (made again only after the core has changed it)."""
        slam = self.slam
        if slam is None:
            return None
        if self._map is None or self._map[0] != slam.updates:
            grid = slam.occupancy_grid(self.params.occ_thresh)
            grid.header.frame_id = self.params.map_frame
            self._map = (slam.updates, grid)
        grid = self._map[1]
        grid.header.stamp_ns = self.now_ns
        return grid

    def publish_map(self) -> None:
        grid = self.current_map()
        if grid is not None:
            self.map_pub.publish(grid)
