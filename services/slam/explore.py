"""Frontier exploration on a slam map: where to drive next to see what is still unknown.

A frontier cell is a free map cell with an unknown 4-neighbour (outside the map counts as
unknown); frontier cells that touch (8-connected) form one frontier, whose size is its cell count
× the resolution (explore_lite's measure). Frontiers shorter than min_frontier_size are ignored,
and so are the cells the caller gave up on (seen from close by and still unknown: shadows the
lidar cannot reach).

The costs: occupied cells are lethal, unknown cells impassable, and everything within the robot's
circumscribed radius + clearance of an occupied cell is inscribed (253, impassable to the search),
with the costmap's inflation falling off beyond (InflationLayer, so paths keep to the middle of
free space). The robot turned any way therefore fits wherever a path goes. Cells near the robot
that are inscribed but not lethal are passable at a high cost, so a robot that finds itself
closer to a wall than the clearance (a wall seen late) can still leave.

One Dijkstra search from the robot over these costs (global planner core) reaches every cell.
A frontier is approached at the reachable cell nearest to it by path cost among the cells within
approach_distance of it; the frontiers are scored by path cost in metres minus gain_scale × size
in metres, the lowest wins (explore_lite's potential_scale · distance − gain_scale · size, both
in metres here). No reachable frontier: the exploration is done.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import ndimage

from ...schemas.messages import MapMetaData, OccupancyGrid
from ...sim.world import GRID_OBSTACLE
from ..costmap.layers import InflationLayer
from ..costmap.params import InflationLayerParams
from ..global_planner.astar import NO_INFORMATION, search
from ..global_planner.params import GlobalPlannerParams
from ..map_server.mapio import cell_to_world, in_grid, world_to_cell

LETHAL, INSCRIBED = 254, 253
SEARCH = GlobalPlannerParams(use_dijkstra=True, allow_unknown=False, outline_map=False)


@dataclass(frozen=True)
class ExploreParams:
    robot_radius: float = 0.53          # m: the robot's circumscribed radius (build_map sets it from the footprint)
    clearance: float = 0.1              # m kept between that circle and occupied map cells
    inflation_radius: float = 1.5       # m: path costs fall off out to here
    cost_scaling_factor: float = 3.0    # 1/m, as the costmap's inflation
    min_frontier_size: float = 0.5      # m (explore_lite's name and default)
    gain_scale: float = 0.3             # score per metre of frontier against a metre of path
    approach_distance: float = 1.0      # m: a frontier is approached to within this
    progress_timeout: float = 30.0      # sim s without getting 0.1 m closer to the goal: give it up (explore_lite's)

    def __post_init__(self) -> None:
        for name in ("robot_radius", "clearance", "inflation_radius", "cost_scaling_factor", "min_frontier_size",
                     "gain_scale", "approach_distance", "progress_timeout"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0):
                raise ValueError(f"{name} must be a number ≥ 0, got {value}")
        for name in ("robot_radius", "progress_timeout"):
            if getattr(self, name) <= 0:
                raise ValueError(f"{name} must be positive, got {getattr(self, name)}")


@dataclass(frozen=True)
class Frontier:
    cells: np.ndarray       # (K, 2) row, col in the map it was found on
    xy: np.ndarray          # (K, 2) world coordinates of their centres
    size_m: float


@dataclass(frozen=True)
class ExploreGoal:
    frontier: Frontier
    cell: tuple[int, int]       # the approach cell
    xy: tuple[float, float]     # its centre
    path_m: float               # the path's cost as metres of free travel
    score: float
    frontiers: int              # frontiers large enough to be considered


def map_classes(grid: OccupancyGrid) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(free, occupied, unknown) masks of a map."""
    data = grid.data
    return (data >= 0) & (data <= GRID_OBSTACLE), data > GRID_OBSTACLE, data < 0


def frontier_cells(grid: OccupancyGrid) -> np.ndarray:
    """Free cells with an unknown 4-neighbour or on the map's edge."""
    free, _, unknown = map_classes(grid)
    padded = np.pad(unknown, 1, constant_values=True)
    near_unknown = padded[:-2, 1:-1] | padded[2:, 1:-1] | padded[1:-1, :-2] | padded[1:-1, 2:]
    return free & near_unknown


def still_frontier(grid: OccupancyGrid, xy: np.ndarray) -> np.ndarray:
    """Which world points lie in frontier cells of grid."""
    rows, cols = world_to_cell(grid.info, xy[:, 0], xy[:, 1])
    inside = in_grid(grid.info, rows, cols)
    still = np.zeros(len(xy), bool)
    still[inside] = frontier_cells(grid)[rows[inside], cols[inside]]
    return still


def given_up_mask(grid: OccupancyGrid, given_up_xy: np.ndarray) -> np.ndarray:
    """The map cells holding the given-up world points."""
    mask = np.zeros(grid.data.shape, bool)
    if len(given_up_xy):
        rows, cols = world_to_cell(grid.info, given_up_xy[:, 0], given_up_xy[:, 1])
        inside = in_grid(grid.info, rows, cols)
        mask[rows[inside], cols[inside]] = True
    return mask


