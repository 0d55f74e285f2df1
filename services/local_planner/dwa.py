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
   base_local_planner does) and every pose is held to the footprint check (footprint_check.py:
   centre not inscribed, lethal, unknown or off the grid; near obstacles, the outline — grown by
   the collision monitor's stop zone while the robot stands clear of it — on no lethal or unknown
   cell);
4. legal trajectories are scored as dwa_local_planner does, lower is better:
   path_distance_bias·(path distance of the end pose + of the point forward_point_distance ahead
   of it) + goal_distance_bias·(goal distance of both) + occdist_scale·(highest cost met);
   the point ahead is the heading term (DWA's alignment and goal-front critics), dropped within
   forward_point_distance of the local goal as DWA does.
With no legal trajectory, base_local_planner's last resorts are rolled out (`fallback_velocities`:
turns on the spot and, holonomic, pure strafes, at the reachable speed nearest standing whatever
min_vel_x) — where the footprint padding leaves none, checked with the robot's own outline grown
by the monitor's stop zone (FootprintCheck.turn_check) — then backing up at escape_vel; else the
command brakes as hard as the window allows. Once it backs up from a block in the costmap (not
from a person, who walks on) the planner is escaping, as base_local_planner's is: only the last resorts are
sampled until the robot has moved escape_reset_dist or turned escape_reset_theta from where the
backing began, so it does not creep forward into the same gap on the next cycle.
Distances are 16-connected around the inscribed, lethal and unknown cells; cells the flood does
not reach (those cells themselves) get the distance of the nearest reached cell plus the straight
line to it, so a point ahead of a pose near a wall is scored, not rejected.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit

from ...schemas.messages import MapMetaData
from ...geometry.distance import nearest_cells
from ...geometry.polygons import densify
from ...geometry.se2 import wrap_angle
from ..costmap.layers import INSCRIBED_INFLATED_OBSTACLE
from ...geometry.grid import in_grid, kernel_costs, world_to_cell
from .dynamic import Movers, carried_on, critic, first_contact, slack
from .dynamic import warm_up as warm_up_movers
from .footprint_check import FootprintCheck, PoseCheck, kernel_grid, trajectory_cost
from .footprint_check import warm_up as warm_up_footprint_check
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


