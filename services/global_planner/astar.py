"""Cost-aware A* and Dijkstra over a costmap, after ROS global_planner.

The graph: cells 8-connected. A cell is passable when its cost is below lethal_cost (so inscribed
253 and lethal 254 are not, by default), or when it is unknown (255) and allow_unknown is set;
with outline_map the border cells are not. A diagonal step needs both cells beside it passable,
so a path never squeezes between two blocked cells. The start cell is always allowed (ROS clears
the robot's cell). Entering a cell costs (neutral_cost + cost_factor · cost) × step length
(1 or √2 cells); an unknown cell costs as the costliest passable one (lethal_cost − 1).
ROS global_planner's Dijkstra caps that weight at lethal_cost − 1, which makes every cell above
cost 68 equally expensive (with the defaults); here the weight keeps growing with the cost, so
paths keep away from walls as the inflation gradient asks.

A* uses neutral_cost × the octile distance, which never exceeds the true remaining cost and is
consistent, so A* and Dijkstra return paths of the same (optimal) cost; ties on f are broken
towards the goal. Both run in numba over a binary heap.

A goal in an impassable cell moves to the nearest passable cell within default_tolerance that the
start can reach; so does a goal the start cannot reach. Orientations along the path follow ROS's
OrientationFilter (orientation_mode) and the last pose takes the goal's yaw. Every failure is a
PlanResult with a status, never an exception. With allow_unknown, a start or goal off the grid
is in unknown space: the grid grows with unknown cells to hold it (grown_to_hold), and the
result's cells are those of the grown grid.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit

from ...schemas.messages import MapMetaData
from ...geometry.grid import cell_to_world, grid_coords, in_grid, kernel_costs
from .params import GlobalPlannerParams
from .path_smoother import smooth

OK, NO_PATH, GOAL_IN_OBSTACLE, OFF_MAP = "ok", "no_path", "goal_in_obstacle", "off_map"
NO_INFORMATION = 255
BUCKETS_PER_STEP = 100   # queue buckets per neutral_cost of f; measured fastest on the Willow bench
SQRT2 = math.sqrt(2.0)


# ---------------------------------------------------------------- the search kernel
#
# The search runs on a copy of the grid padded by one impassable cell all round, flattened, so a
# neighbour is index + offset with no bounds checks. weights[i] is the cost of entering cell i per
# cell length, or -1 where the cell is impassable.

@njit(cache=True)
def _fill_weights(costs, neutral, factor, lethal, allow_unknown, outline, node):
    height, width = costs.shape
    padded = width + 2
    weights = node[:, 0]
    weights[:padded] = -1.0
    weights[(height + 1) * padded:] = -1.0
    unknown = neutral + factor * (lethal - 1) if allow_unknown else -1.0
    for r in range(height):
        row = (r + 1) * padded
        weights[row] = weights[row + padded - 1] = -1.0
        for c in range(width):
            value = costs[r, c]
            if outline and (r == 0 or c == 0 or r == height - 1 or c == width - 1):
                w = -1.0
            elif value == 255:
                w = unknown
            elif value < lethal:
                w = neutral + factor * value
            else:
                w = -1.0
            weights[row + c + 1] = w


@njit(cache=True, inline="always")
def _octile(r, c, goal_r, goal_c):
    dr, dc = abs(r - goal_r), abs(c - goal_c)
    return max(dr, dc) + (1.4142135623730951 - 1.0) * min(dr, dc)


@njit(cache=True, inline="always")
def _push(keys, ties, items, size, key, tie, item):
    """Binary-heap insert (capacity ensured by the caller); returns the new size."""
    hole = size
    while hole > 0:
        above = (hole - 1) // 2
        if key < keys[above] or (key == keys[above] and tie < ties[above]):
            keys[hole], ties[hole], items[hole] = keys[above], ties[above], items[above]
            hole = above
        else:
            break
    keys[hole], ties[hole], items[hole] = key, tie, item
    return size + 1


@njit(cache=True, inline="always")
def _pop(keys, ties, items, size):
    """Binary-heap removal of the least (key, tie); returns (item, new size)."""
    top = items[0]
    size -= 1
    key, tie, item = keys[size], ties[size], items[size]
    hole = 0
    while True:
        child = 2 * hole + 1
        if child >= size:
            break
        if child + 1 < size and (keys[child + 1] < keys[child]
                                 or (keys[child + 1] == keys[child] and ties[child + 1] < ties[child])):
            child += 1
        if keys[child] < key or (keys[child] == key and ties[child] < tie):
            keys[hole], ties[hole], items[hole] = keys[child], ties[child], items[child]
            hole = child
        else:
            break
    keys[hole], ties[hole], items[hole] = key, tie, item
    return top, size


@njit(cache=True)
def _search(node, padded, start, goal, neutral, use_heuristic, base):
    """Best-first search over padded flat indices from `start` until `goal` is expanded (True) or
    the reachable cells are exhausted (False). node rows are (weight, g, stamp, parent), reused
    across searches: a cell is untouched while stamp < base, open at base, expanded at base + 1.

    The queue orders by f, then by h (on equal f, nearer the goal first). With a consistent
    heuristic f never decreases along the search, so entries wait in buckets of f (a hundredth of
    a free step wide) and only the current bucket is a binary heap: pops stay shallow while the
    order stays exact. Returns (found, expanded)."""
    goal_r, goal_c = goal // padded, goal % padded
    keys, ties, items = np.empty(4096), np.empty(4096), np.empty(4096, np.int64)
    # entries of later buckets: linked lists through a pool whose consumed entries are reused
    pool_key, pool_tie, pool_item = np.empty(4096), np.empty(4096), np.empty(4096, np.int64)
    pool_next = np.empty(4096, np.int64)
    pool_used, free = 0, -1
    heads = np.full(1024, -1, np.int64)
    node[start, 1], node[start, 2], node[start, 3] = 0.0, base, -1.0
    f0 = neutral * _octile(start // padded, start % padded, goal_r, goal_c) if use_heuristic else 0.0
    size = _push(keys, ties, items, 0, f0, f0, start)
    bucket, expanded, closed = 0, 0, base + 1
    per_bucket = BUCKETS_PER_STEP / neutral
    step_r = (-1, 1, 0, 0, -1, -1, 1, 1)
    step_c = (0, 0, -1, 1, -1, 1, -1, 1)
    while True:
        if size == 0:   # the current bucket is done: load the next non-empty one into the heap
            bucket += 1
            while bucket < heads.shape[0] and heads[bucket] < 0:
                bucket += 1
            if bucket >= heads.shape[0]:
                return False, expanded
            e, heads[bucket] = heads[bucket], -1
            while e >= 0:
                if size == keys.shape[0]:
                    keys, ties, items = _grown(keys), _grown(ties), _grown(items)
                size = _push(keys, ties, items, size, pool_key[e], pool_tie[e], pool_item[e])
                after = pool_next[e]
                pool_next[e], free = free, e
                e = after
            continue
        u, size = _pop(keys, ties, items, size)
        if node[u, 2] == closed:
            continue   # a stale entry: expanded already at a lower cost
        node[u, 2] = closed
        expanded += 1
        if u == goal:
            return True, expanded
        ur, uc = u // padded, u % padded
        gu = node[u, 1]
        up, down = node[u - padded, 0] >= 0.0, node[u + padded, 0] >= 0.0
        left, right = node[u - 1, 0] >= 0.0, node[u + 1, 0] >= 0.0
        for k in range(8):
            if k == 0:
                ok = up
            elif k == 1:
                ok = down
            elif k == 2:
                ok = left
            elif k == 3:
                ok = right
            elif k == 4:   # a diagonal step needs both cells beside it passable
                ok = up and left
            elif k == 5:
                ok = up and right
            elif k == 6:
                ok = down and left
            else:
                ok = down and right
            if not ok:
                continue
            vr, vc = ur + step_r[k], uc + step_c[k]
            v = vr * padded + vc
            w, seen = node[v, 0], node[v, 2]
            if w < 0.0 or seen == closed:
                continue
            candidate = gu + (w if k < 4 else w * 1.4142135623730951)
            if seen == base and candidate >= node[v, 1]:
                continue
            node[v, 1], node[v, 2], node[v, 3] = candidate, base, u
            h = neutral * _octile(vr, vc, goal_r, goal_c) if use_heuristic else 0.0
            b = int((candidate + h - f0) * per_bucket)
            if b <= bucket:
                if size == keys.shape[0]:
                    keys, ties, items = _grown(keys), _grown(ties), _grown(items)
                size = _push(keys, ties, items, size, candidate + h, h, v)
                continue
            if b >= heads.shape[0]:
                more = np.full(max(2 * heads.shape[0], b + 1), -1, np.int64)
                more[:heads.shape[0]] = heads
                heads = more
            if free >= 0:
                e, free = free, pool_next[free]
            else:
                if pool_used == pool_key.shape[0]:
                    pool_key, pool_tie = _grown(pool_key), _grown(pool_tie)
                    pool_item, pool_next = _grown(pool_item), _grown(pool_next)
                e, pool_used = pool_used, pool_used + 1
            pool_key[e], pool_tie[e], pool_item[e], pool_next[e] = candidate + h, h, v, heads[b]
            heads[b] = e


@njit(cache=True)
def _grown(array):
    out = np.empty(2 * array.shape[0], array.dtype)
    out[:array.shape[0]] = array
    return out


@njit(cache=True)
def _trace(node, goal):
    """Padded indices from the start to `goal`, following parents."""
    count, u = 1, goal
    while node[u, 3] >= 0:
        u = int(node[u, 3])
        count += 1
    out = np.empty(count, np.int64)
    u = goal
    for i in range(count - 1, -1, -1):
        out[i] = u
        u = int(node[u, 3])
    return out


class Workspace:
    """The search's per-cell data, allocated once per costmap size and reused (allocating it for a
    building-sized map would cost more than a typical search): one row of (weight, cost-to-come,
    stamp, parent) per padded cell, so what a step reads about a cell lies together. The weights
    are rebuilt only when the costs or the parameters differ from the last search's."""

    def __init__(self):
        self.shape: tuple[int, int] = (0, 0)
        self.node = np.zeros((0, 4))
        self.base = 0
        self._weights_for: tuple | None = None
        self._costs: np.ndarray | None = None

    def prepare(self, costs: np.ndarray, params: GlobalPlannerParams) -> int:
        """Make the data fit `costs`; returns the stamp of a new search."""
        if costs.shape != self.shape:
            self.shape = costs.shape
            self.node = np.zeros(((costs.shape[0] + 2) * (costs.shape[1] + 2), 4))
            self.base, self._weights_for, self._costs = 0, None, None
        key = (params.neutral_cost, params.cost_factor, params.lethal_cost, params.allow_unknown, params.outline_map)
        if key != self._weights_for or not np.array_equal(costs, self._costs):
            _fill_weights(kernel_costs(costs), float(params.neutral_cost), float(params.cost_factor), int(params.lethal_cost),
                          params.allow_unknown, params.outline_map, self.node)
            self._weights_for, self._costs = key, costs.copy()
        self.base += 2
        return self.base

    def flat(self, row: int, col: int) -> int:
        return (row + 1) * (self.shape[1] + 2) + col + 1

    def cells(self, padded_indices: np.ndarray) -> np.ndarray:
        """(row, col) of padded flat indices."""
        rows, cols = np.divmod(padded_indices, self.shape[1] + 2)
        return np.stack([rows - 1, cols - 1], axis=-1)

    def unpad(self, flat: np.ndarray) -> np.ndarray:
        """A padded flat array as the costmap's (H, W) grid."""
        return flat.reshape(self.shape[0] + 2, self.shape[1] + 2)[1:-1, 1:-1]


