"""The footprint collision check of the local planner: may the robot stand at a pose on the local
costmap? DWA's rollouts, the rotation shim's turns, the final approach's line and the path
follower's path ahead are all held to it (one `FootprintCheck`, built by control.py).

A pose is illegal when its centre cell is inscribed, lethal, unknown or off the grid, or — when its
centre cost is at least `check_cost` (footprint_check_cost: the circumscribed cost) or its centre
cell lies within the outline's reach of a lethal or unknown cell — when any point of the outline
lies on a lethal or unknown cell or off the grid. The outline is the footprint grown by the
collision monitor's stop zone (stop_padding), or, when the robot already stands within that zone,
less (`FootprintCheck.setup`). Not every outline point is looked at: a point's clearance to the
nearest lethal or unknown cell says how many next points cannot touch one (`outline_skips`). The
kernels here are numba's; dwa.py's rollout calls `trajectory_cost` on every trajectory.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np
from numba import njit

from ...schemas.messages import MapMetaData
from ...geometry.footprint import cells_inside, pad, transform
from ...geometry.grid import cell_to_world, in_grid, kernel_costs, world_to_cell
from ...geometry.distance import nearest_cells
from ...geometry.polygons import densify, point_segment_distance, points_in_polygons, transform_points
from ...geometry.se2 import inverse
from ..costmap.layers import INSCRIBED_INFLATED_OBSTACLE, LETHAL_OBSTACLE, inflation_cost

# the outline's points are at most this many cells apart (footprint_outline's spacing)
OUTLINE_SPACING_CELLS = 0.5
# m deeper over its forgiven cells than where it was wedged that a pose may bring the outline: sliding
# along a row of cells, the outline's edge passes their centres a few millimetres nearer or farther
KEEP_AWAY_SLACK = 0.005


@dataclass(frozen=True)
class PoseCheck:
    """What one cycle's poses are checked with (`FootprintCheck.setup`)."""
    outline: np.ndarray     # (K, 2) points along the (padded) footprint, robot frame
    near: np.ndarray        # (H, W) bool: where the outline is checked whatever the centre cost
    # (H, W) int8: how many outline points on from one in this cell (either way along the outline) cannot lie on a
    # lethal or unknown cell or off the grid (`outline_skips`); -1 on lethal and unknown cells
    skips: np.ndarray
    # the centre cost from which a pose is illegal whatever its outline: inscribed, unless the robot
    # already stands on an inscribed cell (a tracking error put it there): then lethal, and the
    # outline alone decides, as ROS does for a polygon footprint, so the robot can drive out again
    centre_limit: int = INSCRIBED_INFLATED_OBSTACLE
    # even the robot's own outline lies on a lethal or unknown cell where it stands (`escape_check`
    # lets it drive off them)
    wedged: bool = False
    # (F, 2) the centres of the cells `escape_check` no longer counts, in the grid's frame, and how
    # deep the deepest of them lay inside the outline where they were forgiven (`keeps_away`)
    forgiven: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))
    forgiven_depth: float = -math.inf


def _depth_inside(outline: np.ndarray, points: np.ndarray, poses: np.ndarray) -> np.ndarray:
    """(N,) for each pose (N, 3), how deep the deepest of `points` (P, 2; the grid's frame) lies
    inside `outline` (K, 2, the polygon in the robot frame) placed there: its distance to the
    outline, negative outside."""
    local = transform_points(points, inverse(poses))                       # (N, P, 2) robot frames
    edges = point_segment_distance(local[:, :, None, :], outline[None, None, :, :],
                                   np.roll(outline, -1, axis=0)[None, None, :, :]).min(axis=2)
    inside = points_in_polygons(local, outline[None])[..., 0]
    return np.where(inside, edges, -edges).max(axis=1)


def outline_skips(clearance: np.ndarray, resolution: float) -> np.ndarray:
    """PoseCheck.skips from the clearance (m from each cell's centre to the nearest lethal or unknown
    cell's, inf without one): a point of a cell is that far less a cell's diagonal (either point
    anywhere in its cell) from any lethal or unknown cell, and from the cells just off the grid as
    from lethal ones; the outline's next points are at most OUTLINE_SPACING_CELLS apart."""
    height, width = clearance.shape
    off_grid = np.minimum.outer(np.minimum(np.arange(1, height + 1), np.arange(height, 0, -1)),
                                np.minimum(np.arange(1, width + 1), np.arange(width, 0, -1))) * resolution
    room = np.minimum(clearance, off_grid) - (math.sqrt(2.0) * resolution + 1e-9)   # and a margin for rounding
    skips = np.clip(np.floor(room / (OUTLINE_SPACING_CELLS * resolution)), 0, np.iinfo(np.int8).max).astype(np.int8)
    skips[clearance == 0.0] = -1
    return skips


