"""Holonomic DWA / trajectory rollout after ROS base_local_planner and dwa_local_planner.

One control cycle (`DwaPlanner.compute`):
1. the local part of the global path (from the path point nearest the robot to where the path
   leaves the local costmap) is drawn into the grid and two distance maps are computed once:
   metres to the nearest path cell and to the local goal (the last local path point), measured
   through the cells the robot's centre may cross (as ROS's MapGrid floods them): a path that
   turns back behind a wall is far from the robot's side of the wall, not next to it;
2. velocities are sampled over the dynamic window — what the acceleration limits allow from the
   current velocity within one control period (dwa: true) or within sim_time (trajectory
   rollout) — and clipped to the velocity limits: vx × vy × ω (vy ≡ 0 for a differential drive;
   holonomic robots also get base_local_planner's y_vels strafe samples);
3. every sample is rolled out for sim_time in one numba call (exact constant-twist arcs; in
   trajectory-rollout mode the twist ramps towards the sample at the acceleration limits, as
   base_local_planner does) and checked against the costmap: a pose is illegal when its centre
   cell is inscribed, lethal, unknown or off the grid, or — when its centre cell lies within the
   outline's reach of a lethal or unknown cell — when any point of the outline lies on a lethal or
   unknown cell: the footprint's grown by the collision monitor's stop zone (stop_padding), or,
   when the robot already stands within that zone, its own (`check_setup`);
4. legal trajectories are scored as dwa_local_planner does, lower is better:
   path_distance_bias·(path distance of the end pose + of the point forward_point_distance ahead
   of it) + goal_distance_bias·(goal distance of both) + occdist_scale·(highest cost met);
   the point ahead is the heading term (DWA's alignment and goal-front critics), dropped within
   forward_point_distance of the local goal as DWA does.
With no legal trajectory, base_local_planner's last resorts are rolled out (`fallback_velocities`:
turns on the spot and, holonomic, pure strafes, at the reachable speed nearest standing whatever
min_vel_x), then backing up at escape_vel; else the command brakes as hard as the window allows.
Distances are 16-connected around the inscribed, lethal and unknown cells; cells the flood does
not reach (those cells themselves) get the distance of the nearest reached cell plus the straight
line to it, so a point ahead of a pose near a wall is scored, not rejected.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit
from scipy import ndimage

from ...schemas.messages import MapMetaData
from ...geometry.footprint import pad
from ...geometry.polygons import densify
from ..costmap.layers import INSCRIBED_INFLATED_OBSTACLE, LETHAL_OBSTACLE, inflation_cost
from ...geometry.grid import in_grid, world_to_cell
from .dynamic import Movers, critic, slack
from .dynamic import warm_up as warm_up_movers
from .params import DwaParams

SMALL_ANGLE = 1e-9   # rad: below this a step is a straight line (sin x / x = 1)


# ---------------------------------------------------------------- path distance maps

@dataclass(frozen=True)
class PathMaps:
    path: np.ndarray          # (M, 3) the local part of the path
    path_dist: np.ndarray     # (H, W) float32, m to the nearest local path cell
    goal_dist: np.ndarray     # (H, W) float32, m to the local goal's cell

    @property
    def local_goal(self) -> np.ndarray:
        return self.path[-1]


def local_path(path: np.ndarray, pose, info: MapMetaData) -> np.ndarray:
    """From the path point nearest the robot (among those on the grid) to where the path leaves the
    grid; (0, 3) when no point is on the grid."""
    path = np.asarray(path, np.float64).reshape(-1, 3)
    inside = in_grid(info, *world_to_cell(info, path[:, 0], path[:, 1]))
    if not inside.any():
        return path[:0]
    distance = np.where(inside, np.hypot(path[:, 0] - pose[0], path[:, 1] - pose[1]), np.inf)
    first = int(np.argmin(distance))
    leaves = np.flatnonzero(~inside[first:])
    return path[first:first + (int(leaves[0]) if leaves.size else len(path) - first)]


# the flood's moves (row, col steps): 16-connected, so that in free space its distances are within
# 3 % of the straight line (8-connected ones are up to 8 % long and tilt the scores off the path);
# a knight's move also needs the two cells it passes between to be passable
_MOVES = np.array([(dr, dc) for dr in range(-2, 3) for dc in range(-2, 3)
                   if (dr, dc) != (0, 0) and max(abs(dr), abs(dc)) <= 2 and math.gcd(abs(dr), abs(dc)) == 1])


@njit(cache=True, inline="always")
def _relax(distance, passable, moves, lengths, row, col) -> bool:
    """Lower the cell's distance through the moves that end in it; whether it changed. The grids'
    borders (two cells) are unreached and impassable, so no move leaves them."""
    best = distance[row, col]
    for m in range(moves.shape[0]):
        dr, dc = moves[m, 0], moves[m, 1]
        r, c = row - dr, col - dc          # the move from (r, c) ends here
        if distance[r, c] + lengths[m] >= best:
            continue
        if abs(dr) == 2 and not (passable[r + dr // 2, c] and passable[r + dr // 2, col]):
            continue    # a knight's move: the two cells it passes between
        if abs(dc) == 2 and not (passable[r, c + dc // 2] and passable[row, c + dc // 2]):
            continue
        best = distance[r, c] + lengths[m]
    if best < distance[row, col]:
        distance[row, col] = best
        return True
    return False


@njit(cache=True)
def _flood(sources, passable, moves):
    """Cells from the nearest source cell through passable cells, by the moves (each its straight
    length); inf where not reached. Sources count whether passable or not. Raster sweeps forwards
    and backwards until one changes nothing (a chamfer transform with obstacles: one pair of sweeps
    per bend the shortest ways take, far cheaper here than a priority queue)."""
    height, width = passable.shape
    border = 2     # the longest move: around the grid, unreached impassable cells
    distance = np.full((height + 2 * border, width + 2 * border), np.inf)
    open_ = np.zeros(distance.shape, np.bool_)
    for row in range(height):
        for col in range(width):
            distance[row + border, col + border] = 0.0 if sources[row, col] else np.inf
            open_[row + border, col + border] = passable[row, col]
    # a sweep uses the moves from the cells it has already passed
    ahead = (moves[:, 0] > 0) | ((moves[:, 0] == 0) & (moves[:, 1] > 0))
    forward, backward = moves[ahead], moves[~ahead]
    forward_lengths = np.sqrt((forward[:, 0] ** 2 + forward[:, 1] ** 2).astype(np.float64))
    backward_lengths = np.sqrt((backward[:, 0] ** 2 + backward[:, 1] ** 2).astype(np.float64))
    # a sweep leaves every cell settled against the cells before it; once a sweep changes nothing, the
    # other direction's last sweep holds too. A forward sweep only needs to start at the first row
    # the backward sweep before it changed, a backward one at the last row the forward one changed.
    top, bottom = border, height + border - 1
    sweeps = 0
    while True:
        first, last = -1, -1
        if sweeps % 2 == 0:
            for row in range(top, height + border):
                for col in range(border, width + border):
                    if open_[row, col] and _relax(distance, open_, forward, forward_lengths, row, col):
                        first = row if first < 0 else first
                        last = row
        else:
            for row in range(bottom, border - 1, -1):
                for col in range(width + border - 1, border - 1, -1):
                    if open_[row, col] and _relax(distance, open_, backward, backward_lengths, row, col):
                        last = row if last < 0 else last
                        first = row
        sweeps += 1
        if first < 0 and sweeps > 1:
            break
        if sweeps % 2 == 1 and last >= 0:
            bottom = last
        elif sweeps % 2 == 0:
            top = first
    return distance[border:height + border, border:width + border].copy()


def _distances_to(masks, passable: np.ndarray, resolution: float) -> list[np.ndarray]:
    """Metres from each mask's cells around the impassable cells; an unreached cell: the distance of
    the nearest reached cell plus the straight line to it (the nearest cells found once for floods
    that reach the same cells)."""
    result, reached_before, nearest = [], None, None
    for mask in masks:
        distance = _flood(mask, passable, _MOVES)
        reached = np.isfinite(distance)
        if not reached.all():
            if reached_before is None or not np.array_equal(reached, reached_before):
                reached_before, nearest = reached, ndimage.distance_transform_edt(~reached, return_indices=True)
            gap, (rows, cols) = nearest
            distance = np.where(reached, distance, distance[rows, cols] + gap)
        result.append((distance * resolution).astype(np.float32))
    return result


def path_maps(path: np.ndarray, pose, info: MapMetaData, costs: np.ndarray | None = None) -> PathMaps | None:
    """The distance maps of one cycle, or None when no path point lies on the grid. With costs,
    distances go around the cells the robot's centre may not enter (inscribed, lethal, unknown)."""
    local = local_path(path, pose, info)
    if len(local) == 0:
        return None
    shape = (info.height, info.width)
    points = densify(local, info.resolution / 2)
    rows, cols = world_to_cell(info, points[:, 0], points[:, 1])
    keep = in_grid(info, rows, cols)
    on_path = np.zeros(shape, bool)
    on_path[rows[keep], cols[keep]] = True
    at_goal = np.zeros(shape, bool)
    at_goal[rows[keep][-1], cols[keep][-1]] = True
    passable = np.ones(shape, np.bool_) if costs is None else np.asarray(costs) < INSCRIBED_INFLATED_OBSTACLE
    return PathMaps(local, *_distances_to((on_path, at_goal), passable, info.resolution))