@dataclass
class Search:
    """One search's outcome; it reads the workspace, so it is valid until the next search on it."""
    found: bool
    expanded: int
    workspace: Workspace
    base: int

    def path(self, cell: tuple[int, int]) -> np.ndarray:
        """(row, col) of the cells from the start to a reached cell."""
        return self.workspace.cells(_trace(self.workspace.node, self.workspace.flat(*cell)))

    def expanded_mask(self) -> np.ndarray:
        """(H, W): the cells expanded; after an exhausted search, exactly the reachable cells."""
        return self.workspace.unpad(self.workspace.node[:, 2] == self.base + 1)

    def cost_to_come(self) -> np.ndarray:
        """(H, W) cost from the start (inf where the search never got)."""
        node = self.workspace.node
        return self.workspace.unpad(np.where(node[:, 2] >= self.base, node[:, 1], np.inf))

    def cost(self, cell: tuple[int, int]) -> float:
        g, stamp = self.workspace.node[self.workspace.flat(*cell), 1:3]
        return float(g) if stamp >= self.base else math.inf


def search(costs: np.ndarray, start: tuple[int, int], goal: tuple[int, int], params: GlobalPlannerParams,
           use_dijkstra: bool | None = None, workspace: Workspace | None = None) -> Search:
    """A* (or Dijkstra) from cell start to cell goal (row, col) over uint8 costs."""
    costs = np.ascontiguousarray(costs, np.uint8)
    workspace = workspace or Workspace()
    base = workspace.prepare(costs, params)
    dijkstra = params.use_dijkstra if use_dijkstra is None else use_dijkstra
    found, expanded = _search(workspace.node, costs.shape[1] + 2, workspace.flat(*start), workspace.flat(*goal),
                              float(params.neutral_cost), not dijkstra, base)
    return Search(bool(found), int(expanded), workspace, base)


