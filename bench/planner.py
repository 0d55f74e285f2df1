"""`omninav bench planner`: global planning across a real building, with a reference in the same run.

The Willow Garage map (shared/data/maps/willow-full-0.05.yaml, 1165 × 945 cells) becomes a global
costmap (static + inflation layers, ROS defaults) inflated for the mecanum paper's 0.832 × 0.636 m
footprint; the time to inflate the whole map is measured first. Then 20 fixed pairs of far-apart
free cells (seeded; both in the largest 4-connected region of known passable cells, so a path
exists) are planned with A* (use_dijkstra: false) and with Dijkstra (ROS's default); each pair is
planned 3 times and the fastest counts, so other load on the machine inflates the figures less.
Times are of GlobalPlanner.plan: search, smoothing and orientations, in CPU time of the planning
thread (nothing here runs in another thread), which other processes on a shared machine disturb
far less than the wall clock.

Reference: scipy.sparse.csgraph.dijkstra on the same graph (same passability, weights and corner
rule), single-source from the start, on the first pairs; its cost to the goal must equal ours.
With `--navfn DIR` (navfn's sources, not part of omninav: bench/navfn_reference.py) also ROS navfn
on the same costmap and pairs, timed as navfn_ros plans (setCostmap + the search and path), fastest
of the same number of runs: the ratio per pair of our time to navfn's, and its median.
"""
from __future__ import annotations

import argparse
import json
import statistics
import sys
import time
from pathlib import Path

import numpy as np
from scipy import ndimage
from scipy.sparse import csgraph

from ..schemas.messages import OccupancyGrid
from ..sim.world import shared_data_dir
from ..geometry.footprint import DEFAULT_FOOTPRINT
from ..services.costmap import layers as costmap_layers
from ..services.costmap.costmap import Costmap
from ..services.costmap.params import CostmapParams, InflationLayerParams, StaticLayerParams
from ..services.map_server.mapio import MapError, load_map
from ..geometry.grid import cell_to_world
from ..services.runtime.errors import UserError, exits_2_on_user_error
from ..services.global_planner.astar import GlobalPlanner, passable, warm_up
from ..services.global_planner.reference import graph
from ..services.global_planner.params import GlobalPlannerParams
from .navfn_reference import build as build_navfn, plan_times as navfn_plan_times