# ---------------------------------------------------------------- rollout kernel

# the outline's points are at most this many cells apart (footprint_outline's spacing)
OUTLINE_SPACING_CELLS = 0.5


@dataclass(frozen=True)
class PoseCheck:
    """What one cycle's poses are checked with (`DwaPlanner.check_setup`)."""
    outline: np.ndarray     # (K, 2) points along the (padded) footprint, robot frame
    near: np.ndarray        # (H, W) bool: where the outline is checked whatever the centre cost
    # (H, W) int8: how many outline points on from one in this cell (either way along the outline) cannot lie on a
    # lethal or unknown cell or off the grid (`outline_skips`); -1 on lethal and unknown cells
    skips: np.ndarray
    # the centre cost from which a pose is illegal whatever its outline: inscribed, unless the robot
    # already stands on an inscribed cell (a tracking error put it there): then lethal, and the
    # outline alone decides, as ROS does for a polygon footprint, so the robot can drive out again
    centre_limit: int = INSCRIBED_INFLATED_OBSTACLE


@njit(cache=True)
def _lower_envelope(f, out, v, z):
    """out[q] = min over p of f[p] + (q - p)² (f may be inf; all inf gives inf): Felzenszwalb and
    Huttenlocher's lower envelope of parabolas, v and z scratch of len(f) and len(f) + 1. Exact for
    integer f: a boundary between two parabolas is a fraction of denominator below 2·len(f), too
    far from any other integer for rounding to move it past one."""
    n, k = f.shape[0], -1
    for q in range(n):
        if f[q] == np.inf:
            continue
        s = -np.inf
        while k >= 0:
            s = ((f[q] + q * q) - (f[v[k]] + v[k] * v[k])) / (2.0 * (q - v[k]))
            if s > z[k]:
                break
            k -= 1
        if k < 0:
            s = -np.inf
        k += 1
        v[k], z[k], z[k + 1] = q, s, np.inf
    if k < 0:
        out[:] = np.inf
        return
    j = 0
    for q in range(n):
        while z[j + 1] < q:
            j += 1
        out[q] = (q - v[j]) * (q - v[j]) + f[v[j]]