# ---------------------------------------------------------------- orientations

def _headings(xy: np.ndarray, window: int) -> np.ndarray:
    """ROS setAngleBasedOnPositionDerivative for every point but the last."""
    n = len(xy)
    index = np.arange(n - 1)
    i0, i1 = np.maximum(index - window, 0), np.minimum(index + window, n - 1)
    return np.arctan2(xy[i1, 1] - xy[i0, 1], xy[i1, 0] - xy[i0, 0])


def _wrap(angle):
    return (np.asarray(angle) + math.pi) % (2 * math.pi) - math.pi


def _interpolate(yaw: np.ndarray, first: int, last: int) -> None:
    """Blend yaw[first] into yaw[last] along the shortest turn (ROS OrientationFilter::interpolate,
    whose increment ROS multiplies by i instead of i − first)."""
    step = _wrap(yaw[last] - yaw[first]) / max(last - first, 1)
    yaw[first:last + 1] = _wrap(yaw[first] + step * np.arange(last - first + 1))


def orientations(xy: np.ndarray, start_yaw: float, goal_yaw: float, mode: int, window: int) -> np.ndarray:
    """Yaw of each path point by ROS's orientation_mode; the last point takes the goal's yaw."""
    n = len(xy)
    yaw = np.zeros(n)
    if n == 0:
        return yaw
    yaw[-1] = goal_yaw
    if n == 1:
        return yaw
    if mode in (1, 3, 4, 5, 6):
        yaw[:-1] = _headings(xy, window) + {1: 0.0, 3: 0.0, 4: math.pi, 5: -math.pi / 2, 6: math.pi / 2}[mode]
        yaw[:-1] = _wrap(yaw[:-1])
    if mode == 2:
        yaw[0] = start_yaw
        _interpolate(yaw, 0, n - 1)
    elif mode == 3:
        i = n - 3   # back from the end over the last straight stretch (turns under 0.35 rad)
        if i > 0:
            last = yaw[i]
            while i > 0 and abs(_wrap(last - yaw[i - 1])) <= 0.35:
                i -= 1
        i = max(i, 0)
        yaw[0] = start_yaw
        _interpolate(yaw, i, n - 1)
    return yaw