def find_frontiers(grid: OccupancyGrid, min_size_m: float = 0.0, given_up_xy=()) -> list[Frontier]:
    """The map's frontiers of at least min_size_m, without given-up cells, largest first."""
    cells = frontier_cells(grid) & ~given_up_mask(grid, np.asarray(given_up_xy, float).reshape(-1, 2))
    labels, count = ndimage.label(cells, structure=np.ones((3, 3), bool))
    frontiers = []
    for k, where in enumerate(ndimage.find_objects(labels), start=1):
        rows, cols = np.nonzero(labels[where] == k)
        size = len(rows) * grid.info.resolution
        if size >= min_size_m:
            rows, cols = rows + where[0].start, cols + where[1].start
            frontiers.append(Frontier(np.column_stack([rows, cols]), np.column_stack(cell_to_world(grid.info, rows, cols)),
                                      size))
    frontiers.sort(key=lambda f: (-len(f.cells), tuple(f.cells[0])))
    return frontiers


class Explorer:
    """Costs and frontier choice for one robot; keeps the inflation's lookup table."""

    def __init__(self, params: ExploreParams, resolution: float):
        self.params = params
        self.resolution = resolution
        self.inflation = InflationLayer(
            InflationLayerParams(inflation_radius=max(params.inflation_radius, params.robot_radius + params.clearance),
                                 cost_scaling_factor=params.cost_scaling_factor),
            params.robot_radius + params.clearance, resolution)

    def costs(self, grid: OccupancyGrid) -> np.ndarray:
        """uint8 costs of the map: lethal at occupied cells, inscribed within the robot's reach of
        them, inflated beyond; unknown cells NO_INFORMATION unless inscribed."""
        if not math.isclose(grid.info.resolution, self.resolution):
            raise ValueError(f"map resolution {grid.info.resolution} m, the explorer was made for {self.resolution} m")
        _, occupied, unknown = map_classes(grid)
        composed = np.where(occupied, LETHAL, np.where(unknown, NO_INFORMATION, 0)).astype(np.uint8)
        costs = np.empty_like(composed)
        self.inflation.inflate(composed, costs, (0, 0, *composed.shape))
        return costs

    def choose(self, grid: OccupancyGrid, costs: np.ndarray, pose, given_up_xy=()) -> ExploreGoal | None:
        """The best frontier to drive to from pose; None when no frontier is reachable."""
        p, info = self.params, grid.info
        start = tuple(int(v) for v in np.ravel(world_to_cell(info, pose[0], pose[1])))
        if not in_grid(info, *start):
            raise ValueError(f"the robot ({pose[0]:.2f}, {pose[1]:.2f}) is off the map")
        frontiers = find_frontiers(grid, p.min_frontier_size, given_up_xy)
        if not frontiers:
            return None
        costs = self._with_escape(costs, info, start)
        result = search(costs, start, (-1, -1), SEARCH)     # no goal: Dijkstra reaches every cell it can
        metres = result.cost_to_come() / SEARCH.neutral_cost * info.resolution
        labels = np.zeros(grid.data.shape, np.int32)
        for k, frontier in enumerate(frontiers, start=1):
            labels[frontier.cells[:, 0], frontier.cells[:, 1]] = k
        distance, (near_r, near_c) = ndimage.distance_transform_edt(labels == 0, return_indices=True)
        candidates = np.isfinite(metres) & (distance * info.resolution <= p.approach_distance)
        rows, cols = np.nonzero(candidates)
        if not len(rows):
            return None
        owner = labels[near_r[rows, cols], near_c[rows, cols]]
        best: tuple | None = None
        for k, frontier in enumerate(frontiers, start=1):
            mine = np.flatnonzero(owner == k)
            if not len(mine):
                continue
            i = mine[np.lexsort((cols[mine], rows[mine], metres[rows[mine], cols[mine]]))[0]]
            cell = (int(rows[i]), int(cols[i]))
            score = float(metres[cell]) - p.gain_scale * frontier.size_m
            if best is None or score < best[0]:
                best = (score, frontier, cell)
        if best is None:
            return None
        score, frontier, cell = best
        return ExploreGoal(frontier=frontier, cell=cell, xy=tuple(float(v) for v in cell_to_world(info, *cell)),
                           path_m=float(metres[cell]), score=score, frontiers=len(frontiers))

    def _with_escape(self, costs: np.ndarray, info: MapMetaData, start: tuple[int, int]) -> np.ndarray:
        """Inscribed (not lethal) cells within the robot's radius of its cell made passable."""
        reach = math.ceil(self.params.robot_radius / info.resolution)
        r0, r1 = max(start[0] - reach, 0), min(start[0] + reach + 1, costs.shape[0])
        c0, c1 = max(start[1] - reach, 0), min(start[1] + reach + 1, costs.shape[1])
        window = costs[r0:r1, c0:c1]
        if not (window == INSCRIBED).any():
            return costs
        costs = costs.copy()
        window = costs[r0:r1, c0:c1]
        window[window == INSCRIBED] = INSCRIBED - 1
        return costs
