"""Mapping in the simulator (`omninav map --world W`) and the comparison of a map with the truth.

build_map runs, in one process and in lockstep (InProcessRunner), the sim, chassis, lidar and slam
services and a driver. By default the driver is the navigation stack with the explore service
(explore_lite + move_base): explore (explore_node.py) sends frontiers of slam's map as goals to the
navigator, which plans them on the global costmap (slam's map as its static layer, the scans as
its obstacle layer, map → odom from slam) and drives them through the local planner, the velocity
smoother and the collision monitor, with slam's pose as the robot's; until no reachable frontier
is left. With a route, localize-eval's harness drives cmd_vel along the waypoints on the TRUE pose
(a test rig, not navigation), here without its map and start request. The map is the slam node's
map at the end, in the world frame (slam starts at the world's start pose, see node.py).

compare_with_truth scores a map against World.rasterize at the map's resolution: the share of
cells that agree among the cells both call known, and how far each occupied map cell lies from the
nearest truly occupied cell (in cells: 0 on a true wall, 1 next to it).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import numpy as np
from scipy import ndimage

from ..schemas.messages import OccupancyGrid
from ..sim.node import SimNode, SimNodeParams
from ..sim.world import World
from ..geometry.grid import GRID_OBSTACLE
from ..cli.navigate import NAVIGATOR, drive_params
from ..services.chassis.node import ChassisNode, ChassisNodeParams
from ..geometry.footprint import radii
from ..services.costmap.node import CostmapNode, CostmapNodeParams
from ..services.global_planner.node import PlannerNode, PlannerNodeParams
from ..services.lidar.node import LidarNode, LidarNodeParams
from ..services.cmd_vel_mux.node import CmdVelMuxNode
from ..services.velocity_smoother.node import VelocitySmootherNode
from ..services.collision_monitor.node import CollisionMonitorNode
from ..services.local_planner.node import LocalPlannerNode, LocalPlannerNodeParams
from .localize_eval import ROUTES, Harness, HarnessParams, Route, route_problems
from ..geometry.grid import cell_to_world, in_grid, world_to_cell
from ..services.navigator.node import NavigatorNode, NavigatorNodeParams
from ..services.runtime.inprocess import InProcessRunner
from ..services.runtime.node import Node
from ..parameters.from_mapping import load_params
from ..services.tracker.node import TrackerNode, TrackerNodeParams
from ..services.explore.frontiers import Failure
from ..services.explore.node import ExploreNode, ExploreNodeParams
from ..services.slam.node import SlamNode, SlamNodeParams

# gmapping's defaults process a scan per metre driven; indoors, with a 12 m lidar, updating every
# 25 cm / 0.25 rad gives the matcher overlapping scans and the map denser evidence. The explorer
# decides on the map, so it comes every second. The simulated wheel odometry drifts a few cm over a
# route, so matches are pulled towards it (Cartographer's default weights): along a corridor the
# matcher otherwise drifts up to 9 cm (docs/slam.md).
MAPPING_DEFAULTS = dict(linearUpdate=0.25, angularUpdate=0.25, particles=30, map_update_interval=1.0,
                        translation_weight=10.0, rotation_weight=40.0)
MARGIN_M = 2.0      # the map's extent beyond the world's bounds
COSTMAP_PARAMS = Path(__file__).resolve().parents[1] / "compose" / "params"
# localize-eval's routes, except where mapping must see more than localizing needs: every aisle of
# the warehouse (a mover may cross; slam keeps it out of the map as it moves on)
MAPPING_ROUTES: dict[str, Route] = {
    **ROUTES,
    "warehouse": Route(((1.0, 1.0), (1.2, 4.25), (8.8, 4.25), (1.2, 4.25), (1.2, 9.25), (8.8, 9.25), (1.2, 9.25),
                        (1.2, 4.25))),
}


class RouteDriver(Harness):
    """localize-eval's harness without its start: no map, no initial pose, only the driving."""
    service = "map_build"

    def __init__(self, params: HarnessParams, **kwargs):
        super().__init__(params, grid=None, **kwargs)
        self.laps = 0

    def _start(self, t: int, pose) -> None:
        pass

    def jump_to(self, waypoint: int) -> None:
        if waypoint <= self.target:     # back to the loop's start
            self.laps += 1
        super().jump_to(waypoint)


@dataclass
class BuildResult:
    grid: OccupancyGrid | None
    sim_s: float
    finished: bool      # the route driven `laps` times, or no reachable frontier left
    laps: int           # with a route
    goals: int          # frontiers driven to, when exploring
    dropped: tuple[str, ...]    # when exploring: the frontiers dropped for good, where and why
    updates: int
    collisions: int
    malformed: int


def slam_params_for(world: World, overrides: dict | None = None, seed: int = 0) -> SlamNodeParams:
    """Mapping defaults for a world: the map frame at its start pose, the extent around its bounds;
    overrides (slam parameter names) win. Raises ParamError naming a bad parameter."""
    xmin, ymin, xmax, ymax = world.extent
    start = world.robot.start
    values = {**MAPPING_DEFAULTS, "xmin": xmin - MARGIN_M, "ymin": ymin - MARGIN_M, "xmax": xmax + MARGIN_M,
              "ymax": ymax + MARGIN_M, "initial_pose_x": float(start[0]), "initial_pose_y": float(start[1]),
              "initial_pose_a": float(start[2]), "seed": seed, **(overrides or {})}
    return load_params(SlamNodeParams, values, "slam parameters")


