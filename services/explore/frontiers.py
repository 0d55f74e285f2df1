"""Frontier exploration on a slam map: where to drive next to see what is still unknown.

A frontier cell is a free map cell with an unknown 4-neighbour (outside the map counts as
unknown); frontier cells that touch (8-connected) form one frontier, whose size is its cell count
× the resolution (explore_lite's measure). Frontiers shorter than min_frontier_size are ignored,
and so are the cells the caller leaves out (shadows the lidar cannot reach, frontiers that failed).

The costs: occupied cells are lethal, unknown cells impassable, and everything within the
footprint's inscribed radius + clearance of an occupied cell is inscribed (253, impassable to the
search), with the costmap's inflation falling off beyond (InflationLayer, so paths keep to the
middle of free space): a path goes wherever the robot fits turned the right way, as the global
planner plans. A goal (the approach cell) must keep the robot's circumscribed radius + clearance
from occupied cells, so the robot fits there turned any way. Cells near the robot that are
inscribed but not lethal are passable at a high cost, so a robot that finds itself closer to a
wall than the clearance (a wall seen late) can still leave.

One Dijkstra search from the robot over these costs (global planner core) reaches every cell.
A frontier is approached at the reachable cell nearest to it by path cost among the cells within
approach_distance of its middle (the cell nearest its centroid, explore_lite's target: approaching
a shadow's edge at its nearest end leaves the robot behind the obstacle that casts it), or, when
none is reachable there, within approach_distance of any of its cells; the frontiers are scored by path cost in metres minus gain_scale × size
in metres, the lowest wins (explore_lite's potential_scale · distance − gain_scale · size, both
in metres here). No reachable frontier: the exploration is done.

explore_lite blacklists a frontier for good once a goal on it failed; here (FailedFrontiers) a
frontier that failed is held back only until the robot has moved or the map has grown since, and
tried again; when only held-back frontiers are left they are tried again anyway, and a frontier is
dropped for good, with its reasons, after max_failures failures. So the exploration ends only
when no frontier is reachable or every one left has failed max_failures times.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import ndimage
from scipy.spatial import cKDTree

from ...schemas.messages import MapMetaData, OccupancyGrid
from ...geometry.grid import GRID_OBSTACLE
from ..costmap.layers import InflationLayer
from ..costmap.params import InflationLayerParams
from ..global_planner.astar import NO_INFORMATION, search
from ..global_planner.params import GlobalPlannerParams
from ...geometry.grid import cell_to_world, in_grid, world_to_cell
from ...parameters.declare import Parameters, Rule, param

LETHAL, INSCRIBED = 254, 253
SEARCH = GlobalPlannerParams(use_dijkstra=True, allow_unknown=False, outline_map=False)


@dataclass(frozen=True)
class ExploreParams(Parameters):
    robot_radius: float = param(0.53, gt=0)        # m: the footprint's circumscribed radius (build_map sets it): at a goal
    inscribed_radius: float = param(0.32, gt=0)    # m: … and its inscribed radius (build_map sets it): along a path
    clearance: float = param(0.1, ge=0)            # m kept between those circles and occupied map cells
    inflation_radius: float = param(1.5, ge=0)     # m: path costs fall off out to here
    cost_scaling_factor: float = param(3.0, ge=0)  # 1/m, as the costmap's inflation
    min_frontier_size: float = param(0.5, ge=0)    # m (explore_lite's name and default)
    gain_scale: float = param(0.3, ge=0)           # score per metre of frontier against a metre of path
    approach_distance: float = param(1.0, ge=0)    # m: a frontier is approached to within this
    retry_distance: float = param(1.0, ge=0)       # m the robot moves from where a frontier failed: it is tried again
    retry_known_area: float = param(1.0, ge=0)     # m² of the map newly known since a frontier failed: it is tried again
    max_failures: int = param(3, gt=0)             # failures of one frontier after which it is dropped for good

    rules = (Rule("inscribed_radius", lambda p: p.inscribed_radius <= p.robot_radius, "≤ robot_radius ({p.robot_radius})"),)


@dataclass(frozen=True)
class Frontier:
    cells: np.ndarray       # (K, 2) row, col in the map it was found on
    xy: np.ndarray          # (K, 2) world coordinates of their centres
    size_m: float

    @property
    def middle(self) -> int:
        """Index of the cell nearest the frontier's centroid (explore_lite's target)."""
        return int(np.argmin(np.hypot(*(self.xy - self.xy.mean(axis=0)).T)))


@dataclass(frozen=True)
class ExploreGoal:
    frontier: Frontier
    cell: tuple[int, int]       # the approach cell
    xy: tuple[float, float]     # its centre
    target_xy: tuple[float, float]  # the frontier cell it approaches: the middle, or the nearest one
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


def approaches(allowed: np.ndarray, targets: list[np.ndarray], reach_cells: float) -> list[tuple[np.ndarray, np.ndarray]]:
    """For each set of target cells: the allowed cells within reach_cells of it (and nearer to it than
    to any other set), and for each of those the target cell nearest to it; (K, 2) row, col both."""
    labels = np.zeros(allowed.shape, np.int32)
    for k, cells in enumerate(targets, start=1):
        labels[cells[:, 0], cells[:, 1]] = k
    distance, (near_r, near_c) = ndimage.distance_transform_edt(labels == 0, return_indices=True)
    rows, cols = np.nonzero(allowed & (distance <= reach_cells))
    owner = labels[near_r[rows, cols], near_c[rows, cols]]
    result = []
    for k in range(1, len(targets) + 1):
        mine = owner == k
        result.append((np.column_stack([rows[mine], cols[mine]]),
                       np.column_stack([near_r[rows[mine], cols[mine]], near_c[rows[mine], cols[mine]]])))
    return result


class Explorer:
    """Costs and frontier choice for one robot; keeps the inflation's lookup table."""

    def __init__(self, params: ExploreParams, resolution: float):
        self.params = params
        self.resolution = resolution
        self.inflation = InflationLayer(
            InflationLayerParams(inflation_radius=max(params.inflation_radius, params.robot_radius + params.clearance),
                                 cost_scaling_factor=params.cost_scaling_factor),
            params.inscribed_radius + params.clearance, resolution)

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
        clear = ndimage.distance_transform_edt(~map_classes(grid)[1]) * info.resolution
        goals = np.isfinite(metres) & (clear > p.robot_radius + p.clearance)
        reach = p.approach_distance / info.resolution
        near_middle = approaches(goals, [f.cells[f.middle:f.middle + 1] for f in frontiers], reach)
        near_any = approaches(goals, [f.cells for f in frontiers], reach)
        best: tuple | None = None
        for frontier, middle, anywhere in zip(frontiers, near_middle, near_any):
            cells, targets = middle if len(middle[0]) else anywhere
            if not len(cells):
                continue
            i = np.lexsort((cells[:, 1], cells[:, 0], metres[cells[:, 0], cells[:, 1]]))[0]
            cell = (int(cells[i, 0]), int(cells[i, 1]))
            score = float(metres[cell]) - p.gain_scale * frontier.size_m
            if best is None or score < best[0]:
                best = (score, frontier, cell, tuple(int(v) for v in targets[i]))
        if best is None:
            return None
        score, frontier, cell, target = best
        return ExploreGoal(frontier=frontier, cell=cell, xy=tuple(float(v) for v in cell_to_world(info, *cell)),
                           target_xy=tuple(float(v) for v in cell_to_world(info, *target)),
                           path_m=float(metres[cell]), score=score, frontiers=len(frontiers))

    def next_goal(self, grid: OccupancyGrid, pose, left_out_xy, failed: FailedFrontiers) -> ExploreGoal | None:
        """The best frontier to drive to, without the cells left_out_xy and the frontiers `failed`
        holds back; when none but held-back ones is reachable, the best of those not yet dropped."""
        costs = self.costs(grid)
        left_out = np.asarray(left_out_xy, float).reshape(-1, 2)
        goal = self.choose(grid, costs, pose, np.vstack([left_out, failed.held_back(pose[:2], known_area(grid))]))
        if goal is None and failed.waiting:
            goal = self.choose(grid, costs, pose, np.vstack([left_out, failed.dropped_xy()]))
        return goal

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


