"""Collision monitor after Nav2's collision_monitor, on the raw scan: the last check between the
planner and the chassis, independent of the costmaps.

Two polygons around the footprint (each vertex pushed out by stop_padding / slowdown_padding, as
costmap_2d pads a footprint): with at least min_points scan points inside the stop zone that the
command brings closer to the footprint, the command becomes zero; else with at least min_points
inside the slowdown zone it is scaled by slowdown_ratio (all axes, so the direction is kept).
Points are in the robot frame.

Unlike Nav2's stop polygon, a point in the stop zone stops only a command that approaches it (its
distance to the footprint would shrink over approach_check_s): a robot that has come within
stop_padding of a door post may still turn or move away from it, instead of standing there until
the navigator gives up.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ...schemas.messages import LaserScan
from ...sim.world import points_in_polygons
from ..costmap.footprint import pad
from ..costmap.layers import scan_points
from ..se2 import integrate
from .params import CollisionMonitorParams


@dataclass(frozen=True)
class MonitorResult:
    twist: np.ndarray    # (3,) the command to send
    action: str          # none | slowdown | stop
    points: int          # scan points inside the zone that acted (0 for none)
    reason: str


def distance_to_outline(points: np.ndarray, polygon: np.ndarray) -> np.ndarray:
    """(K,) distance from each point to the nearest edge of the polygon (its outline)."""
    a = polygon[:, None, :]                                   # (E, 1, 2) edge starts
    edge = np.roll(polygon, -1, axis=0)[:, None, :] - a       # (E, 1, 2)
    t = np.clip(np.sum((points[None] - a) * edge, axis=2) / np.sum(edge * edge, axis=2), 0.0, 1.0)
    nearest = a + t[..., None] * edge                         # (E, K, 2)
    return np.min(np.hypot(*(points[None] - nearest).transpose(2, 0, 1)), axis=0)


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
        zones = points_in_polygons(points, np.stack([self.stop_zone, self.slowdown_zone]))
        inside = zones.sum(axis=0)
        approached = self._approached(twist, points[zones[:, 0]])
        if approached >= p.min_points:
            return MonitorResult(np.zeros(3), "stop", approached,
                                 f"{approached} scan points within {p.stop_padding} m of the footprint, approached")
        if inside[1] >= p.min_points:
            return MonitorResult(twist * p.slowdown_ratio, "slowdown", int(inside[1]),
                                 f"{inside[1]} scan points within {p.slowdown_padding} m of the footprint")
        return MonitorResult(twist.copy(), "none", 0, "")

    def _approached(self, twist: np.ndarray, points: np.ndarray) -> int:
        """How many of the points the command brings closer to the footprint's outline."""
        if len(points) == 0:
            return 0
        dx, dy, dtheta = integrate((0.0, 0.0, 0.0), twist, self.params.approach_check_s)
        cos, sin = np.cos(dtheta), np.sin(dtheta)
        shifted = points - (dx, dy)
        after = np.column_stack([cos * shifted[:, 0] + sin * shifted[:, 1], -sin * shifted[:, 0] + cos * shifted[:, 1]])
        footprint = np.asarray(self.params.footprint, float)
        closer = distance_to_outline(after, footprint) < distance_to_outline(points, footprint) - 1e-9
        return int(np.count_nonzero(closer))
