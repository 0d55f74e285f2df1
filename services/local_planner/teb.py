"""TEB: the timed elastic band among moving people, with teb_local_planner's homotopy-class planning.

The band itself is the elastic band's (eband.py: poses and time intervals optimised for time,
velocity and acceleration limits, drive kinematics and clearance), here with
include_dynamic_obstacles on: each pose is held clear of every tracked mover *where that mover will
be when the band reaches the pose* (its constant-velocity prediction at the pose's time, its radius
grown by dynamic_obstacle_sigmas of the prediction's spread).

One band gets stuck in the first local minimum: passing a pillar on the side the global path
happens to graze, or squeezing in front of a person it could pass behind. TEB therefore keeps up to
max_number_classes bands in different homotopy classes and drives the best. One cycle
(`TebPlanner.compute`):
1. candidates: every band kept from the last cycle, warm-started (moved to the robot and the new
   local goal, as the elastic band warm-starts its one band); the global path's own band; and, as
   teb's simple exploration does, for each obstacle the path comes near — a blob of lethal cells no
   longer than homotopy_obstacle_max_extent (walls are not passed on two sides) or a mover where it
   will be when the robot gets there — a band through a via point beside it on the left and one on
   the right;
2. each candidate is optimised; its class is the side on which it passes each of those obstacles
   (the sign of the cross product of its heading and the obstacle at its closest approach: a
   simple H-signature), and of two candidates in one class only the cheaper stays;
3. each is checked as the elastic band's one is (the costmap, min_obstacle_dist, movers met sooner
   than standing still would meet them) and scored by teb's selection cost: the band's cost with the
   obstacle terms scaled by selection_obst_cost_scale; the band driven last keeps its place unless a
   new one costs less than its cost × selection_cost_hysteresis;
4. the best feasible band gives the command; the feasible ones (at most max_number_classes, the
   cheapest) are kept for the next cycle. None feasible: brake, no_valid_trajectory.
"""
from __future__ import annotations

import math
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass

import numpy as np
from scipy import ndimage

from ...geometry.footprint import radii
from ...geometry.grid import cell_to_world, in_grid, world_to_cell
from ...geometry.polygons import arc_lengths, densify
from ...geometry.movers import Movers
from ...parameters.declare import param
from ...schemas.messages import MapMetaData
from ..costmap.layers import FREE_SPACE, INSCRIBED_INFLATED_OBSTACLE, LETHAL_OBSTACLE, NO_INFORMATION
from .eband import Band, BandProblem, EbandResult, ElasticBandPlanner, clearance_field, initial_band
from .footprint_check import FootprintCheck
from .params import ElasticBandParams

VIA_MARGIN = 0.1    # m beyond the footprint's reach and min_obstacle_dist at which a via point passes an obstacle
EXPLORED = 3        # obstacles explored around per cycle, the nearest along the path
THREADS = 2         # the machines this runs on have two cores
MARKS_LAG_S = 0.6   # s the costmap's marks of a mover lag behind it (scans, the costmap's update, delays)


@dataclass(frozen=True)
class TebParams(ElasticBandParams):
    """The elastic band's (teb_local_planner's names; include_dynamic_obstacles, off by default as
    in TEB, puts the movers in) and teb's homotopy-class planning."""
    enable_homotopy_class_planning: bool = True
    enable_multithreading: bool = True                          # the classes' bands optimised on THREADS threads
    max_number_classes: int = param(4, ge=1)                    # bands kept and optimised each cycle
    selection_cost_hysteresis: float = param(1.0, gt=0)         # a new band must cost below the driven one's × this
    selection_obst_cost_scale: float = param(100.0, ge=0)       # the obstacle terms' extra weight when selecting
    selection_prefer_initial_plan: float = param(0.95, gt=0, le=1)   # × the cost of a band in the global path's class
    homotopy_obstacle_max_extent: float = param(2.0, gt=0)      # m: a longer blob of lethal cells is a wall, passed on one side (ours)



@dataclass(frozen=True)
class Obstacle:
    """An obstacle explored around: a centre, how far it reaches from it, and when (None: static)."""
    centre: np.ndarray          # (2,)
    extent: float               # m
    mover: int | None = None    # index among the movers


@dataclass
class _Candidate:
    poses: np.ndarray
    dts: np.ndarray
    warm: bool = False          # warm-started from a kept band
    driven: bool = False        # from the band driven last cycle
    initial: bool = False       # from the global path itself
    signature: tuple[int, ...] = ()
    cost: float = math.inf      # the selection cost
    problem: str = ""           # why it may not be driven ('' : feasible)
    clearance: float = math.inf