def navigation_stack(world: World, drive: str) -> list[Node]:
    """costmap, tracker, global_planner, local_planner, cmd_vel_mux, velocity_smoother, collision_monitor and navigator, as
    `omninav navigate` runs them (compose/params' costmaps, its navigator: replanning every second,
    recovering from oscillation), fed by slam: the map frame is the world's,
    odometry starts at the world's start pose. The tracker ignores slam's map, still being drawn (as
    `navigate --localization slam`)."""
    start = dict(zip(("initial_pose_x", "initial_pose_y", "initial_pose_a"), map(float, world.robot.start)))
    costmap_files = {f"{which}_costmap_files": (str(COSTMAP_PARAMS / "costmap_common_params.yaml"),
                                                str(COSTMAP_PARAMS / f"costmap_{which}_params.yaml"))
                     for which in ("global", "local")}
    # a differential drive as navigate sets it; holonomic drives keep DWA's strafe (±0.1 m/s): with
    # navigate's ±0.3 and its navigator, 8 of 50 mazes had contacts (docs/slam.md)
    strafing = drive_params(drive) if drive == "diff" else {}
    return [CostmapNode(CostmapNodeParams(**costmap_files, **start)), TrackerNode(TrackerNodeParams(use_map=False, **start)),
            PlannerNode(PlannerNodeParams(goal_topic="plan_request", planner_frequency=0.0, use_dijkstra=False,
                                          **start)),
            LocalPlannerNode(LocalPlannerNodeParams(**strafing, **start)),
            CmdVelMuxNode(), VelocitySmootherNode(), CollisionMonitorNode(),
            NavigatorNode(NavigatorNodeParams(**NAVIGATOR, **start))]


@dataclass(frozen=True)
class MappingProgress:
    sim_s: float
    driven: str                  # frontier goals sent, or the lap driven
    mapped: float | None         # the share of the reachable space mapped (None: no map yet)

    def line(self) -> str:
        mapped = "no map yet" if self.mapped is None else f"{100 * self.mapped:.1f} % of the reachable space mapped"
        return f"sim {self.sim_s:.0f} s: {self.driven}, {mapped}"


def build_map(world_name: str, route=None, drive: str = "", seed: int = 0, params: SlamNodeParams | None = None,
              laps: int = 1, max_sim_s: float = 1800.0, speed: float = 0.4,
              progress: Callable[[MappingProgress], None] | None = None, progress_every_s: float = 30.0) -> BuildResult:
    """Explore (no route) or drive the route (a Route or waypoints) `laps` times at `speed`, at most
    max_sim_s of sim time, while slam maps. `progress` hears every progress_every_s of sim time how
    far it is; it only reads, so the map is the same with it or without."""
    sim = SimNode(SimNodeParams(world=world_name, drive=drive, seed=seed))
    world, drive = sim.world, sim.sim.drive
    if route is not None:
        route = route if isinstance(route, Route) else Route(tuple(tuple(map(float, p)) for p in route))
        problems = route_problems(world, route)
        if problems:
            raise ValueError("the route is not clear: " + "; ".join(problems))
        driver = RouteDriver(HarnessParams(route=route, holonomic=drive != "diff", speed=speed))
        drivers = [driver]
        done = lambda: driver.laps >= laps   # noqa: E731
    else:
        inscribed, circumscribed = radii(world.robot.footprint)
        driver = ExploreNode(ExploreNodeParams(robot_radius=circumscribed, inscribed_radius=inscribed))
        drivers = [*navigation_stack(world, drive), driver]
        done = lambda: driver.finished   # noqa: E731
    slam = SlamNode(params or slam_params_for(world, seed=seed))
    runner = InProcessRunner([sim, ChassisNode(ChassisNodeParams(drive=drive)),
                              LidarNode(LidarNodeParams(world=world_name, seed=seed + 1)), slam, *drivers])
    exploring = isinstance(driver, ExploreNode)
    max_steps, chunk = math.ceil(max_sim_s / sim.params.dt), max(1, round(progress_every_s / sim.params.dt))
    taken = 0
    while taken < max_steps and not done():
        taken += runner.run_until(done, min(chunk, max_steps - taken) if progress else max_steps - taken)
        if progress is not None:
            grid = slam.current_map()
            driven = (f"{driver.counters['goals']} frontier goals sent" if exploring
                      else f"lap {min(driver.laps + 1, laps)} of {laps}")
            progress(MappingProgress(sim.now_ns * 1e-9, driven, explored_share(grid, world) if grid else None))
    runner.close()
    return BuildResult(grid=slam.current_map(), sim_s=sim.now_ns * 1e-9, finished=done(),
                       laps=0 if exploring else driver.laps, goals=driver.counters["goals"] if exploring else 0,
                       dropped=tuple(dropped_text(f) for f in driver.failed.dropped) if exploring else (),
                       updates=slam.counters["filter_updates"], collisions=sim.sim.collisions,
                       malformed=sum(v for k, v in slam.counters.items() if k.startswith("malformed/")))