SAME_FRONTIER_M = 0.3   # a failing frontier with a cell this close to one that failed before is that one again


@dataclass(frozen=True)
class Failure:
    xy: np.ndarray                  # (K, 2) world points of the frontier's cells (every shape it failed in)
    robot_xy: tuple[float, float]   # where the robot was when it last failed
    known_m2: float                 # how much of the map was known then
    reasons: tuple[str, ...]        # one per failure


def known_area(grid: OccupancyGrid) -> float:
    """m² of the map known (free or occupied)."""
    return float(np.count_nonzero(grid.data >= 0)) * grid.info.resolution ** 2


class FailedFrontiers:
    """The frontiers that failed (explore_lite's blacklist, made forgiving). One is held back until
    the robot has moved retry_distance from where it last failed or retry_known_area more of the
    map is known; then it is tried again. At its max_failures-th failure it is dropped for good."""

    def __init__(self, params: ExploreParams):
        self.params = params
        self.waiting: list[Failure] = []
        self.dropped: list[Failure] = []

    def fail(self, xy: np.ndarray, reason: str, robot_xy, known_m2: float) -> Failure:
        """Record a failure of the frontier whose cells lie at xy; its record (dropped, when its
        reasons number max_failures)."""
        xy = np.asarray(xy, float).reshape(-1, 2)
        same = [f for f in self.waiting if _within(f.xy, xy, SAME_FRONTIER_M)]
        record = Failure(xy=np.vstack([*(f.xy for f in same), xy]), robot_xy=(float(robot_xy[0]), float(robot_xy[1])),
                         known_m2=known_m2, reasons=tuple(r for f in same for r in f.reasons) + (reason,))
        self.waiting = [f for f in self.waiting if not any(f is g for g in same)]
        (self.dropped if len(record.reasons) >= self.params.max_failures else self.waiting).append(record)
        return record

    def held_back(self, robot_xy, known_m2: float) -> np.ndarray:
        """World points of the frontiers not to try now: the dropped ones, and the waiting ones with
        neither the robot moved nor the map grown enough since they failed."""
        p = self.params
        unchanged = [f.xy for f in self.waiting if math.dist(robot_xy, f.robot_xy) < p.retry_distance
                     and known_m2 - f.known_m2 < p.retry_known_area]
        return np.vstack([np.zeros((0, 2)), *(f.xy for f in self.dropped), *unchanged])

    def dropped_xy(self) -> np.ndarray:
        return np.vstack([np.zeros((0, 2)), *(f.xy for f in self.dropped)])


def _within(a: np.ndarray, b: np.ndarray, distance: float) -> bool:
    """Whether some point of a lies within distance of some point of b."""
    if not (len(a) and len(b)):
        return False
    nearest, _ = cKDTree(a).query(b, distance_upper_bound=distance)
    return bool(np.isfinite(nearest).any())