@njit(cache=True)
def _clearance_cells(blocked):
    """(H, W) cells from each cell's centre to the nearest blocked cell's (0 on them, inf without
    any): the exact Euclidean distance transform, by columns then rows."""
    height, width = blocked.shape
    squared = np.full((height, width), np.inf)
    size = max(height, width)
    f, out, v, z = np.empty(size), np.empty(size), np.empty(size, np.int64), np.empty(size + 1)
    for col in range(width):
        for row in range(height):
            f[row] = 0.0 if blocked[row, col] else np.inf
        _lower_envelope(f[:height], out[:height], v, z)
        squared[:, col] = out[:height]
    for row in range(height):
        f[:width] = squared[row]
        _lower_envelope(f[:width], out[:width], v, z)
        squared[row] = out[:width]
    return np.sqrt(squared)


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
    """(row, col) of the cell under a world point; (-1, -1) off the grid. grid as in _rollout."""
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


@njit(cache=True, inline="always")
def _pose_cost(costs, near, skips, x, y, c, s, grid, outline, check_cost, centre_limit):
    """The centre cost of the robot at (x, y), heading (cos, sin) = (c, s), or -1 when that pose is
    illegal: its centre cell off the grid or at centre_limit or above (inscribed, lethal, unknown),
    or — from check_cost on, or where `near` — a point of the outline on a lethal or unknown cell or
    off the grid. near, skips and centre_limit as in PoseCheck, grid as in _rollout."""
    row, col = _cell(x, y, grid, costs.shape[0], costs.shape[1])
    if row < 0 or costs[row, col] >= centre_limit:
        return -1
    cost = int(costs[row, col])
    if (cost >= check_cost or near[row, col]) and not _outline_clear(skips, x, y, c, s, grid, outline):
        return -1
    return cost


