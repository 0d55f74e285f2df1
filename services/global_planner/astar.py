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
consistent, so A* and Dijkstra return paths of the same (optimal) cost. Both run in numba over a
ring of buckets of f, stacks without any ordering inside (no heap): a cell reached more cheaply
after its expansion is expanded again, so the costs stay exact up to rounding (see _search).

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
BUCKETS_PER_STEP = 10   # queue buckets per neutral_cost of f; measured fastest on the Willow bench
SQRT2 = math.sqrt(2.0)
# a way to a cell counts as cheaper only below this fraction of the known one: ways whose costs
# differ in the last bits only (the same steps summed in another order) are equal, else each
# would expand the cell again (a quarter of A*'s expansions on the Willow bench)
ROUNDING = 1.0 - 1e-15


# ---------------------------------------------------------------- the search kernel
#
# The search runs on a copy of the grid padded by one impassable cell all round, flattened, so a
# neighbour is index + offset with no bounds checks. The copy holds one byte per cell, a code:
# the cost itself where passable, lethal_cost - 1 for a passable unknown cell (it costs as that),
# IMPASSABLE elsewhere; weights[code] is the cost of entering the cell per cell length. One byte a
# cell keeps what a search reads of a building-sized map in the processor's cache.

IMPASSABLE = 255   # never a passable cost's code: a passable cost is below lethal_cost <= 255


@njit(cache=True)
def _fill_codes(costs, lethal, allow_unknown, outline, codes):
    height, width = costs.shape
    padded = width + 2
    codes[:padded] = IMPASSABLE
    codes[(height + 1) * padded:] = IMPASSABLE
    unknown = lethal - 1 if allow_unknown else IMPASSABLE
    for r in range(height):
        row = (r + 1) * padded
        codes[row] = codes[row + padded - 1] = IMPASSABLE
        for c in range(width):
            value = costs[r, c]
            if outline and (r == 0 or c == 0 or r == height - 1 or c == width - 1):
                code = IMPASSABLE
            elif value == 255:
                code = unknown
            elif value < lethal:
                code = value
            else:
                code = IMPASSABLE
            codes[row + c + 1] = code


def _weights(params: GlobalPlannerParams) -> np.ndarray:
    """(256,) the cost of entering a cell per cell length, by its code."""
    weights = params.neutral_cost + params.cost_factor * np.arange(256, dtype=np.float64)
    weights[params.lethal_cost:] = -1.0
    weights[IMPASSABLE] = -1.0
    return weights


@njit(cache=True, inline="always")
def _row_col(v, inverse, padded):
    """(row, column) of padded index v: v // padded without a division, corrected for rounding."""
    r = int(v * inverse)
    c = np.int64(v) - r * padded
    if c < 0:
        r, c = r - 1, c + padded
    elif c >= padded:
        r, c = r + 1, c - padded
    return r, c


@njit(cache=True, inline="always")
def _octile(dr, dc):
    """The octile distance of a step of |dr| rows and |dc| columns, in cells."""
    return max(dr, dc) + (SQRT2 - 1.0) * min(dr, dc)


@njit(cache=True, inline="always")
def _heuristic(v, inverse, padded, goal_r, goal_c, neutral):
    """neutral_cost × the octile distance from padded index v to the goal's (row, column)."""
    r, c = _row_col(v, inverse, padded)
    return neutral * _octile(abs(r - goal_r), abs(c - goal_c))


BLOCK = 32   # queue entries per block of a bucket's stack


