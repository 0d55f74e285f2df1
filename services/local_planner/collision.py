"""Collision monitor after Nav2's collision_monitor, on the raw scan: the last check between the
planner and the chassis, independent of the costmaps.

Two polygons around the footprint (each vertex pushed out by stop_padding / slowdown_padding, as
costmap_2d pads a footprint): with at least min_points scan points inside the stop zone the command
becomes zero; else with at least min_points inside the slowdown zone it is scaled by slowdown_ratio
(all axes, so the direction is kept). Points are in the robot frame.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ...schemas.messages import LaserScan
from ...sim.world import points_in_polygons
from ..costmap.footprint import pad
from ..costmap.layers import scan_points
from .params import CollisionMonitorParams


@dataclass(frozen=True)
class MonitorResult:
    twist: np.ndarray    # (3,) the command to send
    action: str          # none | slowdown | stop
    points: int          # scan points inside the zone that acted (0 for none)
    reason: str


def robot_frame_points(scan: LaserScan, sensor_pose) -> np.ndarray:
    """(K, 2) scan endpoints in the robot frame; sensor_pose (x, y, yaw) is the laser on the robot."""
    return scan_points(scan, sensor_pose, inf_is_valid=False)


class CollisionMonitor:
    def __init__(self, params: CollisionMonitorParams):
        self.params = params
        footprint = np.asarray(params.footprint, float)
        self.stop_zone = pad(footprint, params.stop_padding)
        self.slowdown_zone = pad(footprint, params.slowdown_padding)

    def check(self, twist, points) -> MonitorResult:
        """The command allowed with these obstacle points (robot frame) around the robot."""
        p = self.params
        twist = np.asarray(twist, float)
        points = np.asarray(points, float).reshape(-1, 2)
        inside = points_in_polygons(points, np.stack([self.stop_zone, self.slowdown_zone])).sum(axis=0)
        if inside[0] >= p.min_points:
            return MonitorResult(np.zeros(3), "stop", int(inside[0]),
                                 f"{inside[0]} scan points within {p.stop_padding} m of the footprint")
        if inside[1] >= p.min_points:
            return MonitorResult(twist * p.slowdown_ratio, "slowdown", int(inside[1]),
                                 f"{inside[1]} scan points within {p.slowdown_padding} m of the footprint")
        return MonitorResult(twist.copy(), "none", 0, "")