@njit(cache=True)
def _step(vx, vy, w, dt):
    """(bx, by, phi): the exact pose increment of a constant twist over dt, robot frame (se2_exp, inlined)."""
    phi = w * dt
    if abs(phi) < SMALL_ANGLE:
        along, across = 1.0, 0.5 * phi
    else:
        along, across = math.sin(phi) / phi, (1.0 - math.cos(phi)) / phi
    return (along * vx - across * vy) * dt, (across * vx + along * vy) * dt, phi


@njit(cache=True)
def _rollout(samples, v0, step_limit, ramp, n_steps, dt, pose0, costs, near, skips, grid, outline, check_cost,
             centre_limit, poses, max_cost, legal):
    """Roll out and check every sample; fills poses (T, n_steps+1, 3), max_cost (T,), legal (T,).

    grid = (origin x, origin y, cos origin yaw, sin origin yaw, 1/resolution)."""
    for t in range(samples.shape[0]):
        if ramp:
            vx, vy, w = v0[0], v0[1], v0[2]
        else:
            vx, vy, w = samples[t, 0], samples[t, 1], samples[t, 2]
        bx, by, phi = _step(vx, vy, w, dt)     # the sample's own, unless ramping
        x, y, th = pose0[0], pose0[1], pose0[2]
        c, s = math.cos(th), math.sin(th)
        poses[t, 0, 0], poses[t, 0, 1], poses[t, 0, 2] = x, y, th
        worst, ok, k = 0, True, 0
        while k < n_steps and ok:
            if ramp:
                vx += min(max(samples[t, 0] - vx, -step_limit[0]), step_limit[0])
                vy += min(max(samples[t, 1] - vy, -step_limit[1]), step_limit[1])
                w += min(max(samples[t, 2] - w, -step_limit[2]), step_limit[2])
                bx, by, phi = _step(vx, vy, w, dt)
            x, y, th = x + c * bx - s * by, y + s * bx + c * by, th + phi
            c, s = math.cos(th), math.sin(th)
            k += 1
            poses[t, k, 0], poses[t, k, 1], poses[t, k, 2] = x, y, th
            cost = _pose_cost(costs, near, skips, x, y, c, s, grid, outline, check_cost, centre_limit)
            if cost < 0:
                ok = False
                break
            if cost > worst:
                worst = cost
        for j in range(k + 1, n_steps + 1):   # a stopped rollout keeps its last pose
            poses[t, j, 0], poses[t, j, 1], poses[t, j, 2] = x, y, th
        legal[t] = ok
        max_cost[t] = worst


@njit(cache=True)
def _check_poses(poses, costs, near, skips, grid, outline, check_cost, centre_limit, legal):
    for i in range(poses.shape[0]):
        x, y, th = poses[i, 0], poses[i, 1], poses[i, 2]
        legal[i] = _pose_cost(costs, near, skips, x, y, math.cos(th), math.sin(th), grid, outline, check_cost,
                              centre_limit) >= 0


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


# ---------------------------------------------------------------- the planner