MAP = "maps/willow-full-0.05.yaml"
PAIRS, SEED, MIN_APART_M, RUNS = 20, 6, 25.0, 3
BAR_PLAN_MS, BAR_INFLATE_MS = 50.0, 200.0


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--map", default=None, help=f"map YAML (default: the shared data folder's {MAP})")
    parser.add_argument("--reference-pairs", type=int, default=3, metavar="N",
                        help="pairs also solved by scipy's Dijkstra (default 3; a few hundred ms each)")
    parser.add_argument("--navfn", metavar="DIR", default=None,
                        help="also time ROS navfn, compiled from its sources in DIR (navfn.cpp, navfn/navfn.h), "
                             "on the same costmap and pairs")


def pick_pairs(costs: np.ndarray, resolution: float, params: GlobalPlannerParams) -> list[tuple]:
    """PAIRS (start, goal) cells, each a free cell (cost 0) in the largest 4-connected region of
    known passable cells, at least MIN_APART_M apart; fixed by SEED."""
    known = passable(costs, *np.indices(costs.shape), params) & (costs != costmap_layers.NO_INFORMATION)
    labels, _ = ndimage.label(known)
    largest = np.bincount(labels.ravel())[1:].argmax() + 1
    free = np.argwhere((labels == largest) & (costs == costmap_layers.FREE_SPACE))
    rng = np.random.default_rng(SEED)
    pairs = []
    while len(pairs) < PAIRS:
        a, b = free[rng.integers(len(free), size=2)]
        if np.hypot(*(a - b)) * resolution >= MIN_APART_M:
            pairs.append((tuple(int(v) for v in a), tuple(int(v) for v in b)))
    return pairs


def load_bench_map(map_arg: str | None) -> tuple[Path, OccupancyGrid]:
    """The map a bench runs on: --map, or MAP in the shared data folder."""
    path = Path(map_arg) if map_arg else (shared_data_dir(Path(__file__)) or Path("shared/data")) / MAP
    try:
        return path, load_map(path)
    except MapError as exc:
        raise UserError(str(exc)) from None


def inflated_costmap(grid: OccupancyGrid) -> Costmap:
    """The global costmap of `grid` for the mecanum footprint: static + inflation layers, ROS defaults."""
    costmap = Costmap(CostmapParams(footprint=tuple(map(tuple, DEFAULT_FOOTPRINT)),
                                    layers=(StaticLayerParams(), InflationLayerParams())), grid)
    costmap.update()
    return costmap


def timed(fn, runs: int = 1, clock=time.thread_time):
    """fn()'s result and the fastest of `runs` calls in ms of `clock`: by default this thread's CPU
    time (other load inflates it less than the wall clock); work fn hands to other threads needs
    the wall clock (time.perf_counter) or the process's CPU time (time.process_time)."""
    best, out = np.inf, None
    for _ in range(runs):
        start = clock()
        out = fn()
        best = min(best, clock() - start)
    return out, best * 1e3


def navfn_figures(binary: Path, costs: np.ndarray, pairs: list[tuple], rows: list[dict]) -> dict:
    """ROS navfn (its built driver) on the same costmap and pairs: its medians and our time over its, per pair."""
    times = navfn_plan_times(binary, costs, pairs, RUNS)
    for row, t in zip(rows, times):
        row["navfn"] = {"ok": t.ok, "astar_ms": t.astar_ms, "astar_search_ms": t.astar_search_ms,
                        "dijkstra_ms": t.dijkstra_ms, "dijkstra_search_ms": t.dijkstra_search_ms}
    return {"navfn_pairs_ok": sum(t.ok for t in times),
            "navfn_astar_median_ms": statistics.median(t.astar_ms for t in times),
            "navfn_astar_search_median_ms": statistics.median(t.astar_search_ms for t in times),
            "navfn_dijkstra_median_ms": statistics.median(t.dijkstra_ms for t in times),
            "astar_over_navfn": statistics.median(r["astar"]["ms"] / t.astar_ms for r, t in zip(rows, times)),
            "dijkstra_over_navfn": statistics.median(r["dijkstra"]["ms"] / t.dijkstra_ms for r, t in zip(rows, times))}


@exits_2_on_user_error("bench planner")
def main(args: argparse.Namespace) -> int:
    path, grid = load_bench_map(args.map)
    # a bad folder or a failed build is said before the minutes of planning
    navfn = build_navfn(Path(args.navfn)) if args.navfn else None
    costmap_layers.warm_up()
    warm_up()
    costmap = inflated_costmap(grid)
    params = costmap.params
    inflate_runs = []
    for _ in range(5):
        _, ms = timed(costmap.recompute)
        inflate_runs.append(ms)
    costs, info = costmap.costs, costmap.info
    planners = {"astar": GlobalPlannerParams(use_dijkstra=False), "dijkstra": GlobalPlannerParams(use_dijkstra=True)}
    pairs = pick_pairs(costs, info.resolution, planners["astar"])
    rows = []
    for start, goal in pairs:
        sx, sy = cell_to_world(info, *start)
        gx, gy = cell_to_world(info, *goal)
        row = {"start": [float(sx), float(sy)], "goal": [float(gx), float(gy)]}
        for name, p in planners.items():
            planner = GlobalPlanner(p)
            result, ms = timed(lambda: planner.plan(costs, info, (sx, sy, 0.0), (gx, gy, 0.0)), RUNS)
            if not result.ok:
                print(f"omninav bench planner: {name} found no path {start} -> {goal}: {result.message}",
                      file=sys.stderr)
                return 1
            row[name] = {"ms": ms, "length_m": result.length, "expanded": result.expanded, "cost": result.cost}
        rows.append(row)

    reference = []
    if args.reference_pairs > 0:
        matrix, build_ms = timed(lambda: graph(costs, planners["astar"]))
        for (start, goal), row in list(zip(pairs, rows))[:args.reference_pairs]:
            s = start[0] * info.width + start[1]
            dist, ms = timed(lambda: csgraph.dijkstra(matrix, indices=s))
            cost = float(dist[goal[0] * info.width + goal[1]])
            reference.append({"ms": ms, "cost": cost, "diff": abs(cost - row["astar"]["cost"]) / cost})

    def med(name, key):
        return statistics.median(r[name][key] for r in rows)

    figures = {
        "map": str(path), "cells": [info.width, info.height], "pairs": len(rows), "runs_per_pair": RUNS,
        "median_ms": med("astar", "ms"), "worst_ms": max(r["astar"]["ms"] for r in rows),
        "inflate_ms": statistics.median(inflate_runs),
        "path_length_m": med("astar", "length_m"), "longest_path_m": max(r["astar"]["length_m"] for r in rows),
        "expanded": med("astar", "expanded"), "most_expanded": max(r["astar"]["expanded"] for r in rows),
        "dijkstra_median_ms": med("dijkstra", "ms"), "dijkstra_worst_ms": max(r["dijkstra"]["ms"] for r in rows),
        "dijkstra_expanded": med("dijkstra", "expanded"),
        "astar_vs_dijkstra_cost_diff": max(abs(r["astar"]["cost"] - r["dijkstra"]["cost"]) / r["dijkstra"]["cost"]
                                           for r in rows),
        "reference": "scipy.sparse.csgraph.dijkstra, single source, same graph",
        "reference_pairs": len(reference),
        "reference_median_ms": statistics.median(r["ms"] for r in reference) if reference else None,
        "reference_cost_diff": max(r["diff"] for r in reference) if reference else None,
        "bars": {"median_ms": BAR_PLAN_MS, "inflate_ms": BAR_INFLATE_MS},
        **(navfn_figures(navfn, costs, pairs, rows) if navfn else {}),
        "per_pair": rows,
    }
    if args.json:
        print(json.dumps(figures))
        return 0
    print(f"map {path}: {info.width} x {info.height} cells at {info.resolution} m; footprint 0.832 x 0.636 m, "
          f"padding {params.footprint_padding} m, inflation_radius {params.layers[1].inflation_radius} m")
    print(f"inflate the whole map (a full recompute: static + inflation layers): {figures['inflate_ms']:.1f} ms "
          f"(median of {len(inflate_runs)}; bar {BAR_INFLATE_MS:.0f} ms)")
    print(f"{len(rows)} pairs at least {MIN_APART_M:.0f} m apart (seed {SEED}); fastest of {RUNS} runs per pair:")
    print(f"  A*       median {figures['median_ms']:.1f} ms, worst {figures['worst_ms']:.1f} ms (bar: median "
          f"{BAR_PLAN_MS:.0f} ms); path median {figures['path_length_m']:.1f} m, longest "
          f"{figures['longest_path_m']:.1f} m; expanded median {figures['expanded']:.0f}, most "
          f"{figures['most_expanded']}")
    print(f"  Dijkstra median {figures['dijkstra_median_ms']:.1f} ms, worst {figures['dijkstra_worst_ms']:.1f} ms; "
          f"expanded median {figures['dijkstra_expanded']:.0f}; path costs equal to A*'s within "
          f"{figures['astar_vs_dijkstra_cost_diff']:.1e} (relative)")
    if reference:
        print(f"  reference {figures['reference']} (graph built in {build_ms:.0f} ms): median "
              f"{figures['reference_median_ms']:.0f} ms over {len(reference)} pairs; costs equal to A*'s "
              f"within {figures['reference_cost_diff']:.1e} (relative)")
    if navfn:
        print(f"  ROS navfn (setCostmap + search + path, as navfn_ros plans; {figures['navfn_pairs_ok']}/{len(rows)} "
              f"found): A* median {figures['navfn_astar_median_ms']:.1f} ms (search alone "
              f"{figures['navfn_astar_search_median_ms']:.1f}), Dijkstra {figures['navfn_dijkstra_median_ms']:.1f} ms; "
              f"ours over navfn's, median per pair: A* {figures['astar_over_navfn']:.2f}, "
              f"Dijkstra {figures['dijkstra_over_navfn']:.2f}")
    return 0