def dropped_text(failure: Failure) -> str:
    x, y = failure.xy.mean(axis=0)
    return f"({x:.2f}, {y:.2f}): " + "; ".join(failure.reasons)


@dataclass(frozen=True)
class Comparison:
    known_both: int              # cells known in both (outside the movers' lanes)
    agreement: float             # share of those on which map and truth agree (occupied or free)
    occupied: int                # occupied map cells inside the truth's grid, outside the movers' lanes
    wall_mean_cells: float       # distance of those cells to the nearest true obstacle cell
    wall_p99_cells: float
    wall_max_cells: float
    within_one_cell: float       # share of those cells at most one cell from a true obstacle
    occupied_in_lanes: int = 0   # occupied map cells where a mover can be (its path swept by its radius)

    def text(self) -> str:
        lanes = (f"; {self.occupied_in_lanes} occupied cells in the movers' lanes (not counted above)"
                 if self.occupied_in_lanes else "")
        return (f"agreement {100 * self.agreement:.2f} % of {self.known_both} cells known in both; "
                f"walls: {self.occupied} occupied cells, distance to the true wall mean {self.wall_mean_cells:.2f}"
                f" / p99 {self.wall_p99_cells:.2f} / max {self.wall_max_cells:.2f} cells, "
                f"{100 * self.within_one_cell:.2f} % within one cell{lanes}")


def mover_lanes(grid: OccupancyGrid, world: World) -> np.ndarray:
    """The map cells a mover can overlap: within its radius of its path (the whole cell)."""
    x, y = cell_to_world(grid.info, *np.indices(grid.data.shape))
    points = np.stack([x.ravel(), y.ravel()], axis=1)
    lanes = np.zeros(len(points), bool)
    half_diagonal = grid.info.resolution / math.sqrt(2.0)
    for loop, radius in zip(world.movers.loops, world.movers.radius):
        for a, b in zip(loop[:-1], loop[1:]):
            ab = b - a
            t = np.clip((points - a) @ ab / max(float(ab @ ab), 1e-12), 0.0, 1.0)
            lanes |= np.hypot(*(points - a - t[:, None] * ab).T) < radius + half_diagonal
    return lanes.reshape(grid.data.shape)


def compare_with_truth(grid: OccupancyGrid, world: World) -> Comparison:
    """The map against the world's true occupancy, rasterized at the map's resolution; each map
    cell is looked up at its centre, so any alignment (and an origin with yaw) is honoured. The
    truth holds the static geometry only: cells a mover can overlap are counted apart."""
    truth = world.rasterize(grid.info.resolution)
    rows, cols = np.indices(grid.data.shape)
    tr, tc = world_to_cell(truth.info, *cell_to_world(grid.info, rows, cols))
    inside = in_grid(truth.info, tr, tc)
    lanes = mover_lanes(grid, world)
    true_val = np.full(grid.data.shape, -1, np.int16)
    true_val[inside] = truth.data[tr[inside], tc[inside]]
    mine = grid.data
    known = (mine >= 0) & (true_val >= 0) & ~lanes
    agree = (mine > GRID_OBSTACLE) == (true_val > GRID_OBSTACLE)
    true_occupied = truth.data > GRID_OBSTACLE
    distance = ndimage.distance_transform_edt(~true_occupied)
    occupied = (mine > GRID_OBSTACLE) & inside
    occ = occupied & ~lanes
    d = distance[tr[occ], tc[occ]]
    n_known = int(known.sum())
    return Comparison(known_both=n_known, agreement=float(agree[known].mean()) if n_known else 0.0,
                      occupied=int(occ.sum()), wall_mean_cells=float(d.mean()) if d.size else 0.0,
                      wall_p99_cells=float(np.percentile(d, 99)) if d.size else 0.0,
                      wall_max_cells=float(d.max()) if d.size else 0.0,
                      within_one_cell=float((d <= 1.0).mean()) if d.size else 0.0,
                      occupied_in_lanes=int((occupied & lanes).sum()))


def explored_share(grid: OccupancyGrid, world: World) -> float:
    """The share of the truly free cells connected to the robot's start (4-connected, at the map's
    resolution) that the map knows (free or occupied): how much of the reachable space was mapped."""
    truth = world.rasterize(grid.info.resolution)
    free = truth.data == 0
    labels, _ = ndimage.label(free)
    start = world_to_cell(truth.info, world.robot.start[0], world.robot.start[1])
    reachable = labels == labels[int(start[0]), int(start[1])]
    rows, cols = np.nonzero(reachable)
    mr, mc = world_to_cell(grid.info, *cell_to_world(truth.info, rows, cols))
    inside = in_grid(grid.info, mr, mc)
    known = np.zeros(len(rows), bool)
    known[inside] = grid.data[mr[inside], mc[inside]] >= 0
    return float(known.mean())