class TebPlanner:
    """The pure TEB core: `compute` is one control cycle; it keeps the last cycle's feasible bands
    (one per homotopy class) to warm-start the next. `footprint_check` is the local planner's one
    collision check, as for DWA and the elastic band."""

    def __init__(self, params: TebParams, footprint_check: FootprintCheck):
        self.params = params
        self.band = ElasticBandPlanner(params, footprint_check)
        self.inscribed = radii(footprint_check.footprint)[0]
        self._kept: list[Band] = []     # the last cycle's feasible bands, the driven one first
        self._pool: ThreadPoolExecutor | None = None

    def reset(self) -> None:
        """Forget the kept bands (a new goal, or after a recovery)."""
        self._kept = []

    def compute(self, pose, velocity, costs: np.ndarray, info: MapMetaData, path: np.ndarray,
                movers: Movers | None = None) -> EbandResult:
        """One cycle: pose (x, y, yaw) and path (N, 3) in the costmap's frame, velocity (vx, vy, wz)
        in the robot frame, movers (the tracker's tracks at this instant) in the costmap's frame."""
        p, band = self.params, self.band
        pose = np.asarray(pose, np.float64)
        path = np.asarray(path, np.float64).reshape(-1, 3)
        brake = band.brake(velocity)
        spanned = band.span(pose, path, info)
        if spanned is None:
            self.reset()
            return EbandResult("no_path", brake, np.zeros((0, 3)), np.zeros(0),
                               "no point of the path lies on the local costmap")
        span, goal, at_final_goal = spanned
        stop = band.stops_at_goal(at_final_goal)
        movers = movers if movers is not None and len(movers) else None
        if movers is not None and p.include_dynamic_obstacles:
            costs = without_movers(costs, info, movers, self.inscribed)
        field = clearance_field(costs, info.resolution)
        obstacles = self._obstacles(span, costs, info, movers) if p.enable_homotopy_class_planning else []
        interaction = self._interaction()
        candidates = self._starts(span, pose, goal, path, costs, info, obstacles, movers)
        optimised = self._map(lambda c: band.optimise(c.poses, c.dts, velocity, stop, field, info, movers), candidates)
        for c, (poses, dts) in zip(candidates, optimised):
            c.poses, c.dts = poses, dts
            c.poses[:, 2] = np.arctan2(np.sin(c.poses[:, 2]), np.cos(c.poses[:, 2]))
            c.signature = signature(c.poses, c.dts, obstacles, movers, interaction)
        weights = band.weights(0)
        weights[9:13] *= math.sqrt(p.selection_obst_cost_scale)
        initial = {c.signature for c in candidates if c.initial}
        for c in candidates:
            c.cost = BandProblem(band, c.poses, c.dts, velocity, stop, field, info, 0, movers, weights).cost()
            if c.signature in initial:
                c.cost *= p.selection_prefer_initial_plan
            c.problem, c.clearance = band.problem(c.poses, c.dts, costs, info, field, movers, whole=False)
        feasible = sorted(_cheapest_per_class(c for c in candidates if not c.problem), key=lambda c: c.cost)
        if not feasible:
            self._kept = []
            cheapest = min(candidates, key=lambda c: c.cost)
            return EbandResult("no_valid_trajectory", brake, cheapest.poses, cheapest.dts, cheapest.problem,
                               cheapest.clearance)
        best = feasible[0]
        driven = next((c for c in feasible if c.driven), None)
        if driven is not None and not best.cost < driven.cost * p.selection_cost_hysteresis:
            best = driven
        # the driven band first: next cycle's hysteresis knows it by that place
        kept = [best] + [c for c in feasible if c is not best][:p.max_number_classes - 1]
        self._kept = [Band(path.copy(), c.poses, c.dts) for c in kept]
        return EbandResult("ok", band.command(best.poses, best.dts, velocity), best.poses, best.dts, "",
                           best.clearance, best.warm)

    def _map(self, work, items: list) -> list:
        """work(item) for each item, on enable_multithreading's threads (the solver releases the GIL;
        each band's optimisation is its own, so the results are the same either way)."""
        if not self.params.enable_multithreading or len(items) < 2:
            return [work(item) for item in items]
        if self._pool is None:
            self._pool = ThreadPoolExecutor(THREADS, thread_name_prefix="teb")
        return list(self._pool.map(work, items))

    def _interaction(self) -> float:
        """m: an obstacle whose edge comes this near the band's centre line is passed on a side."""
        return self.band.reach + self.params.inflation_dist

    def _starts(self, span, pose, goal, path, costs, info, obstacles, movers) -> list[_Candidate]:
        """The candidates' first bands, one per class, at most max_number_classes: the kept ones
        warm-started (the one driven last first), the global path's, then a detour on each side of
        every explored obstacle whose via point is open."""
        p = self.params
        warm = [_Candidate(*w, warm=True, driven=i == 0) for i, w in
                enumerate(kept.warm(path, pose, goal, info.resolution, p) for kept in self._kept) if w is not None]
        # the driven band, the global path's and the other kept ones come before any new detour
        starts = [c for c in warm if c.driven] + [_Candidate(*initial_band(span, pose, goal, p), initial=True)]
        starts += [c for c in warm if not c.driven]
        clearance = self.band.reach + p.min_obstacle_dist + VIA_MARGIN
        for obstacle in obstacles:
            for side in (1.0, -1.0):
                found = _detour(span, obstacle, side, clearance)
                if found is not None and _open(found[0][found[1] - 1:found[1] + 2], costs, info):
                    starts.append(_Candidate(*initial_band(found[0], pose, goal, p)))
        interaction, distinct = self._interaction(), {}
        for start in starts:
            start.signature = signature(start.poses, start.dts, obstacles, movers, interaction)
            if start.signature in distinct:     # the first of a class stays, in the global path's class if either is
                distinct[start.signature].initial |= start.initial
            else:
                distinct[start.signature] = start
        return list(distinct.values())[:p.max_number_classes]

    def _obstacles(self, span, costs, info, movers) -> list[Obstacle]:
        """The blobs of lethal cells and the movers the span comes near, the EXPLORED nearest along it."""
        p = self.params
        reach = self._interaction()
        found = _blobs(span, costs, info, p.homotopy_obstacle_max_extent, reach)
        if movers is not None:
            found += _movers_met(span, movers, p.max_vel_x, reach)
        found.sort(key=lambda item: item[0])
        return [o for _, o in found[:EXPLORED]]


