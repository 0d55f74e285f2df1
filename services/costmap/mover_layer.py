"""The mover layer: where the tracker's moving obstacles will walk, as costs the global plan avoids.

People who do not give way walk on through where the robot would be; a costmap of where they
stand now lets the plan run into their way, and the local planner sees them coming only within its
rollouts' seconds. This layer stamps, for each track faster than min_speed, the way it sweeps over
the next prediction_time seconds at constant velocity, and the behind_time seconds of it just
walked: every cell whose centre lies within the track's radius plus the robot's inscribed radius
plus margin of the track's centre at some τ in [−behind_time, prediction_time] costs sweep_cost,
wherever along the way.

The lane behind, because people turn round: a robot that followed a person along their lane was in
their way when they came back (generated head-on worlds, seeds 0–9: 4 of 10 without the lane
behind, 7 of 10 with 2 s of it). The same cost all along, because with costs falling over τ plans
crossed a slow person's way just ahead of them, where it was cheap, and then walked beside them
(generated crossing world, seed 1: a contact); a way that costs the same everywhere is crossed
behind the person, where it has no cost at all. Costs stay below INSCRIBED_INFLATED_OBSTACLE: the
way is dear, not closed (a doorway the person walks through is still the only way). Like
social_navigation_layers' passing and proxemic layers in ROS, it goes after the inflation layer
and combines by maximum.
"""
from __future__ import annotations

import numpy as np

from ...geometry.grid import cell_to_world, world_to_cell
from ...geometry.movers import Movers
from ...schemas.messages import MapMetaData
from .layers import NO_INFORMATION, Box, View, combine_max, union
from .params import MoverLayerParams


def sweep_costs(info: MapMetaData, movers: Movers, robot_radius: float, params: MoverLayerParams,
                out: np.ndarray) -> Box | None:
    """Stamp the movers' sweeps into `out` (the costmap's geometry, NO_INFORMATION where nothing
    walks: every sweep has the one cost, so stamping overwrites); returns the box of cells stamped."""
    box = None
    horizon = params.prediction_time
    for p, v, r in zip(movers.positions, movers.velocities, movers.radii):
        if np.hypot(*v) < params.min_speed:
            continue
        reach = r + robot_radius + params.margin
        begin, end = p - v * params.behind_time, p + v * horizon
        lo, hi = np.minimum(begin, end) - reach, np.maximum(begin, end) + reach
        corners_r, corners_c = world_to_cell(info, np.array([lo[0], hi[0], lo[0], hi[0]]),
                                             np.array([lo[1], lo[1], hi[1], hi[1]]))   # the grid may be rotated
        r0, c0 = max(int(corners_r.min()), 0), max(int(corners_c.min()), 0)
        r1, c1 = min(int(corners_r.max()) + 1, info.height), min(int(corners_c.max()) + 1, info.width)
        if r0 >= r1 or c0 >= c1:
            continue
        rows, cols = np.mgrid[r0:r1, c0:c1]
        x, y = cell_to_world(info, rows, cols)
        tau = np.clip(((x - p[0]) * v[0] + (y - p[1]) * v[1]) / max(float(v @ v), 1e-12), -params.behind_time, horizon)
        near = np.hypot(x - (p[0] + v[0] * tau), y - (p[1] + v[1] * tau)) <= reach
        out[r0:r1, c0:c1][near] = params.sweep_cost
        box = union(box, (r0, c0, r1, c1))
    return box


class MoverLayer:
    """The tracks' predicted sweeps (mover_layer.py); `set_movers` before each update."""

    def __init__(self, params: MoverLayerParams, robot_radius: float):
        self.params = params
        self.name = params.name
        self.robot_radius = robot_radius
        self.movers: Movers | None = None
        self.costs: np.ndarray | None = None
        self._stamped: Box | None = None

    def set_movers(self, movers: Movers | None) -> None:
        """The tracks at the coming update's time in the costmap's frame (None: none)."""
        self.movers = movers

    def resize(self, info: MapMetaData) -> None:
        self.costs = np.full((info.height, info.width), NO_INFORMATION, np.uint8)
        self._stamped = None

    def shift(self, dr: int, dc: int) -> None:
        self.costs[:] = NO_INFORMATION    # restamped at every update: nothing to carry
        self._stamped = None

    def update_bounds(self, view: View) -> Box | None:
        old = self._stamped
        if old is not None:
            r0, c0, r1, c1 = old
            self.costs[r0:r1, c0:c1] = NO_INFORMATION
        moving = self.movers is not None and len(self.movers) > 0
        self._stamped = sweep_costs(view.info, self.movers, self.robot_radius, self.params, self.costs) if moving else None
        return union(old, self._stamped)

    def update_costs(self, master: np.ndarray, box: Box) -> None:
        if self._stamped is not None:
            combine_max(master, self.costs, box)