@njit(cache=True)
def _search(codes, weights, g, stamp, padded, start, goal, neutral, use_heuristic, base, per_bucket, buckets):
    """Best-first search over padded flat indices from `start` until the cost to `goal` is final
    (True) or the reachable cells are exhausted (False). codes and weights as _fill_codes and
    _weights; g (cost-to-come) and stamp are reused across searches: a cell is untouched while its
    stamp < base, reached at base, expanded at base + 1; g is read only where the stamp says it is
    this search's. No parents are kept: the path is read off g afterwards (_descend).

    The queue is buckets of f, 1/per_bucket wide, in a ring of `buckets` (a power of two, more than
    the largest rise of f in one step spans), each a stack: no heap and no ordering within a bucket. Within a
    bucket a cell may be expanded before a cheaper way to it is found (A*'s f may stay level along a
    step); it is then opened and expanded again, so every cost-to-come is exact (up to ROUNDING)
    once no entry below it is left; an entry of a cell expanded since it was made is skipped. The cost to the goal is final when the lowest bucket left starts above it:
    every entry with a lower f has been expanded. Returns (found, expanded).

    Written for the time per expansion (about 35 ns on the Willow bench, from 50), which is all
    that is left to gain: A* expands little more than the cells any exact A* with this heuristic
    must. Hence:
    - indices are unsigned (np.uint64 for cells, np.uint32 in the queue): numba checks every
      array access with a signed index for a negative one (to count from the end), a fifth of the
      time; u + ONE and not u + 1, as uint64 + int64 is int64 to numba;
    - the eight neighbours are written out rather than looped over (a loop, even over tables of
      offsets, measured 15-25 % slower), and their heuristics come from the expanded cell's
      (row, column), found once;
    - a bucket's stack lives in blocks of BLOCK entries (a linked list of blocks, not of entries):
      a push or pop touches one block, and every bucket owns block `slot`, so only a bucket deeper
      than a block takes blocks from the free list. Each bucket stays last in, first out, the
      order that decides which cells are expanded twice;
    - no helper takes an array: numba counts references on arrays passed to a function, even an
      inlined one, which made such a relax helper about ten times slower.
    """
    goal_r, goal_c = goal // padded, goal % padded
    ring, inverse = np.uint64(buckets - 1), 1.0 / padded
    P, ONE, goal_u = np.uint64(padded), np.uint64(1), np.uint64(goal)
    hn = neutral if use_heuristic else 0.0   # h = hn × octile: 0 for Dijkstra
    # the stacks: block b holds blocks[b, :], link[b] the block below it (or the next free block);
    # bucket slot's top block is head[slot], filled to top[slot]
    NONE = np.uint32(0xFFFFFFFF)
    blocks = np.empty((buckets + 256, BLOCK), np.uint32)
    link = np.empty(buckets + 256, np.uint32)
    head = np.arange(buckets).astype(np.uint32)
    top = np.zeros(buckets, np.uint32)
    fresh, free = np.uint32(buckets), NONE   # the first block never used; the free blocks
    opened = np.empty(8, np.uint64)   # the cells an expansion opens, in order, and their buckets
    opened_b = np.empty(8, np.int64)
    reached, closed = np.uint8(base), np.uint8(base + 1)
    g[start], stamp[start] = 0.0, reached
    f0 = _heuristic(start, inverse, padded, goal_r, goal_c, neutral) if use_heuristic else 0.0
    blocks[0, 0], top[0] = start, 1
    bucket, pending, expanded = 0, 1, 0
    goal_cost = 0.0 if start == goal else np.inf
    while pending > 0:
        slot = np.uint64(bucket) & ring
        if f0 + (bucket - 1) / per_bucket >= goal_cost:   # (one bucket late: f's rounding)
            break
        while True:   # pop the bucket's top entry
            n = top[slot]
            if n == 0:
                block = head[slot]
                if block == slot:
                    break   # the bucket is empty
                head[slot], link[block], free = link[block], free, block   # free the empty top block
                n = np.uint32(BLOCK)
            n -= np.uint32(1)
            top[slot] = n
            u = np.uint64(blocks[head[slot], n])
            pending -= 1
            if stamp[u] == closed:
                continue   # expanded already since this entry was made
            gu = g[u]
            r, c = _row_col(u, inverse, padded)
            # rows and columns from the goal of u's neighbours: above, level, below; left, level, right
            dr0, dr1, dr2 = abs(r - 1 - goal_r), abs(r - goal_r), abs(r + 1 - goal_r)
            dc0, dc1, dc2 = abs(c - 1 - goal_c), abs(c - goal_c), abs(c + 1 - goal_c)
            if goal_cost < np.inf and gu + hn * _octile(dr1, dc1) >= goal_cost:
                continue   # cannot lead to a cheaper goal
            stamp[u] = closed
            expanded += 1
            if fresh + 8 > blocks.shape[0]:   # room for this expansion's new blocks
                blocks, link = _more_blocks(blocks, link)
            # relax the neighbours: open those reached more cheaply (with their bucket of f) ...
            up, down, left, right = codes[u - P], codes[u + P], codes[u - ONE], codes[u + ONE]
            m = 0
            if up != IMPASSABLE:
                v, candidate = u - P, gu + weights[up]
                if stamp[v] < reached or candidate < g[v] * ROUNDING:
                    g[v], stamp[v] = candidate, reached
                    opened[m], opened_b[m], m = v, int((candidate + hn * _octile(dr0, dc1) - f0) * per_bucket), m + 1
            if down != IMPASSABLE:
                v, candidate = u + P, gu + weights[down]
                if stamp[v] < reached or candidate < g[v] * ROUNDING:
                    g[v], stamp[v] = candidate, reached
                    opened[m], opened_b[m], m = v, int((candidate + hn * _octile(dr2, dc1) - f0) * per_bucket), m + 1
            if left != IMPASSABLE:
                v, candidate = u - ONE, gu + weights[left]
                if stamp[v] < reached or candidate < g[v] * ROUNDING:
                    g[v], stamp[v] = candidate, reached
                    opened[m], opened_b[m], m = v, int((candidate + hn * _octile(dr1, dc0) - f0) * per_bucket), m + 1
            if right != IMPASSABLE:
                v, candidate = u + ONE, gu + weights[right]
                if stamp[v] < reached or candidate < g[v] * ROUNDING:
                    g[v], stamp[v] = candidate, reached
                    opened[m], opened_b[m], m = v, int((candidate + hn * _octile(dr1, dc2) - f0) * per_bucket), m + 1
            # a diagonal step needs both cells beside it passable
            if up != IMPASSABLE and left != IMPASSABLE and codes[u - P - ONE] != IMPASSABLE:
                v = u - P - ONE
                candidate = gu + weights[codes[v]] * SQRT2
                if stamp[v] < reached or candidate < g[v] * ROUNDING:
                    g[v], stamp[v] = candidate, reached
                    opened[m], opened_b[m], m = v, int((candidate + hn * _octile(dr0, dc0) - f0) * per_bucket), m + 1
            if up != IMPASSABLE and right != IMPASSABLE and codes[u - P + ONE] != IMPASSABLE:
                v = u - P + ONE
                candidate = gu + weights[codes[v]] * SQRT2
                if stamp[v] < reached or candidate < g[v] * ROUNDING:
                    g[v], stamp[v] = candidate, reached
                    opened[m], opened_b[m], m = v, int((candidate + hn * _octile(dr0, dc2) - f0) * per_bucket), m + 1
            if down != IMPASSABLE and left != IMPASSABLE and codes[u + P - ONE] != IMPASSABLE:
                v = u + P - ONE
                candidate = gu + weights[codes[v]] * SQRT2
                if stamp[v] < reached or candidate < g[v] * ROUNDING:
                    g[v], stamp[v] = candidate, reached
                    opened[m], opened_b[m], m = v, int((candidate + hn * _octile(dr2, dc0) - f0) * per_bucket), m + 1
            if down != IMPASSABLE and right != IMPASSABLE and codes[u + P + ONE] != IMPASSABLE:
                v = u + P + ONE
                candidate = gu + weights[codes[v]] * SQRT2
                if stamp[v] < reached or candidate < g[v] * ROUNDING:
                    g[v], stamp[v] = candidate, reached
                    opened[m], opened_b[m], m = v, int((candidate + hn * _octile(dr2, dc2) - f0) * per_bucket), m + 1
            # ... and push them, in that order
            for i in range(m):
                v = opened[i]
                if v == goal_u:
                    goal_cost = g[v]
                    continue   # nothing beyond the goal can make it cheaper
                t = np.uint64(max(opened_b[i], bucket)) & ring
                n = top[t]
                if n == BLOCK:   # the top block is full: put a new one on it
                    if free != NONE:
                        new, free = free, link[free]
                    else:
                        new, fresh = fresh, fresh + np.uint32(1)
                    link[new], head[t], n = head[t], new, np.uint32(0)
                blocks[head[t], n] = v
                top[t] = n + np.uint32(1)
                pending += 1
        bucket += 1
    if goal_cost < np.inf or start == goal:
        stamp[goal] = closed
        return True, expanded
    return False, expanded