@njit(cache=True, inline="always")
def _cell(x, y, grid, height, width):
    """(row, col) of the cell under a world point; (-1, -1) off the grid. grid as in kernel_grid."""
    dx, dy = x - grid[0], y - grid[1]
    u = (grid[2] * dx + grid[3] * dy) * grid[4]
    v = (-grid[3] * dx + grid[2] * dy) * grid[4]
    if u < 0.0 or v < 0.0 or u >= width or v >= height:
        return -1, -1
    return int(v), int(u)


@njit(cache=True, inline="always")
def _outline_clear(skips, x, y, c, s, grid, outline):
    """Whether no point of the outline around (x, y), heading (cos, sin) = (c, s), lies on a lethal or
    unknown cell or off the grid; skips as in PoseCheck. Walked from both ends at once: two lookups
    that do not wait for each other."""
    height, width = skips.shape
    first, last = 0, outline.shape[0] - 1
    while first <= last:
        row, col = _cell(x + c * outline[first, 0] - s * outline[first, 1],
                         y + s * outline[first, 0] + c * outline[first, 1], grid, height, width)
        back_row, back_col = _cell(x + c * outline[last, 0] - s * outline[last, 1],
                                   y + s * outline[last, 0] + c * outline[last, 1], grid, height, width)
        if row < 0 or skips[row, col] < 0 or back_row < 0 or skips[back_row, back_col] < 0:
            return False
        first += 1 + skips[row, col]
        last -= 1 + skips[back_row, back_col]
    return True


@njit(cache=True)
def trajectory_cost(poses, headings, costs, near, skips, grid, outline, check_cost, centre_limit):
    """(count, worst): how many of the poses (N, 3), from the first, the robot may stand at, and the
    highest centre cost among those. A pose is illegal when its centre cell is off the grid or at
    centre_limit or above (inscribed, lethal, unknown), or when — from check_cost on, or where
    `near` — a point of the outline lies on a lethal or unknown cell or off the grid. headings (N, 2)
    are the cos and sin of each pose's yaw (a rollout turns them without trigonometry); near, skips
    and centre_limit as in PoseCheck, grid as in kernel_grid. One call checks a whole trajectory:
    a numba call per pose would take and release each array it is given, which costs more than the
    check itself."""
    height, width = costs.shape
    worst = 0
    for i in range(poses.shape[0]):
        x, y = poses[i, 0], poses[i, 1]
        row, col = _cell(x, y, grid, height, width)
        if row < 0 or costs[row, col] >= centre_limit:
            return i, worst
        cost = int(costs[row, col])
        if cost >= check_cost or near[row, col]:
            if not _outline_clear(skips, x, y, headings[i, 0], headings[i, 1], grid, outline):
                return i, worst
        worst = max(worst, cost)
    return poses.shape[0], worst


@njit(cache=True)
def _check_poses(poses, costs, near, skips, grid, outline, check_cost, centre_limit, legal):
    headings = np.empty((1, 2))
    for i in range(poses.shape[0]):
        headings[0, 0], headings[0, 1] = math.cos(poses[i, 2]), math.sin(poses[i, 2])
        legal[i] = trajectory_cost(poses[i:i + 1], headings, costs, near, skips, grid, outline, check_cost,
                                   centre_limit)[0] == 1


def _clearance_and_skips(blocked: np.ndarray, resolution: float) -> tuple[np.ndarray, np.ndarray]:
    """(clearance, skips) of the blocked (lethal or unknown) cells: m from each cell's centre to the
    nearest blocked cell's, and outline_skips."""
    clearance = np.sqrt(nearest_cells(blocked)[0]) * resolution
    return clearance, outline_skips(clearance, resolution)


def _reach(outline: np.ndarray, resolution: float) -> float:
    """How far from a lethal or unknown cell's centre a pose's centre may put a point of `outline`
    on that cell: the outline's farthest point plus a cell's diagonal (the centre anywhere in its
    cell, the obstacle anywhere in its own)."""
    return float(np.max(np.hypot(outline[:, 0], outline[:, 1]))) + math.sqrt(2.0) * resolution


