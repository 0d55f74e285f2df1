"""`omninav bench local`: one DWA control cycle over ≥ 1000 trajectories on a real building's costmap.

The Willow Garage map (shared/data/maps/willow-full-0.05.yaml) is inflated for the mecanum
paper's 0.832 × 0.636 m footprint (static + inflation layers, ROS defaults) and a global path is
planned between the first of the global-planner bench's seeded far-apart pairs. The robot is then
put on CYCLES poses along that path (every half metre from the start) moving at 0.4 m/s along it;
each pose crops the 6 × 6 m local costmap around it (120 × 120 cells) and runs
DwaPlanner.compute — path and goal distance maps, sampling, the batched rollout and scoring —
REPEATS times, the fastest counting (as the planner bench: other load on the shared machine
inflates the figures less); median and p99 are over the poses. Sampling: the ROS defaults with vx_samples 6, vy_samples 10 (+ y_vels and 0),
vtheta_samples 20 and max_vel_y 0.5, which gives over a thousand trajectories per cycle.

Elastic band, in the same run: ElasticBandPlanner.compute (EBAND_PARAMS: holonomic, TEB's 3 m
lookahead and 5 × 4 iterations) at the same poses and velocity; per pose one cold cycle (a new
band) and then REPEATS warm-started cycles on the same path, the fastest on the wall clock counting
(and beside it the median CPU time of all threads: TEB optimises its classes' bands on two). TEB likewise
(TebPlanner.compute, the same band settings, homotopy classes on), with a person crossing the path
PERSON_AHEAD_M ahead of the robot at PERSON_SPEED: its median, p95 and p99 (teb_local_planner runs
at 10–20 Hz; issue 35's aim is p95 ≤ 25 ms on 2 cores). `--controller` picks which of the two run.

Reference, in the same run: the same rollout and checks written as a plain per-trajectory Python
loop (odometry.integrate per step, costmap lookups per pose) on REFERENCE_SAMPLES trajectories of
each of the first cycles, scaled to the cycle's sample count; its legality and costs are compared
with the batch's. The numba kernel is compiled (or loaded from cache) before anything is timed.
"""
from __future__ import annotations

import argparse
import json
import math
import statistics
import sys
import time
from dataclasses import fields

import numpy as np

from ..geometry.polygons import arc_lengths
from ..schemas.messages import MapMetaData, Pose2D
from ..services.costmap import layers as costmap_layers
from ..services.global_planner import astar
from .planner import MAP, inflated_costmap, load_bench_map, pick_pairs, timed
from ..services.global_planner.params import GlobalPlannerParams
from ..geometry.grid import cell_to_world, world_to_cell
from ..services.runtime.errors import UserError, exits_2_on_user_error
from ..services.local_planner import eband
from ..services.local_planner.dwa import DwaPlanner, warm_up
from ..services.local_planner.footprint_check import FootprintCheck, footprint_check_cost
from ..services.local_planner.params import DwaParams, ElasticBandParams
from ..services.local_planner.reference import reference_rollout
from ..services.local_planner.teb import TebPlanner, TebParams
from ..geometry.movers import Movers

CYCLES, REPEATS, SPACING_M, WINDOW_M = 60, 5, 0.5, 6.0
SPEED = 0.4                 # m/s along the path
REFERENCE_SAMPLES, REFERENCE_CYCLES = 40, 5
BAR_MS = 10.0
PARAMS = DwaParams(vx_samples=6, vy_samples=10, vtheta_samples=20, max_vel_y=0.5, min_vel_y=-0.5)
EBAND_PARAMS = ElasticBandParams(holonomic_robot=True, max_vel_y=0.4, min_obstacle_dist=0.1, inflation_dist=0.2)
TEB_PARAMS = TebParams(**{**{f.name: getattr(EBAND_PARAMS, f.name) for f in fields(ElasticBandParams)},
                          "include_dynamic_obstacles": True})