@njit(cache=True)
def _more_blocks(blocks, link):
    """The queue's blocks and links, with room for as many blocks again."""
    count = blocks.shape[0]
    more_blocks, more_link = np.empty((2 * count, blocks.shape[1]), blocks.dtype), np.empty(2 * count, link.dtype)
    more_blocks[:count], more_link[:count] = blocks, link
    return more_blocks, more_link


@njit(cache=True)
def _descend(codes, weights, g, stamp, padded, start, goal, reached, neutral):
    """Padded indices from the start to `goal` (reached by the last search): from the goal, step
    to the neighbour whose cost-to-come plus the step into the current cell is least, until the
    start. That neighbour is the one the search came from (or one as cheap): the cost-to-come of
    a cell the path passes is final, so the costs fall strictly along it (every step costs at
    least neutral_cost) down to the start's 0."""
    out = np.empty(int(g[goal] / neutral) + 2, np.int64)   # every step costs at least neutral
    out[0], count, u = goal, 1, goal
    while u != start:
        up, down = codes[u - padded] != IMPASSABLE, codes[u + padded] != IMPASSABLE
        left, right = codes[u - 1] != IMPASSABLE, codes[u + 1] != IMPASSABLE
        w = weights[codes[u]]
        best, best_cost = -1, np.inf
        for k in range(8):
            if k < 4:
                v = u + (-padded, padded, -1, 1)[k]
                step = w
            else:   # the corner rule holds both ways: the same two cells lie beside the step
                vertical = up if k < 6 else down
                side = left if k % 2 == 0 else right
                if not (vertical and side):
                    continue
                v = u + (-padded if k < 6 else padded) + (-1 if k % 2 == 0 else 1)
                step = w * SQRT2
            if stamp[v] < reached or (codes[v] == IMPASSABLE and v != start):
                continue
            if g[v] + step < best_cost:
                best, best_cost = v, g[v] + step
        out[count], count, u = best, count + 1, best
    return out[:count][::-1].copy()


