"""The tracker service: moving obstacles from the scan (tracker.py), published as Tracks in the
odom frame, the local planner's and the collision monitor's.

Inputs, in merge order: odom, scan (synced; a scan is placed with the latest odometry at or before
its stamp, as the costmap places it: the sim stamps both alike); map and tf/map_odom (sporadic,
held request_delay_s: a map or transform stamped t takes effect at the first scan stamped after
t + request_delay_s, so whether it arrived before or after the scans in between changes nothing,
and a replay is exact). Until a tf/map_odom comes, the odom frame's pose in the map is the
initial_pose_* (frames.py). Without a map, the static world is what the evidence grid has seen
standing (BARN, SLAM runs); with one, also what the map holds.

Output: `tracks` after every scan, stamped with it: the confirmed tracks (ids, x y vx vy,
covariances, radii), in the odom frame.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ...schemas import MessageError
from ...schemas.messages import LaserScan, OccupancyGrid, Tracks
from ...geometry.frames import FrameParams, LASER_MOUNT
from ...geometry.frames import scan_points
from ..runtime.deferred import Deferred
from ..runtime.node import NS_PER_S, Node
from ...geometry.se2 import compose
from .tracker import MoverTracker, TrackerParams, warm_up
from ...parameters.declare import param

_MAP, _MAP_ODOM = range(2)      # sporadic inputs, in input order (the order of equal stamps)


@dataclass(frozen=True)
class TrackerNodeParams(FrameParams, TrackerParams):
    laser_x: float = LASER_MOUNT[0]     # m: the laser on the robot (the simulated lidar's mount)
    laser_y: float = LASER_MOUNT[1]
    laser_yaw: float = LASER_MOUNT[2]
    use_map: bool = True                     # explain scan points by the static map (the map key)
    request_delay_s: float = param(0.3, ge=0)             # sim s from a map / tf/map_odom stamp to its effect


class TrackerNode(Node):
    service = "tracker"
    Params = TrackerNodeParams

    def setup(self) -> None:
        p = self.params
        warm_up()
        self.core = MoverTracker(TrackerParams(**{name: getattr(p, name) for name in TrackerParams.__dataclass_fields__}))
        self.frames = p.robot_frames()
        self.laser = np.array([p.laser_x, p.laser_y, p.laser_yaw])
        self.pending = Deferred(p.request_delay_s)
        self.map_key = self.keys.resolve("map")
        self.tracks_pub = self.publisher("tracks")
        self.subscribe("odom", self.frames.set_odom)
        self.subscribe("scan", self.on_scan)
        if p.use_map:
            self.subscribe_deferred("map", self.pending, _MAP)
        self.subscribe_deferred("tf/map_odom", self.pending, _MAP_ODOM, self.frames.transform_problem)

    def _apply_due(self, now_ns: int) -> None:
        for kind, msg in self.pending.due(now_ns):
            if kind == _MAP_ODOM:
                self.frames.set_map_odom(msg)
            else:
                self._set_map(msg)

    def _set_map(self, msg: OccupancyGrid) -> None:
        try:
            self.core.set_map(msg)
            self.counters["maps"] += 1
        except ValueError as exc:
            self.reject(self.map_key, MessageError(str(exc), type_name="OccupancyGrid", key=self.map_key))

    def on_scan(self, msg: LaserScan) -> None:
        t = msg.header.stamp_ns
        self._apply_due(t)
        if self.frames.odom is None:
            self.counters["scans_before_odometry"] += 1
            return
        if self.core.stamp_s is not None and t / NS_PER_S < self.core.stamp_s:
            # stamp order makes this impossible on the bus; a replayed or injected scan can be older
            key = self.keys.resolve("scan")
            self.reject(key, MessageError(f"stamp {t / NS_PER_S} s is older than the last scan's, "
                                          f"{self.core.stamp_s} s", type_name="LaserScan", key=key))
            return
        laser = compose(self.frames.odom, self.laser)
        points = scan_points(msg, laser, inf_is_valid=False)
        tracks = self.core.update(t / NS_PER_S, laser[:2], points, self.frames.map_odom)
        self.counters["tracks"] += len(tracks.ids)
        self.tracks_pub.publish(Tracks(header=self.header(self.frames.odom_frame, t), ids=tracks.ids,
                                       states=tracks.states, covariances=tracks.covariances, radii=tracks.radii))