def footprint_outline(points: np.ndarray, spacing: float) -> np.ndarray:
    """Points along the closed footprint polygon, at most `spacing` apart (robot frame)."""
    points = np.asarray(points, np.float64).reshape(-1, 2)
    return densify(np.vstack([points, points[:1]]), spacing)[:-1]


def footprint_check_cost(inscribed_radius: float, circumscribed_radius: float, inflation_radius: float,
                         cost_scaling_factor: float) -> int:
    """The centre cost from which the footprint may touch an obstacle (ROS's circumscribed cost);
    0 (check every pose) when the inflation does not reach the circumscribed radius."""
    if inflation_radius < circumscribed_radius:
        return 0
    return inflation_cost(circumscribed_radius, inscribed_radius, cost_scaling_factor)


def kernel_grid(info: MapMetaData) -> np.ndarray:
    """The kernels' view of the grid (`grid` in trajectory_cost): (origin x, origin y, cos origin yaw, sin
    origin yaw, 1/resolution)."""
    theta = info.origin.theta
    return np.array([info.origin.x, info.origin.y, math.cos(theta), math.sin(theta), 1.0 / info.resolution])


class FootprintCheck:
    """`footprint` is the polygon in the robot frame, padded by `footprint_padding`; `check_cost` the
    centre cost from which the footprint's outline is checked (footprint_check_cost; 0 checks every
    pose); `stop_padding` the collision monitor's stop zone around the footprint, kept free of lethal
    and unknown cells (see `setup`)."""

    def __init__(self, footprint: np.ndarray, check_cost: int = 0, stop_padding: float = 0.0,
                 footprint_padding: float = 0.0):
        self.footprint = np.asarray(footprint, np.float64).reshape(-1, 2)
        self.check_cost = int(check_cost)
        for name, value in (("stop_padding", stop_padding), ("footprint_padding", footprint_padding)):
            if not (math.isfinite(value) and value >= 0):
                raise ValueError(f"{name} must be zero or positive, got {value}")
        self.stop_padding = float(stop_padding)
        self.footprint_padding = float(footprint_padding)
        self._outlines: dict[tuple[float, float], tuple[np.ndarray, float]] = {}
        # the last grid's (blocked cells, resolution, clearance, skips): the local costmap comes at its
        # own rate, while a control cycle sets up a check once or more (DWA, the shim, the approach)
        self._last_grid: tuple[np.ndarray, float, np.ndarray, np.ndarray] | None = None

    def _clearance(self, costs: np.ndarray, resolution: float) -> tuple[np.ndarray, np.ndarray]:
        """(clearance, skips) of a grid: m from each cell's centre to the nearest lethal or unknown
        cell's, and outline_skips; the last grid's again while its blocked cells are the same."""
        blocked = costs >= LETHAL_OBSTACLE
        last = self._last_grid
        if last is None or last[1] != resolution or not np.array_equal(last[0], blocked):
            self._last_grid = last = blocked, resolution, *_clearance_and_skips(blocked, resolution)
        return last[2], last[3]

    def _outline_check(self, clearance: np.ndarray, skips: np.ndarray, resolution: float, padding: float = 0.0,
               centre_limit: int = INSCRIBED_INFLATED_OBSTACLE) -> PoseCheck:
        """The PoseCheck of the footprint padded by `padding`: its outline is checked where a centre may
        put a point of it on a lethal or unknown cell (within its farthest point plus a cell's diagonal:
        the centre anywhere in its cell, the obstacle anywhere in its own)."""
        if (resolution, padding) not in self._outlines:
            outline = footprint_outline(pad(self.footprint, padding), OUTLINE_SPACING_CELLS * resolution)
            self._outlines[resolution, padding] = outline, _reach(outline, resolution)
        outline, reach = self._outlines[resolution, padding]
        return PoseCheck(outline, clearance <= reach, skips, centre_limit)

    def _zone_check(self, costs: np.ndarray, info: MapMetaData, extra: float, centre_limit: int) -> PoseCheck:
        """The robot's own outline (without footprint_padding) grown by the monitor's stop zone and `extra`."""
        clearance, skips = self._clearance(np.ascontiguousarray(costs, np.uint8), info.resolution)
        return self._outline_check(clearance, skips, info.resolution,
                                   self.stop_padding + extra - self.footprint_padding, centre_limit)

    def monitor_check(self, costs: np.ndarray, info: MapMetaData) -> PoseCheck:
        """The robot's own outline grown by the monitor's stop zone, whatever the centre cost: what the
        collision monitor lets through. A maneuver planned with the padded check is driven within it,
        its padding the slack for the robot's tracking."""
        return self._zone_check(costs, info, 0.0, LETHAL_OBSTACLE)

    def setup(self, pose, costs: np.ndarray, info: MapMetaData) -> PoseCheck:
        """What poses are checked with, starting from `pose`.

        The outline: the footprint padded by stop_padding (nothing where footprint_padding already
        holds the zone) plus a quarter cell — the monitor would stop a motion into its stop zone, and
        the outline's points are half a cell apart, so a cell's corner may reach a quarter cell in
        between them — while the robot stands a cell clear of that zone (at its edge every slide
        along a jagged row of obstacle cells would cross it); else the footprint padded by the
        quarter cell only, or the footprint itself, or the robot's own outline without
        footprint_padding: the robot may still move (away); when even that one lies on a lethal
        cell, the check is `wedged` (`escape_check` then lets it drive off those cells). A padding
        whose outline holds a lethal or unknown cell inside it at `pose` is passed over as one that
        touches it: the outline check is sound only for a robot that starts with nothing inside
        its outline (it cannot then move onto anything without crossing it); a door's jamb, two
        cells thick, inside the padded outline of a robot 5 cm beside it made every neighbouring
        pose illegal and no maneuver was found (building-diff-84 stood 20 s in a door).
        The outline is checked whatever the
        centre cost where
        `PoseCheck.near` (the circumscribed cost alone let a corner reach a cell one further). A robot
        whose centre stands on an inscribed cell is checked by its outline alone (`centre_limit`)."""
        costs = np.ascontiguousarray(costs, np.uint8)
        grid = kernel_grid(info)
        row, col = _cell(float(pose[0]), float(pose[1]), grid, costs.shape[0], costs.shape[1])
        centre_limit = (LETHAL_OBSTACLE if row >= 0 and costs[row, col] == INSCRIBED_INFLATED_OBSTACLE
                        else INSCRIBED_INFLATED_OBSTACLE)
        clearance, skips = self._clearance(costs, info.resolution)
        quarter = info.resolution / 4
        legal = np.empty(1, np.bool_)
        start = np.asarray(pose, np.float64).reshape(1, 3)
        # the monitor's stop zone lies around the robot's own outline: a footprint_padding at least
        # as wide holds it (stacked, the Jackal's 0.1 m padding and 0.02 m zone kept BARN world 30's
        # 0.45 m gaps shut); a narrower one is no margin against it, and the whole zone is kept
        # beyond it (cut to 0.04 m, a default robot's 0.05 m zone on its 0.01 m padding let the
        # monitor act on DWA's choices: a shoved robot ended 0.36 m off its goal)
        zone = 0.0 if self.footprint_padding >= self.stop_padding else self.stop_padding
        own = -self.footprint_padding
        for padding, margin in ((zone + quarter, info.resolution), (quarter, 0.0), (0.0, 0.0), (own, 0.0)):
            clear = self._outline_check(clearance, skips, info.resolution, padding + margin, centre_limit)
            _check_poses(start, kernel_costs(costs), clear.near, skips, grid, clear.outline, self.check_cost, centre_limit, legal)
            # nothing lies within the outline's reach of a centre whose cell is not `near`
            if legal[0] and not ((row < 0 or clear.near[row, col])
                                 and self._holds_blocked(start[0], padding + margin, costs, info)):
                return self._outline_check(clearance, skips, info.resolution, padding, centre_limit)
        return replace(clear, wedged=True)   # the last one tried: the robot's own outline

    def _holds_blocked(self, pose: np.ndarray, padding: float, costs: np.ndarray, info: MapMetaData) -> bool:
        """Whether the footprint padded by `padding` at `pose` holds a lethal or unknown cell's centre."""
        rows, cols = cells_inside(info, transform(pad(self.footprint, padding), pose))
        return bool((costs[rows, cols] >= LETHAL_OBSTACLE).any())

    def escape_check(self, check: PoseCheck, pose, costs: np.ndarray, info: MapMetaData) -> PoseCheck:
        """A wedged `check` (the robot's own outline) with the lethal and unknown cells its outline
        lies on at `pose` (where the robot became wedged) no longer counted: the robot braked beside
        an obstacle seen late, which lies somewhere in those cells but not under the robot, and may
        drive away from it — not onto any other cell (BARN world 142 seed 0 stood 1.8 cm from a cylinder until
        it timed out; judging every cell by its centre instead let it drive on into a tighter gap).
        The collision monitor, which sees the scan's points themselves, keeps it off the obstacle."""
        points = transform(check.outline, pose)
        rows, cols = world_to_cell(info, points[:, 0], points[:, 1])
        on_grid = in_grid(info, rows, cols)
        blocked = np.ascontiguousarray(costs, np.uint8) >= LETHAL_OBSTACLE
        under = np.unique(np.column_stack([rows[on_grid], cols[on_grid]]), axis=0)
        under = under[blocked[under[:, 0], under[:, 1]]]
        blocked[under[:, 0], under[:, 1]] = False
        clearance, skips = _clearance_and_skips(blocked, info.resolution)
        forgiven = np.column_stack(cell_to_world(info, under[:, 0], under[:, 1]))
        depth = (float(_depth_inside(check.outline, forgiven, np.asarray(pose, np.float64)[None, :3])[0])
                 if len(forgiven) else -math.inf)
        return PoseCheck(check.outline, clearance <= _reach(check.outline, info.resolution), skips, check.centre_limit,
                         forgiven=forgiven, forgiven_depth=depth)

    def keeps_away(self, check: PoseCheck, poses) -> np.ndarray:
        """(N,) whether each pose (N, 3) brings the outline no deeper over the cells `check`
        forgives than it lay where they were forgiven (the deepest cell centre's signed distance
        inside the outline, within KEEP_AWAY_SLACK): a wedged robot may drive off or along them,
        not over them (the collision monitor, on the scan, stops that)."""
        poses = np.asarray(poses, np.float64).reshape(-1, 3)
        if len(check.forgiven) == 0:
            return np.ones(len(poses), np.bool_)
        return _depth_inside(check.outline, check.forgiven, poses) <= check.forgiven_depth + KEEP_AWAY_SLACK

    def turn_check(self, check: PoseCheck, costs: np.ndarray, info: MapMetaData) -> PoseCheck | None:
        """What a last-resort turn is checked with when the padded footprint (`check`, set up for the
        pose) leaves none: the robot's own outline grown by the monitor's stop zone and a quarter cell
        — a turn the monitor lets through — with check's centre limit. None when that is no smaller
        than the padded footprint (a padding within the zone)."""
        quarter = info.resolution / 4
        if self.stop_padding + quarter - self.footprint_padding >= 0.0:
            return None
        return self._zone_check(costs, info, quarter, check.centre_limit)

    def check_poses(self, check: PoseCheck, poses, costs: np.ndarray, info: MapMetaData) -> np.ndarray:
        """(N,) whether the robot may stand at each pose (N, 3) by a check already set up."""
        poses = np.ascontiguousarray(poses, np.float64).reshape(-1, 3)
        legal = np.empty(len(poses), np.bool_)
        _check_poses(poses, kernel_costs(np.ascontiguousarray(costs, np.uint8)), check.near, check.skips,
                     kernel_grid(info), check.outline, self.check_cost, check.centre_limit, legal)
        return legal

    def legal_poses(self, poses, costs: np.ndarray, info: MapMetaData) -> np.ndarray:
        """(N,) whether the robot may stand at each pose (N, 3), checked as from the first (`setup`)."""
        poses = np.ascontiguousarray(poses, np.float64).reshape(-1, 3)
        if len(poses) == 0:
            return np.empty(0, np.bool_)
        return self.check_poses(self.setup(poses[0], costs, info), poses, costs, info)


def warm_up() -> None:
    """Compile (or load from cache) the check's kernels, outside any control cycle."""
    square = np.array([[0.1, 0.1], [-0.1, 0.1], [-0.1, -0.1], [0.1, -0.1]])
    FootprintCheck(square).legal_poses(np.array([[0.2, 0.2, 0.0]]), np.zeros((4, 4), np.uint8),
                                       MapMetaData(resolution=0.1, width=4, height=4))
