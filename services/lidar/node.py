"""The lidar service: casts a scan at the robot's true pose, on a fixed sim-time schedule.

Inputs are the sim's movers and ground truth, both synced and in that order, so the movers at t
are known when the truth at t is handled. Scans are due at multiples of 1 / rate_hz of sim time
(whenever the lidar started, its scans fall on the same instants); the first truth at or after a
due time is scanned. The sensor model's randomness (noise, dropouts, mixed pixels) comes from the
node's own seeded Generator, advanced only by scans and by the same number of draws in each, so a
replay reproduces every range.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ...schemas.messages import LaserScan, Obstacles, Odometry
from ...sim.lidar import LidarParams, make_scan, scan, warm_up
from ...sim.world import load_world, world_path
from ..runtime.node import Node, Ticks

LASER_FRAME = "laser"


@dataclass(frozen=True)
class LidarNodeParams(LidarParams):
    """LidarParams plus the world to cast into (the sim's world) and the noise seed."""
    world: str = "room"     # a shipped world's name or a world file's path (relative to the working directory)
    seed: int = 0


class LidarNode(Node):
    service = "lidar"
    Params = LidarNodeParams

    def setup(self) -> None:
        self.world = load_world(world_path(self.params.world))   # WorldError names the file and key
        self.rng = np.random.default_rng(self.params.seed)
        self.scan_ticks = Ticks(self.params.rate_hz)
        self.movers = np.zeros((0, 3))
        self.last_scan: LaserScan | None = None
        self.scan_pub = self.publisher("scan")
        self.subscribe("sim/movers", self.on_movers)
        self.subscribe("sim/truth", self.on_truth)
        self.queryable("scan", lambda _params: self.last_scan)
        warm_up()   # compile the casting kernels now, never inside a cycle

    def on_movers(self, msg: Obstacles) -> None:
        self.movers = msg.circles

    def on_truth(self, msg: Odometry) -> None:
        t = msg.header.stamp_ns
        if not self.scan_ticks.due(t):
            return
        pose = (msg.pose.x, msg.pose.y, msg.pose.theta)
        ranges = scan(self.world, pose, self.movers, self.params, self.rng)
        self.last_scan = make_scan(self.params, ranges, t, LASER_FRAME)
        self.scan_pub.publish(self.last_scan)