def without_movers(costs: np.ndarray, info: MapMetaData, movers: Movers, inscribed: float) -> np.ndarray:
    """The costmap with the tracked movers' own marks taken out: the lethal cells within a mover's
    radius (and a cell) of where it is and was over the last MARKS_LAG_S, the inflated ones within
    that and the footprint's inscribed radius. The band is held clear of the movers where they
    will be; their marks where they are (and, the scans lagging, were) would hold it off a place
    the mover leaves before the robot gets there. A wall's lethal cells that near a mover stay
    out too; the footprint check of the first poses and the collision monitor still see the
    scans."""
    out = costs.copy()
    x, y = cell_to_world(info, *np.indices(costs.shape))
    lethal = costs >= LETHAL_OBSTACLE
    for (px, py), (vx, vy), radius in zip(movers.positions, movers.velocities, movers.radii):
        # distance from each cell to the segment the mover walked over the last MARKS_LAG_S
        ax, ay = px - vx * MARKS_LAG_S, py - vy * MARKS_LAG_S
        ex, ey = px - ax, py - ay
        t = np.clip(((x - ax) * ex + (y - ay) * ey) / max(ex * ex + ey * ey, 1e-12), 0.0, 1.0)
        distance = np.hypot(x - (ax + t * ex), y - (ay + t * ey))
        body = distance <= radius + info.resolution
        out[body & lethal] = FREE_SPACE
        out[(distance <= radius + inscribed + info.resolution) & ~lethal & (costs < NO_INFORMATION)] = FREE_SPACE
    return out


def _cheapest_per_class(candidates) -> list[_Candidate]:
    best: dict[tuple[int, ...], _Candidate] = {}
    for c in candidates:
        if c.signature not in best or c.cost < best[c.signature].cost:
            best[c.signature] = c
    return list(best.values())