# ---------------------------------------------------------------- planning

@dataclass
class PlanResult:
    status: str                         # OK, NO_PATH, GOAL_IN_OBSTACLE or OFF_MAP
    message: str = ""
    poses: np.ndarray = None            # (N, 3) x, y, yaw in the costmap's frame
    cells: np.ndarray = None            # (M, 2) row, col of the grid path
    cost: float = math.inf              # summed step costs of the grid path
    expanded: int = 0                   # cells the search expanded
    goal_adjusted: bool = False         # the path ends at another cell than the goal's (tolerance)
    potential: np.ndarray | None = None  # (H, W) cost-to-come, with visualize_potential

    def __post_init__(self):
        if self.poses is None:
            self.poses = np.zeros((0, 3))
        if self.cells is None:
            self.cells = np.zeros((0, 2), np.int64)

    @property
    def ok(self) -> bool:
        return self.status == OK

    @property
    def length(self) -> float:
        """Length of the returned path, m."""
        return float(np.hypot(*np.diff(self.poses[:, :2], axis=0).T).sum()) if len(self.poses) > 1 else 0.0


def passable(costs: np.ndarray, rows, cols, params: GlobalPlannerParams) -> np.ndarray:
    """Whether the search may enter cells (rows, cols) (the start cell aside)."""
    rows, cols = np.asarray(rows), np.asarray(cols)
    value = costs[rows, cols]
    ok = np.where(value == NO_INFORMATION, params.allow_unknown, value < params.lethal_cost)
    if params.outline_map:
        height, width = costs.shape
        ok &= (rows > 0) & (cols > 0) & (rows < height - 1) & (cols < width - 1)
    return ok


