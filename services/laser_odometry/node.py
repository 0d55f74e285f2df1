"""The laser_odometry service: each scan matched to a local map (laser_odometry.py), published as
odometry with covariance on `odom_laser`, for a fusion (services/ekf) to weigh against the wheels.

Inputs, in merge order: the wheel odometry on odom_topic (`odom_wheel`, what the chassis publishes
when a fusion publishes `odom`; or `odom`) and scan, both synced. A scan stamped t is processed once
odometry stamped ≥ t has come (rule 2 of the determinism rules), with the odometry pose at t
interpolated between the two messages around it (OdomHistory, as slam and the localizer do); its
end points are placed on the robot by the laser's mount (laser_x, laser_y, laser_yaw).

Output, for every scan matched: `odom_laser` (Odometry stamped with the scan, frame_id odom_frame,
child base_frame): the pose in the odometry frame (the wheel odometry's pose at the first scan),
pose_covariance (the match's), and the twist from the previous published pose (base_link, with
their covariances summed over dt²). The first scan and a refused match publish nothing: a fusion
takes laser odometry as it comes (services/ekf holds it as sporadic), and the wheels' pose
republished at every scan would pull it back to the wheels, however large its covariance.
Counters: matches, failed_matches and failed_matches/<why>, map_recentres, map_restarts,
ghost_cells_cleared (laser_odometry.py: what moving bodies left in the local map).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ...geometry.frames import LASER_MOUNT, scan_points
from ...geometry.odometry_history import OdomHistory, WaitingForOdometry
from ...geometry.se2 import relative
from ...parameters.declare import param
from ...schemas import MessageError
from ...schemas.messages import Header, LaserScan, Odometry, Pose2D, Twist
from ..runtime.node import NS_PER_S, Node
from .laser_odometry import FIRST_SCAN, LaserOdometry, LaserOdometryParams, warm_up

@dataclass(frozen=True)
class LaserOdometryNodeParams(LaserOdometryParams):
    odom_topic: str = param("odom_wheel", choices=("odom_wheel", "odom"))   # the wheel odometry
    laser_x: float = LASER_MOUNT[0]          # m: the laser on the robot (the simulated lidar's mount)
    laser_y: float = LASER_MOUNT[1]
    laser_yaw: float = LASER_MOUNT[2]
    odom_frame: str = param("odom", nonempty=True)
    base_frame: str = param("base_link", nonempty=True)
    odom_history_s: float = param(2.0, ge=0)     # sim s of odometry kept for interpolation


class LaserOdometryNode(Node):
    service = "laser_odometry"
    Params = LaserOdometryNodeParams

    def setup(self) -> None:
        p = self.params
        warm_up()
        self.core = LaserOdometry(p)
        self.laser = np.array([p.laser_x, p.laser_y, p.laser_yaw])
        self.odom = OdomHistory(round(p.odom_history_s * NS_PER_S))
        self.scans = WaitingForOdometry(self.odom)          # each scan's end points in the robot frame
        self.last: tuple[int, np.ndarray, np.ndarray] | None = None   # stamp, pose, covariance published last
        self.keys_in = {name: self.keys.resolve(name) for name in (p.odom_topic, "scan")}
        self.odom_pub = self.publisher("odom_laser")
        self.subscribe(p.odom_topic, self.on_odom)
        self.subscribe("scan", self.on_scan)

    def on_odom(self, msg: Odometry) -> None:
        stamp, latest = msg.header.stamp_ns, self.odom.latest
        if latest is not None and stamp < latest:
            self._reject(self.params.odom_topic, f"stamp {stamp} ns is before the previous odometry's {latest} ns",
                         "Odometry")
            return
        self.odom.add(stamp, np.array([msg.pose.x, msg.pose.y, msg.pose.theta]))
        self._process_waiting_scans()

    def on_scan(self, msg: LaserScan) -> None:
        stamp = msg.header.stamp_ns
        newest = self.scans.newest if self.scans.newest is not None else self.last[0] if self.last is not None else None
        if newest is not None and stamp <= newest:
            self._reject("scan", f"stamp {stamp} ns is not after the previous scan's, {newest} ns", "LaserScan")
            return
        if not self.scans.add(stamp, scan_points(msg, self.laser, inf_is_valid=False)):
            self.counters["scans_dropped_waiting_for_odometry"] += 1
        self._process_waiting_scans()   # odometry at the scan's stamp may have come first

    def _reject(self, name: str, problem: str, type_name: str) -> None:
        key = self.keys_in[name]
        self.reject(key, MessageError(problem, type_name=type_name, key=key))

    def _process_waiting_scans(self) -> None:
        for stamp, points, odom in self.scans.ready():
            if odom is None:
                self.counters["scans_before_odometry"] += 1
            else:
                self._publish(stamp, self.core.step(stamp, points, odom))

    def _publish(self, stamp: int, result) -> None:
        p = self.params
        if result.ok:
            self.counters["matches"] += 1
        elif result.failure != FIRST_SCAN:
            self.counters["failed_matches"] += 1
            self.counters[f"failed_matches/{result.failure}"] += 1
        self.counters["map_recentres"] += int(result.recentred)
        self.counters["map_restarts"] = self.core.restarts
        self.counters["ghost_cells_cleared"] = self.core.ghosts_cleared
        if not result.ok:
            return      # the wheels' pose again says nothing a fusion may take (laser_odometry.py)
        twist, twist_covariance = np.zeros(3), result.covariance.copy()
        if self.last is not None:
            dt = (stamp - self.last[0]) / NS_PER_S
            twist = relative(self.last[1], result.pose) / dt
            c, s = math.cos(self.last[1][2]), math.sin(self.last[1][2])
            into_base = np.array([[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]])
            twist_covariance = into_base @ (self.last[2] + result.covariance) @ into_base.T / dt ** 2
        self.last = (stamp, result.pose, result.covariance)
        x, y, theta = (float(v) for v in result.pose)
        vx, vy, wz = (float(v) for v in twist)
        self.odom_pub.publish(Odometry(
            header=Header(stamp_ns=stamp, frame_id=p.odom_frame), child_frame_id=p.base_frame,
            pose=Pose2D(x, y, theta), twist=Twist(header=Header(stamp_ns=stamp, frame_id=p.base_frame),
                                                  linear_x=vx, linear_y=vy, angular_z=wz),
            pose_covariance=result.covariance, twist_covariance=twist_covariance))