@dataclass(frozen=True)
class DwaResult:
    status: str                # ok | escape | no_valid_trajectory | no_path
    cmd: np.ndarray            # (3,) vx, vy, wz to send
    samples: np.ndarray        # (T, 3) sampled twists
    poses: np.ndarray          # (T, S + 1, 3) rolled-out poses in the costmap frame
    scores: np.ndarray         # (T,) lower is better; inf for illegal trajectories
    best: int                  # index of the chosen sample, -1 if none
    message: str = ""

    @property
    def legal(self) -> np.ndarray:
        return np.isfinite(self.scores)

    @property
    def trajectory(self) -> np.ndarray:
        """(S + 1, 3) the chosen rollout's poses; (0, 3) when none was chosen."""
        return self.poses[self.best] if self.best >= 0 else np.zeros((0, 3))


def reachable(params: DwaParams, velocity) -> tuple[np.ndarray, np.ndarray]:
    """(low, high) per axis: what the acceleration limits reach from `velocity` within the window's
    duration (one control period with dwa, else sim_time), whatever the velocity limits."""
    period = 1.0 / params.controller_frequency if params.dwa else params.sim_time
    v = np.asarray(velocity, np.float64)
    reach = np.array([params.acc_lim_x, params.acc_lim_y, params.acc_lim_theta]) * period
    return v - reach, v + reach


def dynamic_window(params: DwaParams, velocity) -> tuple[np.ndarray, np.ndarray]:
    """(low, high) per axis: the reachable velocities inside the velocity limits; when the current
    velocity is outside them, the reachable value nearest to the limits."""
    v = np.asarray(velocity, np.float64)
    soonest, furthest = reachable(params, v)
    lowest = np.array([params.min_vel_x, params.min_vel_y if params.holonomic_robot else 0.0, params.min_vel_theta])
    highest = np.array([params.max_vel_x, params.max_vel_y if params.holonomic_robot else 0.0, params.max_vel_theta])
    low, high = np.maximum(lowest, soonest), np.minimum(highest, furthest)
    stuck = low > high
    nearest = np.clip(np.clip(v, lowest, highest), soonest, furthest)
    return np.where(stuck, nearest, low), np.where(stuck, nearest, high)


def _axis(low: float, high: float, count: int, extra=()) -> np.ndarray:
    values = [*np.linspace(low, high, count), *(e for e in extra if low <= e <= high)]
    if low <= 0.0 <= high:
        values.append(0.0)
    return np.unique(np.asarray(values, np.float64))


def sample_velocities(params: DwaParams, velocity) -> np.ndarray:
    """(T, 3) twists over the dynamic window; no standing still, no turning on the spot slower than
    min_in_place_vel_theta."""
    low, high = dynamic_window(params, velocity)
    vx = _axis(low[0], high[0], params.vx_samples)
    vy = _axis(low[1], high[1], params.vy_samples, params.y_vels) if params.holonomic_robot else np.zeros(1)
    wz = _axis(low[2], high[2], params.vtheta_samples)
    return _without_standing(params, np.stack(np.meshgrid(vx, vy, wz, indexing="ij"), axis=-1).reshape(-1, 3))


def fallback_velocities(params: DwaParams, velocity) -> np.ndarray:
    """(T, 3) base_local_planner's last resorts before backing up, at the reachable vx (and vy) nearest
    zero whatever min_vel_x: turns on the spot over [min_vel_theta, max_vel_theta] (as its in-place
    rotations, beyond one period's reach: from standing the window holds no turn as fast as
    min_in_place_vel_theta; the velocity smoother ramps them) and, holonomic, pure strafes over the
    window's vy — a robot facing a wall or with its goal behind it turns or slides away."""
    low, high = dynamic_window(params, velocity)
    soonest, furthest = reachable(params, velocity)
    slowest = np.clip(0.0, soonest, furthest)
    if not params.holonomic_robot:
        slowest[1] = 0.0
    wz = _axis(params.min_vel_theta, params.max_vel_theta, params.vtheta_samples)
    turns = np.column_stack([np.full(len(wz), slowest[0]), np.full(len(wz), slowest[1]), wz])
    if params.holonomic_robot:
        vy = _axis(low[1], high[1], params.vy_samples, params.y_vels)
        turns = np.vstack([turns, np.column_stack([np.full(len(vy), slowest[0]), vy, np.full(len(vy), slowest[2])])])
    return _without_standing(params, np.unique(turns, axis=0))