GROWTH_MARGIN = 2        # cells of unknown beyond a start or goal the grid grows to hold (outline_map)


def grown_to_hold(costs: np.ndarray, info: MapMetaData, poses) -> tuple[np.ndarray, MapMetaData]:
    """The costs and geometry grown with unknown cells until they hold every pose (x, y, …) with
    GROWTH_MARGIN to spare: a goal not yet seen lies in unknown space, which allow_unknown plans
    through (move_base's planner does the same on a costmap sized to hold it). Unchanged when every
    pose is on the grid already."""
    u, v = grid_coords(info, [float(pose[0]) for pose in poses], [float(pose[1]) for pose in poses])
    cols, rows = np.floor(u).astype(np.int64), np.floor(v).astype(np.int64)
    if in_grid(info, rows, cols).all():
        return costs, info
    below = max(0, GROWTH_MARGIN - int(rows.min()))
    left = max(0, GROWTH_MARGIN - int(cols.min()))
    height = max(info.height, int(rows.max()) + 1 + GROWTH_MARGIN) + below
    width = max(info.width, int(cols.max()) + 1 + GROWTH_MARGIN) + left
    grown = np.full((height, width), NO_INFORMATION, np.uint8)
    grown[below:below + info.height, left:left + info.width] = costs
    x0, y0 = cell_to_world(info, -below - 0.5, -left - 0.5)     # the corner of the new first cell
    origin = MapMetaData(resolution=info.resolution, width=width, height=height,
                         origin=type(info.origin)(float(x0), float(y0), info.origin.theta))
    return grown, origin