class Workspace:
    """The search's per-cell data, allocated once per costmap size and reused (allocating it for a
    building-sized map would cost more than a typical search): the padded cells' codes, and per
    cell the cost-to-come and the stamp of the searches. The stamp is one byte (it fits the
    processor's second-level cache with the codes, and a relaxation of a cell not yet reached reads
    nothing else); when its values run out it is cleared. The codes are rebuilt only when the
    costs or the passability parameters differ from the last search's."""

    def __init__(self):
        self.shape: tuple[int, int] = (0, 0)
        self.codes = np.zeros(0, np.uint8)
        self.g = np.zeros(0)
        self.stamp = np.zeros(0, np.uint8)
        self.weights = np.zeros(256)
        self.base = 0
        self._codes_for: tuple | None = None
        self._costs: np.ndarray | None = None

    def prepare(self, costs: np.ndarray, params: GlobalPlannerParams) -> int:
        """Make the data fit `costs`; returns the stamp of a new search."""
        if costs.shape != self.shape:
            self.shape = costs.shape
            size = (costs.shape[0] + 2) * (costs.shape[1] + 2)
            self.codes, self.g, self.stamp = np.empty(size, np.uint8), np.zeros(size), np.zeros(size, np.uint8)
            self.base, self._codes_for, self._costs = 0, None, None
        key = (params.lethal_cost, params.allow_unknown, params.outline_map)
        if key != self._codes_for or not np.array_equal(costs, self._costs):
            _fill_codes(kernel_costs(costs), int(params.lethal_cost), params.allow_unknown, params.outline_map, self.codes)
            self._codes_for, self._costs = key, costs.copy()
        self.weights = _weights(params)
        if self.base + 3 > np.iinfo(self.stamp.dtype).max:   # no stamps left: every cell untouched again
            self.stamp[:] = 0
            self.base = 0
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
    start: int          # the start's padded index
    neutral: float      # the least a step costs

    def path(self, cell: tuple[int, int]) -> np.ndarray:
        """(row, col) of the cells from the start to a reached cell."""
        if self.cost(cell) == math.inf:   # the descent needs this search's cost-to-come at its start
            raise ValueError(f"cell {cell} was not reached by the search")
        workspace = self.workspace
        return workspace.cells(_descend(workspace.codes, workspace.weights, workspace.g, workspace.stamp,
                                        workspace.shape[1] + 2, self.start, workspace.flat(*cell), self.base,
                                        self.neutral))

    def expanded_mask(self) -> np.ndarray:
        """(H, W): the cells expanded; after an exhausted search, exactly the reachable cells."""
        return self.workspace.unpad(self.workspace.stamp == self.base + 1)

    def cost_to_come(self) -> np.ndarray:
        """(H, W) cost from the start (inf where the search never got)."""
        workspace = self.workspace
        return workspace.unpad(np.where(workspace.stamp >= self.base, workspace.g, np.inf))

    def cost(self, cell: tuple[int, int]) -> float:
        index = self.workspace.flat(*cell)
        return float(self.workspace.g[index]) if self.workspace.stamp[index] >= self.base else math.inf


def search(costs: np.ndarray, start: tuple[int, int], goal: tuple[int, int], params: GlobalPlannerParams,
           use_dijkstra: bool | None = None, workspace: Workspace | None = None) -> Search:
    """A* (or Dijkstra) from cell start to cell goal (row, col) over uint8 costs."""
    costs = np.ascontiguousarray(costs, np.uint8)
    if (costs.shape[0] + 2) * (costs.shape[1] + 2) > 0xFFFFFFFF:   # the queue holds cells as uint32
        raise ValueError(f"a costmap of {costs.shape[0]} x {costs.shape[1]} cells is too large to search")
    workspace = workspace or Workspace()
    base = workspace.prepare(costs, params)
    dijkstra = params.use_dijkstra if use_dijkstra is None else use_dijkstra
    neutral = float(params.neutral_cost)
    per_bucket = BUCKETS_PER_STEP / neutral
    steepest = (neutral + params.cost_factor * (params.lethal_cost - 1) + neutral) * SQRT2   # f's largest rise
    origin = workspace.flat(*start)
    found, expanded = _search(workspace.codes, workspace.weights, workspace.g, workspace.stamp, costs.shape[1] + 2, origin,
                              workspace.flat(*goal), neutral, not dijkstra, base, per_bucket,
                              1 << (int(steepest * per_bucket) + 3).bit_length())
    return Search(bool(found), int(expanded), workspace, base, origin, neutral)


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