@njit(cache=True)
def _move_table(moves, width):
    """The moves on a grid flattened by rows of `width`: (offsets, lengths, between) where a move
    ends at cell i from cell i - offsets[m], is lengths[m] long and, a knight's move, passes between
    the cells i - between[m, 0] and i - between[m, 1] (0, 0 for the others)."""
    offsets = moves[:, 0] * width + moves[:, 1]
    lengths = np.sqrt((moves[:, 0] ** 2 + moves[:, 1] ** 2).astype(np.float64))
    between = np.zeros((moves.shape[0], 2), np.int64)
    for m in range(moves.shape[0]):
        dr, dc = moves[m, 0], moves[m, 1]
        if abs(dr) == 2:
            between[m, 0], between[m, 1] = (dr // 2) * width + dc, (dr // 2) * width
        elif abs(dc) == 2:
            between[m, 0], between[m, 1] = dr * width + dc // 2, dc // 2
    return offsets, lengths, between


@njit(cache=True, _nrt=False)
def _sweep(distance, passable, offsets, lengths, between, row_start, row_stop, col_start, col_stop, step, width):
    """One raster sweep over the flattened grids (rows and, within each, columns in the direction
    of step): each passable cell's distance lowered through the moves that end in it. Returns the
    first and the last row it changed in sweep order (-1, -1: none)."""
    first, last = -1, -1
    for row in range(row_start, row_stop, step):
        base = row * width
        for i in range(base + col_start, base + col_stop, step):
            if not passable[i]:
                continue
            best = distance[i]
            for m in range(offsets.shape[0]):
                candidate = distance[i - offsets[m]] + lengths[m]
                if candidate >= best:
                    continue
                if between[m, 0] != 0 and not (passable[i - between[m, 0]] and passable[i - between[m, 1]]):
                    continue
                best = candidate
            if best < distance[i]:
                distance[i] = best
                first = row if first < 0 else first
                last = row
    return first, last


@njit(cache=True)
def _flood(sources, passable, moves):
    """Cells from the nearest source cell through passable cells, by the moves (each its straight
    length); inf where not reached. Sources count whether passable or not. Raster sweeps forwards
    and backwards until one changes nothing (a chamfer transform with obstacles: one pair of sweeps
    per bend the shortest ways take, far cheaper here than a priority queue). The grids are
    flattened with a border of two unreached impassable cells (the longest move), so no move
    leaves them and a move is one offset."""
    height, width = passable.shape
    border = 2
    padded = width + 2 * border
    distance = np.full((height + 2 * border, padded), np.inf)
    open_ = np.zeros(distance.shape, np.bool_)
    for row in range(height):
        for col in range(width):
            distance[row + border, col + border] = 0.0 if sources[row, col] else np.inf
            open_[row + border, col + border] = passable[row, col]
    # a sweep uses the moves from the cells it has already passed
    ahead = (moves[:, 0] > 0) | ((moves[:, 0] == 0) & (moves[:, 1] > 0))
    forward, backward = _move_table(moves[ahead], padded), _move_table(moves[~ahead], padded)
    flat, flat_open = distance.reshape(-1), open_.reshape(-1)
    # a sweep leaves every cell settled against the cells before it; once a sweep changes nothing, the
    # other direction's last sweep holds too. A forward sweep only needs to start at the first row
    # the backward sweep before it changed, a backward one at the last row the forward one changed.
    top, bottom = border, height + border - 1
    sweeps = 0
    while True:
        if sweeps % 2 == 0:
            first, last = _sweep(flat, flat_open, *forward, top, height + border, border, width + border, 1, padded)
        else:
            last, first = _sweep(flat, flat_open, *backward, bottom, border - 1, width + border - 1, border - 1, -1,
                                 padded)
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
                reached_before, nearest = reached, nearest_cells(reached)
            squared, rows, cols = nearest
            gap = np.sqrt(squared)
            distance = np.where(reached, distance, distance[rows, cols] + gap)
        result.append((distance * resolution).astype(np.float32))
    return result


class DistanceCache:
    """The last cycle's distance maps (_distances_to), handed out again for the same grid and mask:
    the local costmap comes at its own rate and the local goal stays where the path leaves the
    window, so most control cycles would flood the very same grids again. The maps are read-only."""

    def __init__(self):
        self._passable: np.ndarray | None = None
        self._resolution = 0.0
        self._known: list[tuple[np.ndarray, np.ndarray]] = []     # (mask, metres) on that grid

    def distances_to(self, masks, passable: np.ndarray, resolution: float) -> list[np.ndarray]:
        if not (resolution == self._resolution and self._passable is not None
                and np.array_equal(passable, self._passable)):
            self._passable, self._resolution, self._known = passable.copy(), resolution, []
        found = [next((metres for known, metres in self._known if np.array_equal(mask, known)), None)
                 for mask in masks]
        computed = iter(_distances_to([m for m, f in zip(masks, found) if f is None], passable, resolution))
        result = [f if f is not None else next(computed) for f in found]
        for metres in result:
            metres.flags.writeable = False
        self._known = [(mask.copy(), metres) for mask, metres in zip(masks, result)]
        return result


def path_maps(path: np.ndarray, pose, info: MapMetaData, costs: np.ndarray | None = None,
              cache: DistanceCache | None = None) -> PathMaps | None:
    """The distance maps of one cycle, or None when no path point lies on the grid. With costs,
    distances go around the cells the robot's centre may not enter (inscribed, lethal, unknown);
    `cache` keeps the maps of the last cycle to reuse."""
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
    distances = (cache or DistanceCache()).distances_to((on_path, at_goal), passable, info.resolution)
    return PathMaps(local, *distances)


# ---------------------------------------------------------------- rollout kernel

@njit(cache=True, inline="always")
def _step(vx, vy, w, dt):
    """(bx, by, phi, cos phi, sin phi): the exact pose increment of a constant twist over dt, robot
    frame (se2_exp, inlined), and its rotation."""
    phi = w * dt
    cos_phi, sin_phi = math.cos(phi), math.sin(phi)
    if abs(phi) < SMALL_ANGLE:
        along, across = 1.0, 0.5 * phi
    else:
        along, across = sin_phi / phi, (1.0 - cos_phi) / phi
    return (along * vx - across * vy) * dt, (across * vx + along * vy) * dt, phi, cos_phi, sin_phi


@njit(cache=True)
def _rollout(samples, v0, step_limit, ramp, n_steps, dt, pose0, costs, near, skips, grid, outline, check_cost,
             centre_limit, poses, max_cost, legal):
    """Roll out and check every sample; fills poses (T, n_steps+1, 3), max_cost (T,), legal (T,).
    The heading's cosine and sine turn by the step's rotation rather than being recomputed: a
    twist that holds (every step but a ramp's) costs no trigonometry. A trajectory is rolled out
    whole, then checked up to its first illegal pose, which it keeps from there on.

    grid as in kernel_grid; near, skips, outline, check_cost and centre_limit as in PoseCheck and FootprintCheck."""
    headings = np.empty((n_steps + 1, 2))
    for t in range(samples.shape[0]):
        if ramp:
            vx, vy, w = v0[0], v0[1], v0[2]
        else:
            vx, vy, w = samples[t, 0], samples[t, 1], samples[t, 2]
        bx, by, phi, cos_phi, sin_phi = _step(vx, vy, w, dt)     # the sample's own, unless ramping
        x, y, th = pose0[0], pose0[1], pose0[2]
        c, s = math.cos(th), math.sin(th)
        poses[t, 0, 0], poses[t, 0, 1], poses[t, 0, 2] = x, y, th
        for k in range(1, n_steps + 1):
            if ramp and (vx != samples[t, 0] or vy != samples[t, 1] or w != samples[t, 2]):
                vx += min(max(samples[t, 0] - vx, -step_limit[0]), step_limit[0])
                vy += min(max(samples[t, 1] - vy, -step_limit[1]), step_limit[1])
                w += min(max(samples[t, 2] - w, -step_limit[2]), step_limit[2])
                bx, by, phi, cos_phi, sin_phi = _step(vx, vy, w, dt)
            x, y, th = x + c * bx - s * by, y + s * bx + c * by, th + phi
            c, s = c * cos_phi - s * sin_phi, s * cos_phi + c * sin_phi
            poses[t, k, 0], poses[t, k, 1], poses[t, k, 2] = x, y, th
            headings[k, 0], headings[k, 1] = c, s
        count, max_cost[t] = trajectory_cost(poses[t, 1:], headings[1:], costs, near, skips, grid, outline, check_cost,
                                             centre_limit)
        legal[t] = count == n_steps
        for j in range(count + 2, n_steps + 1):   # a stopped rollout keeps its first illegal pose
            poses[t, j, 0], poses[t, j, 1], poses[t, j, 2] = poses[t, count + 1, 0], poses[t, count + 1, 1], \
                poses[t, count + 1, 2]


# ---------------------------------------------------------------- the planner

VALID_DWA_STATUSES = ("ok", "escape", "evade")     # the statuses whose command is a valid one


@dataclass(frozen=True)
class DwaResult:
    status: str                # ok | escape | evade | no_valid_trajectory | no_path
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


def evasion_velocities(params: DwaParams) -> np.ndarray:
    """(T, 3) twists over the whole velocity range, standing (braking) and backing at escape_vel
    among them: what the planner ramps towards when evading movers (DwaPlanner._evade)."""
    vx = _axis(params.min_vel_x, params.max_vel_x, params.vx_samples)
    vx = np.unique(np.append(vx, min(params.escape_vel, 0.0)))
    vy = _axis(params.min_vel_y, params.max_vel_y, min(params.vy_samples, 5)) if params.holonomic_robot else np.zeros(1)
    wz = _axis(params.min_vel_theta, params.max_vel_theta, params.vtheta_samples)
    return np.stack(np.meshgrid(vx, vy, wz, indexing="ij"), axis=-1).reshape(-1, 3)


def _without_standing(params: DwaParams, samples: np.ndarray) -> np.ndarray:
    in_place = (samples[:, 0] == 0.0) & (samples[:, 1] == 0.0)
    return samples[~(in_place & (np.abs(samples[:, 2]) < params.min_in_place_vel_theta))]


class DwaPlanner:
    """The pure DWA core: `compute` is one control cycle. Poses are held to `footprint_check`
    (footprint_check.py); its footprint is the one kept clear of the moving obstacles."""

    def __init__(self, params: DwaParams, footprint_check: FootprintCheck):
        self.params = params
        self.footprint_check = footprint_check
        self.distances = DistanceCache()
        self._escape_start: np.ndarray | None = None   # the pose where backing up began, while escaping
        self._wedged_at: np.ndarray | None = None      # where the robot stood when it became wedged

    def _escaped(self, pose) -> bool:
        start, p = self._escape_start, self.params
        return (math.hypot(pose[0] - start[0], pose[1] - start[1]) >= p.escape_reset_dist
                or abs(wrap_angle(pose[2] - start[2])) >= p.escape_reset_theta)

    def n_steps(self, samples: np.ndarray) -> int:
        """Poses per rollout: the fastest sample moves at most sim_granularity (m, or rad) per step."""
        p = self.params
        fastest = max(float(np.max(np.hypot(samples[:, 0], samples[:, 1]), initial=0.0)),
                      float(np.max(np.abs(samples[:, 2]), initial=0.0)))
        return max(1, int(math.ceil(p.sim_time * fastest / p.sim_granularity)))

    def rollout(self, samples, pose, velocity, costs: np.ndarray, info: MapMetaData, check: PoseCheck | None = None,
                ramp: bool | None = None):
        """(poses (T, S+1, 3), max_cost (T,), legal (T,)) of the samples, one batch; `check` may be
        passed when already set up for this pose and costmap; `ramp` (default: not dwa) ramps each
        rollout's twist from `velocity` towards its sample at the acceleration limits."""
        samples = np.ascontiguousarray(samples, np.float64).reshape(-1, 3)
        p = self.params
        n = self.n_steps(samples)
        dt = p.sim_time / n
        step_limit = np.array([p.acc_lim_x, p.acc_lim_y, p.acc_lim_theta]) * dt
        poses = np.empty((len(samples), n + 1, 3))
        max_cost = np.empty(len(samples), np.int64)
        legal = np.empty(len(samples), np.bool_)
        check = check if check is not None else self.footprint_check.setup(pose, costs, info)
        ramp = not p.dwa if ramp is None else ramp
        _rollout(samples, np.asarray(velocity, np.float64), step_limit, ramp, n, dt,
                 np.asarray(pose, np.float64), kernel_costs(costs), check.near, check.skips,
                 kernel_grid(info), check.outline, self.footprint_check.check_cost, check.centre_limit, poses, max_cost,
                 legal)
        return poses, max_cost, legal

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
        maps = maps if maps is not None else path_maps(path, pose, info, costs, self.distances)
        low, high = reachable(self.params, velocity)
        brake = np.clip(0.0, low, high)   # as hard as the acceleration limits allow
        if not self.params.holonomic_robot:
            brake[1] = 0.0
        if self._escape_start is not None and self._escaped(pose):
            self._escape_start = None
        escaping = self._escape_start is not None
        samples = (fallback_velocities if escaping else sample_velocities)(self.params, velocity)
        if maps is None:
            return DwaResult("no_path", brake, samples, np.zeros((0, 1, 3)), np.zeros(0), -1,
                             "no point of the path lies on the local costmap")
        check = self.footprint_check.setup(pose, costs, info)
        wedged = check if check.wedged else None   # the robot's own outline against every lethal cell
        if wedged is None:
            self._wedged_at = None
        else:
            check = self._escape(check, pose, costs, info, movers)

        def evaluate(samples, check=check):
            """(poses, legal, legal against the costmap alone, scores)"""
            poses, max_cost, static = self.rollout(samples, pose, velocity, costs, info, check)
            if wedged is not None:   # a way off the cells the robot is wedged on must end clear of them
                static = static & self.footprint_check.check_poses(wedged, poses[:, -1], costs, info)
            legal, cost = static, 0.0
            if movers is not None and len(movers):
                clear, cost = self._clear_of(poses, movers)
                legal = static & clear
            return poses, legal, static, self.score(poses, max_cost, legal, maps, info) + cost

        poses, legal, static, scores = evaluate(samples)
        # a gap the robot does not fit stays put; a person in the way walks on, so backing from one
        # starts no escape
        walled_in = not static.any()
        last_resorts = fallback_velocities(self.params, velocity) if not (legal.any() or escaping) else samples[:0]
        if len(last_resorts):     # base_local_planner's last resorts before backing up
            samples = last_resorts
            poses, legal, _, scores = evaluate(samples)
        tight = self.footprint_check.turn_check(check, costs, info) if not legal.any() else None
        if tight is not None:   # the padding keeps the robot from turning where the monitor would not
            samples = fallback_velocities(self.params, velocity)
            poses, legal, _, scores = evaluate(samples, tight)
        if legal.any():
            best = int(np.argmin(scores))
            return DwaResult("ok", samples[best].copy(), samples, poses, scores, best)
        if self.params.evade_movers and movers is not None and len(movers) and not walled_in and wedged is None:
            evasion = self._evade(pose, velocity, costs, info, check, maps, movers)
            if evasion is not None:
                return evasion
        if self.params.escape_vel < 0:
            escape = np.clip(np.array([self.params.escape_vel, 0.0, 0.0]), low, high)
            if escape[0] < 0 and evaluate(escape[None])[1][0]:
                if not escaping and walled_in:
                    self._escape_start = np.array(pose[:3], np.float64)
                return DwaResult("escape", escape, samples, poses, scores, -1,
                                 f"every one of {len(samples)} trajectories collides; backing up")
        if escaping:   # cannot turn or back any further: the whole window again
            self._escape_start = None
            return self.compute(pose, velocity, costs, info, path, maps, movers)
        return DwaResult("no_valid_trajectory", brake, samples, poses, scores, -1,
                         f"every one of {len(samples)} trajectories collides; braking")

    def _escape(self, check: PoseCheck, pose, costs: np.ndarray, info: MapMetaData, movers: Movers | None) -> PoseCheck:
        """What a wedged robot is checked with: the escape check of the cells its outline lay on
        where it became wedged (not where it stands now: forgiven afresh every cycle, a robot creeping
        along a wall may creep on; generated doorway-65; shoved into another wedge without coming
        free, it keeps that anchor and brakes), while no tracked person's edge is within
        wedged_mover_distance; people shove a robot against a wall (driving off along a door's jamb
        while a person pushed it met the jamb: generated doorway-1), but once they have walked on it
        may drive off (generated crossing-79 braked on a wall for 100 s while a person patrolled past).
        A way off must end clear (compute: its last pose legal by the robot's own outline against every
        lethal cell): forgiven all the way, the robot strafed along the jamb it was shoved onto, touching
        it (generated doorway-7048, -7068)."""
        if self._wedged_at is None:
            self._wedged_at = np.array(pose[:3], np.float64)
        if movers is not None and movers.nearest_edge(pose) < self.params.wedged_mover_distance:
            return check
        return self.footprint_check.escape_check(check, self._wedged_at, costs, info)

    def _evade(self, pose, velocity, costs: np.ndarray, info: MapMetaData, check: PoseCheck, maps: PathMaps,
               movers: Movers) -> DwaResult | None:
        """When every sample meets a mover sooner than standing would (or meets one anyway) but the
        costmap alone allows some: the way that meets a mover latest, or none — over twists the
        whole velocity range, each ramped towards at the acceleration limits (braking, turning away,
        speeding past), not only the next period's window. Braking where a crossing person walks is
        no refuge (DynaBARN easy-24: braked in a cylinder's way, struck), nor is stopping to replan.
        The command is the chosen ramp's first control period. None when no way is clear of the
        costmap."""
        p = self.params
        targets = evasion_velocities(p)
        poses, max_cost, legal = self.rollout(targets, pose, velocity, costs, info, check, ramp=True)
        if not legal.any():
            return None
        carried, times = self._carried(poses)
        hard, _ = slack(carried, times, self.footprint_check.footprint, movers, p.dynamic_obstacle_margin, 0.0)
        contact = np.where(legal, first_contact(hard), -1)
        if contact.max() <= 1:      # every way meets one at once: backing up or braking is all that is left
            return None
        scores = np.where(contact == contact.max(), self.score(poses, max_cost, legal, maps, info), np.inf)
        best = int(np.argmin(scores))
        soonest, furthest = reachable(p, velocity)
        cmd = np.clip(targets[best], soonest, furthest)
        meets = (f"meets none within {times[-1]:.1f} s" if contact[best] == len(times)
                 else f"meets one latest, after {times[contact[best]]:.1f} s")
        return DwaResult("evade", cmd, targets, poses, scores, best,
                         f"every trajectory of the window meets a mover; the way ramped towards {meets}")

    def _carried(self, poses: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Rollouts of sim_time carried on to dynamic_horizon, for the movers (dynamic.carried_on)."""
        p = self.params
        return carried_on(poses, p.sim_time / max(1, poses.shape[1] - 1), max(p.dynamic_horizon, p.sim_time))

    def _clear_of(self, poses: np.ndarray, movers: Movers) -> tuple[np.ndarray, np.ndarray]:
        """(legal (T,), cost (T,)) of rollouts against the predicted movers (dynamic.py)."""
        p = self.params
        poses, times = self._carried(poses)
        hard, soft = slack(poses, times, self.footprint_check.footprint, movers, p.dynamic_obstacle_margin, p.dynamic_obstacle_sigmas)
        standing = np.repeat(poses[:1, :1], poses.shape[1], axis=1)
        standing_hard, _ = slack(standing, times, self.footprint_check.footprint, movers, p.dynamic_obstacle_margin, 0.0)
        return critic(hard, soft, standing_hard, p.dynamic_influence_distance, p.dynamic_obstacle_scale,
                      closing_at_once=p.evade_movers)


def warm_up() -> None:
    """Compile (or load from cache) the rollout and flood kernels, outside any control cycle."""
    info = MapMetaData(resolution=0.1, width=4, height=4)
    square = np.array([[0.1, 0.1], [-0.1, 0.1], [-0.1, -0.1], [0.1, -0.1]])
    for dwa in (True, False):
        DwaPlanner(DwaParams(dwa=dwa), FootprintCheck(square)).rollout(
            np.array([[0.1, 0.0, 0.1]]), (0.2, 0.2, 0.0), (0.0, 0.0, 0.0), np.zeros((4, 4), np.uint8), info)
    warm_up_footprint_check()
    _flood(np.eye(4, dtype=np.bool_), np.ones((4, 4), np.bool_), _MOVES)
    warm_up_movers()