def signature(poses: np.ndarray, dts: np.ndarray, obstacles: list[Obstacle], movers: Movers | None,
              interaction: float) -> tuple[int, ...]:
    """The side (+1 left, -1 right, 0 not passed) on which the band passes each obstacle: the sign of
    the cross product of the band's direction and the obstacle, at the band's closest approach to it
    (a mover where it is at that pose's time)."""
    times = np.concatenate([[0.0], np.cumsum(dts)])
    step = np.diff(poses[:, :2], axis=0)
    step = np.vstack([step, step[-1:]])
    sides = []
    for o in obstacles:
        centres = (np.broadcast_to(o.centre, poses[:, :2].shape) if o.mover is None
                   else movers.positions[o.mover] + movers.velocities[o.mover] * times[:, None])
        offset = centres - poses[:, :2]
        gap = np.hypot(offset[:, 0], offset[:, 1]) - o.extent
        k = int(np.argmin(gap))
        if gap[k] > interaction:
            sides.append(0)
            continue
        cross = step[k, 0] * offset[k, 1] - step[k, 1] * offset[k, 0]
        sides.append(1 if cross < 0 else -1)    # the obstacle on the band's right: the band passes left of it
    return tuple(sides)


def _blobs(span, costs, info: MapMetaData, max_extent: float, reach: float) -> list[tuple[float, Obstacle]]:
    """(distance along the span, obstacle) of each 8-connected blob of lethal cells no longer than
    max_extent whose edge comes within `reach` of the span, beyond the span's first point."""
    labels, count = ndimage.label(costs >= LETHAL_OBSTACLE, structure=np.ones((3, 3)))
    along = arc_lengths(span)
    found = []
    for index, (rows, cols) in enumerate(ndimage.find_objects(labels)):
        if max(rows.stop - rows.start, cols.stop - cols.start) * info.resolution > max_extent:
            continue    # a wall
        r, c = np.nonzero(labels[rows, cols] == index + 1)
        x, y = cell_to_world(info, r + rows.start, c + cols.start)
        points = np.column_stack([x, y])
        centre = (points.min(axis=0) + points.max(axis=0)) / 2
        extent = float(np.hypot(*(points - centre).T).max()) + info.resolution / 2
        distance = np.hypot(*(span[:, :2] - centre).T)
        k = int(np.argmin(distance))
        if k > 0 and distance[k] - extent <= reach:
            found.append((float(along[k]), Obstacle(centre, extent)))
    return found


def _movers_met(span, movers: Movers, speed: float, reach: float) -> list[tuple[float, Obstacle]]:
    """(distance along the span, obstacle) of each mover that comes within `reach` of the robot driving
    the span at `speed`: the mover where it is when the robot is nearest it."""
    along = arc_lengths(span)
    times = along / speed
    found = []
    for m in range(len(movers)):
        centres = movers.positions[m] + movers.velocities[m] * times[:, None]
        gap = np.hypot(*(centres - span[:, :2]).T) - movers.radii[m]
        k = int(np.argmin(gap))
        if k > 0 and gap[k] <= reach:
            found.append((float(along[k]), Obstacle(centres[k], float(movers.radii[m]), m)))
    return found


def _open(polyline: np.ndarray, costs: np.ndarray, info: MapMetaData) -> bool:
    """Whether the robot's centre may pass along the polyline: every cell it crosses on the grid
    below the inscribed cost (a detour whose via point lies in a wall is not worth optimising)."""
    points = densify(polyline, info.resolution / 2)
    rows, cols = world_to_cell(info, points[:, 0], points[:, 1])
    on = in_grid(info, rows, cols)
    return bool((costs[rows[on], cols[on]] < INSCRIBED_INFLATED_OBSTACLE).all())


def _detour(span: np.ndarray, obstacle: Obstacle, side: float, clearance: float) -> tuple[np.ndarray, int] | None:
    """The span through a via point beside the obstacle (side +1: on the span's left), the span's
    points within that reach of the via point's station left out, and the via point's index (its
    legs are the points either side of it); None when the obstacle is nearest the span's ends
    (nothing to pass)."""
    distance = np.hypot(*(span[:, :2] - obstacle.centre).T)
    k = int(np.argmin(distance))
    if k == 0 or k == len(span) - 1:
        return None
    direction = span[k + 1, :2] - span[k - 1, :2]
    direction /= max(np.hypot(*direction), 1e-9)
    normal = np.array([-direction[1], direction[0]])
    # from the obstacle's centre, past its far edge on that side
    via = obstacle.centre + side * normal * (obstacle.extent + clearance)
    along = arc_lengths(span)
    keep = np.abs(along - along[k]) > obstacle.extent + clearance
    keep[0] = keep[-1] = True
    before, after = span[keep & (along < along[k])], span[keep & (along > along[k])]
    heading = math.atan2(direction[1], direction[0])
    return np.vstack([before, [[via[0], via[1], heading]], after]), len(before)