def _without_standing(params: DwaParams, samples: np.ndarray) -> np.ndarray:
    in_place = (samples[:, 0] == 0.0) & (samples[:, 1] == 0.0)
    return samples[~(in_place & (np.abs(samples[:, 2]) < params.min_in_place_vel_theta))]


def _grid(info: MapMetaData) -> np.ndarray:
    """The kernels' view of the grid: (origin x, origin y, cos origin yaw, sin origin yaw, 1/resolution)."""
    theta = info.origin.theta
    return np.array([info.origin.x, info.origin.y, math.cos(theta), math.sin(theta), 1.0 / info.resolution])


class DwaPlanner:
    """The pure DWA core: `compute` is one control cycle. `footprint` is the polygon in the robot
    frame, padded by `footprint_padding`; `check_cost` the centre cost from which the footprint's
    outline is checked (footprint_check_cost; 0 checks every pose); `stop_padding` the collision
    monitor's stop zone around the footprint, kept free of lethal and unknown cells (see `check_setup`)."""

    def __init__(self, params: DwaParams, footprint: np.ndarray, check_cost: int = 0, stop_padding: float = 0.0,
                 footprint_padding: float = 0.0):
        self.params = params
        self.footprint = np.asarray(footprint, np.float64).reshape(-1, 2)
        self.check_cost = int(check_cost)
        for name, value in (("stop_padding", stop_padding), ("footprint_padding", footprint_padding)):
            if not (math.isfinite(value) and value >= 0):
                raise ValueError(f"{name} must be zero or positive, got {value}")
        self.stop_padding = float(stop_padding)
        self.footprint_padding = float(footprint_padding)
        self._outlines: dict[tuple[float, float], tuple[np.ndarray, float]] = {}

    def _check(self, clearance: np.ndarray, skips: np.ndarray, resolution: float, padding: float = 0.0,
               centre_limit: int = INSCRIBED_INFLATED_OBSTACLE) -> PoseCheck:
        """The PoseCheck of the footprint padded by `padding`: its outline is checked where a centre may
        put a point of it on a lethal or unknown cell (within its farthest point plus a cell's diagonal:
        the centre anywhere in its cell, the obstacle anywhere in its own)."""
        if (resolution, padding) not in self._outlines:
            outline = footprint_outline(pad(self.footprint, padding), OUTLINE_SPACING_CELLS * resolution)
            reach = float(np.max(np.hypot(outline[:, 0], outline[:, 1]))) + math.sqrt(2.0) * resolution
            self._outlines[resolution, padding] = outline, reach
        outline, reach = self._outlines[resolution, padding]
        return PoseCheck(outline, clearance <= reach, skips, centre_limit)

    def check_setup(self, pose, costs: np.ndarray, info: MapMetaData) -> PoseCheck:
        """What poses are checked with, starting from `pose`.

        The outline: the footprint padded by stop_padding plus a quarter cell — the monitor would
        stop a motion into its stop zone, and the outline's points are half a cell apart, so a cell's
        corner may reach a quarter cell in between them — while the robot stands a cell clear of
        that zone (at its edge every slide along a jagged row of obstacle cells would cross it);
        else the footprint padded by the quarter cell only, or the footprint itself, or at last the
        robot's own outline without footprint_padding: the robot may still move (away). The outline is checked whatever the centre cost where
        `PoseCheck.near` (the circumscribed cost alone let a corner reach a cell one further). A robot
        whose centre stands on an inscribed cell is checked by its outline alone (`centre_limit`)."""
        costs = np.ascontiguousarray(costs, np.uint8)
        grid = _grid(info)
        row, col = _cell(float(pose[0]), float(pose[1]), grid, costs.shape[0], costs.shape[1])
        centre_limit = (LETHAL_OBSTACLE if row >= 0 and costs[row, col] == INSCRIBED_INFLATED_OBSTACLE
                        else INSCRIBED_INFLATED_OBSTACLE)
        blocked = costs >= LETHAL_OBSTACLE
        clearance = _clearance_cells(blocked) * info.resolution
        skips = outline_skips(clearance, info.resolution)
        quarter = info.resolution / 4
        legal = np.empty(1, np.bool_)
        start = np.asarray(pose, np.float64).reshape(1, 3)
        for padding, margin in ((self.stop_padding + quarter, info.resolution), (quarter, 0.0), (0.0, 0.0)):
            clear = self._check(clearance, skips, info.resolution, padding + margin, centre_limit)
            _check_poses(start, costs, clear.near, skips, grid, clear.outline, self.check_cost, centre_limit, legal)
            if legal[0]:
                return self._check(clearance, skips, info.resolution, padding, centre_limit)
        return self._check(clearance, skips, info.resolution, -self.footprint_padding, centre_limit)

    def n_steps(self, samples: np.ndarray) -> int:
        """Poses per rollout: the fastest sample moves at most sim_granularity (m, or rad) per step."""
        p = self.params
        fastest = max(float(np.max(np.hypot(samples[:, 0], samples[:, 1]), initial=0.0)),
                      float(np.max(np.abs(samples[:, 2]), initial=0.0)))
        return max(1, int(math.ceil(p.sim_time * fastest / p.sim_granularity)))

    def rollout(self, samples, pose, velocity, costs: np.ndarray, info: MapMetaData, check: PoseCheck | None = None):
        """(poses (T, S+1, 3), max_cost (T,), legal (T,)) of the samples, one batch; `check` may be
        passed when already set up for this pose and costmap."""
        samples = np.ascontiguousarray(samples, np.float64).reshape(-1, 3)
        p = self.params
        n = self.n_steps(samples)
        dt = p.sim_time / n
        step_limit = np.array([p.acc_lim_x, p.acc_lim_y, p.acc_lim_theta]) * dt
        poses = np.empty((len(samples), n + 1, 3))
        max_cost = np.empty(len(samples), np.int64)
        legal = np.empty(len(samples), np.bool_)
        check = check if check is not None else self.check_setup(pose, costs, info)
        _rollout(samples, np.asarray(velocity, np.float64), step_limit, not p.dwa, n, dt,
                 np.asarray(pose, np.float64), np.ascontiguousarray(costs, np.uint8), check.near, check.skips,
                 _grid(info), check.outline, self.check_cost, check.centre_limit, poses, max_cost, legal)
        return poses, max_cost, legal

    def legal_poses(self, poses, costs: np.ndarray, info: MapMetaData) -> np.ndarray:
        """(N,) whether the robot may stand at each pose (N, 3), by the rollout's test from the first."""
        poses = np.ascontiguousarray(poses, np.float64).reshape(-1, 3)
        legal = np.empty(len(poses), np.bool_)
        if len(poses) == 0:
            return legal
        check = self.check_setup(poses[0], costs, info)
        _check_poses(poses, np.ascontiguousarray(costs, np.uint8), check.near, check.skips, _grid(info),
                     check.outline, self.check_cost, check.centre_limit, legal)
        return legal

    def score(self, poses, max_cost, legal, maps: PathMaps, info: MapMetaData) -> np.ndarray:
        """Scores (T,) of rolled-out trajectories; inf where illegal."""
        p = self.params
        end = poses[:, -1]
        points = [(end[:, 0], end[:, 1])]
        # within forward_point_distance of the local goal the point ahead would hold the robot that
        # far short of it, so (as DWA) only the end pose counts there
        if np.hypot(*(poses[0, 0, :2] - maps.local_goal[:2])) > p.forward_point_distance:
            ahead = end[:, :2] + p.forward_point_distance * np.stack([np.cos(end[:, 2]), np.sin(end[:, 2])], axis=1)
            points.append((ahead[:, 0], ahead[:, 1]))
        total = p.occdist_scale * max_cost.astype(np.float64)
        for x, y in points:
            rows, cols = world_to_cell(info, x, y)
            # a point ahead may leave the window near its edge: take the nearest cell's distance
            rows, cols = np.clip(rows, 0, info.height - 1), np.clip(cols, 0, info.width - 1)
            total += p.path_distance_bias * maps.path_dist[rows, cols] + p.goal_distance_bias * maps.goal_dist[rows, cols]
        return np.where(legal, total, np.inf)

    def compute(self, pose, velocity, costs: np.ndarray, info: MapMetaData, path: np.ndarray,
                maps: PathMaps | None = None, movers: Movers | None = None) -> DwaResult:
        """One cycle: pose (x, y, yaw) and path (N, 3) in the costmap's frame, velocity (vx, vy, wz)
        in the robot frame. `maps` may be passed when already computed for this cycle; `movers`
        (dynamic.py), the tracks predicted from the cycle's time, are scored along each rollout."""
        maps = maps if maps is not None else path_maps(path, pose, info, costs)
        low, high = reachable(self.params, velocity)
        brake = np.clip(0.0, low, high)   # as hard as the acceleration limits allow
        if not self.params.holonomic_robot:
            brake[1] = 0.0
        samples = sample_velocities(self.params, velocity)
        if maps is None:
            return DwaResult("no_path", brake, samples, np.zeros((0, 1, 3)), np.zeros(0), -1,
                             "no point of the path lies on the local costmap")
        check = self.check_setup(pose, costs, info)

        def evaluate(samples):
            poses, max_cost, legal = self.rollout(samples, pose, velocity, costs, info, check)
            cost = 0.0
            if movers is not None and len(movers):
                clear, cost = self._clear_of(poses, movers)
                legal = legal & clear
            return poses, legal, self.score(poses, max_cost, legal, maps, info) + cost

        poses, legal, scores = evaluate(samples)
        last_resorts = fallback_velocities(self.params, velocity) if not legal.any() else samples[:0]
        if len(last_resorts):     # base_local_planner's last resorts before backing up
            samples = last_resorts
            poses, legal, scores = evaluate(samples)
        if legal.any():
            best = int(np.argmin(scores))
            return DwaResult("ok", samples[best].copy(), samples, poses, scores, best)
        if self.params.escape_vel < 0:
            escape = np.clip(np.array([self.params.escape_vel, 0.0, 0.0]), low, high)
            if escape[0] < 0 and evaluate(escape[None])[1][0]:
                return DwaResult("escape", escape, samples, poses, scores, -1,
                                 f"every one of {len(samples)} trajectories collides; backing up")
        return DwaResult("no_valid_trajectory", brake, samples, poses, scores, -1,
                         f"every one of {len(samples)} trajectories collides; braking")

    def _clear_of(self, poses: np.ndarray, movers: Movers) -> tuple[np.ndarray, np.ndarray]:
        """(legal (T,), cost (T,)) of rollouts against the predicted movers (dynamic.py)."""
        p = self.params
        dt = p.sim_time / max(1, poses.shape[1] - 1)
        hard, soft = slack(poses, dt, self.footprint, movers, p.dynamic_obstacle_margin, p.dynamic_obstacle_sigmas)
        standing = np.repeat(poses[:1, :1], poses.shape[1], axis=1)
        standing_hard, _ = slack(standing, dt, self.footprint, movers, p.dynamic_obstacle_margin, 0.0)
        return critic(hard, soft, standing_hard, p.dynamic_influence_distance, p.dynamic_obstacle_scale)


def warm_up() -> None:
    """Compile (or load from cache) the rollout and flood kernels, outside any control cycle."""
    info = MapMetaData(resolution=0.1, width=4, height=4)
    square = np.array([[0.1, 0.1], [-0.1, 0.1], [-0.1, -0.1], [0.1, -0.1]])
    for dwa in (True, False):
        DwaPlanner(DwaParams(dwa=dwa), square).rollout(np.array([[0.1, 0.0, 0.1]]), (0.2, 0.2, 0.0), (0.0, 0.0, 0.0),
                        np.zeros((4, 4), np.uint8), info)
    DwaPlanner(DwaParams(), square).legal_poses(np.array([[0.2, 0.2, 0.0]]), np.zeros((4, 4), np.uint8), info)
    _flood(np.eye(4, dtype=np.bool_), np.ones((4, 4), np.bool_), _MOVES)
    warm_up_movers()