class GlobalPlanner:
    def __init__(self, params: GlobalPlannerParams | None = None):
        self.params = params or GlobalPlannerParams()
        self.workspace = Workspace()

    def _candidates(self, costs: np.ndarray, info: MapMetaData, gu: float, gv: float) -> np.ndarray:
        """(K, 2) row, col of the passable cells whose centres lie within default_tolerance of the
        goal (grid coordinates gu, gv), nearest first."""
        reach = self.params.default_tolerance / info.resolution
        r0, r1 = max(int(gv - reach) - 1, 0), min(int(gv + reach) + 2, info.height)
        c0, c1 = max(int(gu - reach) - 1, 0), min(int(gu + reach) + 2, info.width)
        rows, cols = np.mgrid[r0:r1, c0:c1]
        d2 = (cols + 0.5 - gu) ** 2 + (rows + 0.5 - gv) ** 2
        keep = (d2 <= reach * reach) & passable(costs, rows, cols, self.params)
        order = np.lexsort((cols[keep], rows[keep], d2[keep]))
        return np.stack([rows[keep][order], cols[keep][order]], axis=1)

    def plan(self, costs: np.ndarray, info: MapMetaData, start, goal) -> PlanResult:
        """A path from start to goal poses (x, y, yaw in the costmap's frame) over uint8 costs."""
        p = self.params
        costs = np.ascontiguousarray(costs, np.uint8)
        if costs.shape != (info.height, info.width):
            raise ValueError(f"costs of shape {costs.shape} do not match the grid's {info.height} x {info.width}")
        if p.allow_unknown:
            costs, info = grown_to_hold(costs, info, (start, goal))
        (su, sv), (gu, gv) = ((float(t) for t in grid_coords(info, pose[0], pose[1])) for pose in (start, goal))
        s_cell, g_cell = (int(math.floor(sv)), int(math.floor(su))), (int(math.floor(gv)), int(math.floor(gu)))
        for what, pose, cell in (("start", start, s_cell), ("goal", goal, g_cell)):
            if not in_grid(info, *cell):
                return PlanResult(OFF_MAP, f"the {what} ({pose[0]:.2f}, {pose[1]:.2f}) is off the costmap")
        goal_free = g_cell == s_cell or bool(passable(costs, *g_cell, p))
        candidates = self._candidates(costs, info, gu, gv) if p.default_tolerance > 0 else np.zeros((0, 2), int)
        if not goal_free and not len(candidates):
            why = "is on the costmap's border (outline_map)" if costs[g_cell] < p.lethal_cost or (
                costs[g_cell] == NO_INFORMATION and p.allow_unknown) else f"has cost {costs[g_cell]}"
            return PlanResult(GOAL_IN_OBSTACLE, f"the goal cell {g_cell} {why} and no passable cell lies within "
                                                f"default_tolerance {p.default_tolerance} m")
        target = g_cell if goal_free else tuple(candidates[0])
        result = search(costs, s_cell, target, p, workspace=self.workspace)
        if not result.found:
            reachable = candidates[result.expanded_mask()[candidates[:, 0], candidates[:, 1]]]
            if not len(reachable):
                within = f" or any cell within {p.default_tolerance} m of it" if p.default_tolerance > 0 else ""
                return PlanResult(NO_PATH if goal_free else GOAL_IN_OBSTACLE,
                                  f"no path from cell {s_cell} to the goal cell {g_cell}{within}",
                                  expanded=result.expanded, potential=self._potential(result))
            target = tuple(reachable[0])
        target = tuple(int(v) for v in target)
        cells = result.path(target)
        adjusted = target != g_cell
        points = np.column_stack([cells[:, 1] + 0.5, cells[:, 0] + 0.5])
        points[0] = su, sv
        if len(points) == 1:   # start and goal share a cell
            points = np.vstack([points, points])
        if not adjusted:
            points[-1] = gu, gv
        if not p.use_grid_path:
            points = smooth(points, costs, p.smooth_weight_data, p.smooth_weight_smooth, p.smooth_max_iterations,
                            p.smooth_tolerance)
        x, y = cell_to_world(info, points[:, 1] - 0.5, points[:, 0] - 0.5)
        xy = np.column_stack([x, y])
        yaw = orientations(xy, float(start[2]), float(goal[2]), p.orientation_mode, p.orientation_window_size)
        message = f"goal moved to the nearest reachable cell {target} within default_tolerance" if adjusted else ""
        return PlanResult(OK, message, poses=np.column_stack([xy, yaw]), cells=cells, cost=result.cost(target),
                          expanded=result.expanded, goal_adjusted=adjusted, potential=self._potential(result))

    def _potential(self, result: Search) -> np.ndarray | None:
        return result.cost_to_come().astype(np.float32) if self.params.visualize_potential else None


def warm_up() -> None:
    """Compile (or load from cache) the search and smoothing kernels."""
    costs = np.zeros((4, 4), np.uint8)
    planner = GlobalPlanner(GlobalPlannerParams(outline_map=False))
    info = MapMetaData(resolution=1.0, width=4, height=4)
    planner.plan(costs, info, (0.5, 0.5, 0.0), (3.5, 2.5, 0.0))