PERSON_AHEAD_M, PERSON_SPEED, PERSON_RADIUS = 1.5, 1.0, 0.25
BANDS = ("eband", "teb")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--map", default=None, help=f"map YAML (default: the shared data folder's {MAP})")
    parser.add_argument("--controller", nargs="+", choices=BANDS, default=list(BANDS),
                        help="the band controllers timed beside DWA (default both)")


def crop(costs: np.ndarray, info: MapMetaData, x: float, y: float) -> tuple[np.ndarray, MapMetaData]:
    """The WINDOW_M square of a yaw-free global costmap around (x, y), as a local costmap."""
    n = int(round(WINDOW_M / info.resolution))
    row, col = world_to_cell(info, x, y)
    r0 = int(np.clip(row - n // 2, 0, info.height - n))
    c0 = int(np.clip(col - n // 2, 0, info.width - n))
    local = MapMetaData(resolution=info.resolution, width=n, height=n,
                        origin=Pose2D(info.origin.x + c0 * info.resolution, info.origin.y + r0 * info.resolution, 0.0))
    return np.ascontiguousarray(costs[r0:r0 + n, c0:c0 + n]), local


def _percentile(values, q):
    return float(np.percentile(np.asarray(values), q))


@exits_2_on_user_error("bench local")
def main(args: argparse.Namespace) -> int:
    path, grid = load_bench_map(args.map)
    if grid.info.origin.theta != 0.0:
        raise UserError(f"{path} has a yawed origin; the bench crops axis-aligned windows")
    costmap_layers.warm_up()
    astar.warm_up()
    eband.warm_up()
    start = time.perf_counter()
    warm_up()
    warm_ms = (time.perf_counter() - start) * 1e3
    costmap = inflated_costmap(grid)
    costs, info = costmap.costs, costmap.info
    planner_params = GlobalPlannerParams(use_dijkstra=False)
    (s, g), = pick_pairs(costs, info.resolution, planner_params)[:1]
    plan = astar.GlobalPlanner(planner_params).plan(costs, info, (*cell_to_world(info, *s), 0.0),
                                                    (*cell_to_world(info, *g), 0.0))
    if not plan.ok:
        print(f"omninav bench local: no global path on {path}: {plan.message}", file=sys.stderr)
        return 1
    along = arc_lengths(plan.poses)
    picks = np.searchsorted(along, np.arange(CYCLES) * SPACING_M).clip(0, len(along) - 1)

    # the robot at each pose, moving along the path, in its local window
    windows = [(plan.poses[index], *crop(costs, info, *plan.poses[index][:2])) for index in picks]
    velocity = np.array([SPEED, 0.0, 0.0])

    fp, inflation = costmap.footprint, costmap.params.layers[1]
    planner = DwaPlanner(PARAMS, FootprintCheck(fp.points, footprint_check_cost(
        fp.inscribed_radius, fp.circumscribed_radius, inflation.inflation_radius, inflation.cost_scaling_factor)))
    cycle_ms, samples, legal, statuses, reference_ms, mismatches = [], [], [], {}, [], 0
    for i, (pose, local_costs, local_info) in enumerate(windows):
        result, ms = timed(lambda: planner.compute(pose, velocity, local_costs, local_info, plan.poses), REPEATS)
        cycle_ms.append(ms)
        samples.append(len(result.samples))
        legal.append(int(result.legal.sum()))
        statuses[result.status] = statuses.get(result.status, 0) + 1
        if i < REFERENCE_CYCLES:
            chosen = np.linspace(0, len(result.samples) - 1, REFERENCE_SAMPLES).astype(int)
            subset = result.samples[chosen]
            poses, max_cost, ok = planner.rollout(subset, pose, velocity, local_costs, local_info)
            begin = time.perf_counter()
            for k, twist in enumerate(subset):
                _, ref_cost, ref_ok = reference_rollout(planner, twist, planner.n_steps(subset), pose, velocity,
                                                        local_costs, local_info)
                mismatches += int(ref_ok != ok[k] or ref_cost != max_cost[k])
            reference_ms.append((time.perf_counter() - begin) * 1e3 * len(result.samples) / REFERENCE_SAMPLES)

    bands = {}
    if "eband" in args.controller:
        bands["eband"] = time_band(eband.ElasticBandPlanner(EBAND_PARAMS, planner.footprint_check), windows, velocity,
                                   plan.poses, lambda pose: None)
    if "teb" in args.controller:
        bands["teb"] = time_band(TebPlanner(TEB_PARAMS, planner.footprint_check), windows, velocity, plan.poses,
                                 lambda pose: crossing_person(pose))

    figures = {
        "map": str(path), "cycles": len(windows), "repeats": REPEATS,
        "window_cells": [local_info.width, local_info.height],
        "samples": int(min(samples)), "samples_median": float(statistics.median(samples)),
        "steps": planner.n_steps(result.samples),
        "legal_median": float(statistics.median(legal)), "statuses": statuses,
        "cycle_median_ms": statistics.median(cycle_ms), "cycle_p99_ms": _percentile(cycle_ms, 99),
        "cycle_max_ms": max(cycle_ms), "warm_up_ms": warm_ms,
        "reference": f"per-trajectory Python loop on {REFERENCE_SAMPLES} samples of {len(reference_ms)} cycles, scaled",
        "reference_cycle_median_ms": statistics.median(reference_ms),
        "reference_mismatches": mismatches, "bar_ms": BAR_MS,
        **{f"{name}_{key}": value for name, timing in bands.items() for key, value in timing.items()},
    }
    if args.json:
        print(json.dumps(figures))
        return 0
    print(f"map {path}; mecanum footprint 0.832 x 0.636 m; {WINDOW_M:.0f} x {WINDOW_M:.0f} m local windows "
          f"({local_info.width} x {local_info.height} cells) at {len(windows)} poses along a "
          f"{plan.length:.1f} m global path, moving at {SPEED} m/s; fastest of {REPEATS} cycles per pose")
    print(f"DWA cycle (distance maps + sampling + rollout + scoring) over {figures['samples']}–{max(samples)} "
          f"trajectories x {figures['steps']} steps: median {figures['cycle_median_ms']:.2f} ms, p99 "
          f"{figures['cycle_p99_ms']:.2f} ms, max {figures['cycle_max_ms']:.2f} ms (bar {BAR_MS:.0f} ms); "
          f"legal median {figures['legal_median']:.0f}; statuses {statuses}")
    print(f"  reference {figures['reference']}: median {figures['reference_cycle_median_ms']:.0f} ms per cycle; "
          f"{mismatches} disagreements in legality or cost")
    for name, t in bands.items():
        crossing = (f", a person crossing {PERSON_AHEAD_M} m ahead at {PERSON_SPEED} m/s" if name == "teb" else "")
        print(f"{'elastic band' if name == 'eband' else 'TEB'} cycle ({EBAND_PARAMS.max_global_plan_lookahead_dist:.0f} "
              f"m lookahead, median {t['poses_median']:.0f} poses{crossing}), warm-started: median "
              f"{t['cycle_median_ms']:.2f} ms, p95 {t['cycle_p95_ms']:.2f} ms, p99 {t['cycle_p99_ms']:.2f} ms "
              f"(bar {BAR_MS:.0f} ms; wall clock), CPU of all threads median {t['cpu_median_ms']:.2f} ms; cold: "
              f"median {t['cold_median_ms']:.2f} ms; statuses {t['statuses']}")
    return 0


def crossing_person(pose) -> Movers:
    """A person PERSON_AHEAD_M ahead of the robot at `pose`, a metre to its right, walking across its heading."""
    c, s = math.cos(pose[2]), math.sin(pose[2])
    ahead = np.array([pose[0] + PERSON_AHEAD_M * c + s, pose[1] + PERSON_AHEAD_M * s - c])
    return Movers(ahead[None], PERSON_SPEED * np.array([[-s, c]]), np.array([PERSON_RADIUS]), np.zeros((1, 3)))


def time_band(band, windows, velocity, path, movers_at) -> dict:
    """A band controller's cycle times at every window: one cold cycle, then REPEATS warm ones (the
    fastest counting) on the wall clock (TEB optimises its classes' bands on threads), and the
    CPU time of all the process's threads in the same cycles."""
    warm_ms, cold_ms, cpu_ms, poses, statuses = [], [], [], [], {}
    for pose, local_costs, local_info in windows:
        movers = movers_at(pose)
        band.reset()
        _, cold = timed(lambda: band.compute(pose, velocity, local_costs, local_info, path, movers), 1, time.perf_counter)
        result, warm = timed(lambda: band.compute(pose, velocity, local_costs, local_info, path, movers), REPEATS,
                             time.perf_counter)
        cpu_ms.append(timed(lambda: band.compute(pose, velocity, local_costs, local_info, path, movers), REPEATS,
                            time.process_time)[1])
        cold_ms.append(cold)
        warm_ms.append(warm)
        poses.append(len(result.trajectory))
        statuses[result.status] = statuses.get(result.status, 0) + 1
    return {"cycle_median_ms": statistics.median(warm_ms), "cycle_p95_ms": _percentile(warm_ms, 95),
            "cycle_p99_ms": _percentile(warm_ms, 99), "cpu_median_ms": statistics.median(cpu_ms),
            "cold_median_ms": statistics.median(cold_ms), "poses_median": statistics.median(poses),
            "statuses": statuses}
