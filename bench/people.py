"""`omninav bench people [--json]`: the pedestrian model against Weidmann, and what a call costs.

Fundamental diagram: at each density (people/m², default 0.5 … 3.0) the mean walking speed in a
16 m × 2.5 m corridor without ends (sim/people/fundamental.py), averaged over seeds, for Weidmann's
walkers (free speeds 1.34 ± 0.26 m/s, the population his relation describes) and for the people a
flow brings (the same, truncated to [1.0, 1.5] m/s), beside Weidmann's v(ρ).

Cost: `accelerations` for N people (10, 25, 50) walking in the warehouse world (its walls, shelves,
columns and the robot at its start), and `Crowd.update` for the same people, median CPU time per
call over repeats, beside the reference measured in the same run: one 2 ms pymunk Space.step of the
same N people as 70 kg discs among the same static geometry — the substep the forces are computed for.
"""
from __future__ import annotations

import argparse
import json
import statistics
import time

import numpy as np
import pymunk

from ..geometry.polygons import transform_points
from ..sim.people.fundamental import corridor_speed, weidmann_speed
from ..sim.people.plans import SPEED_RANGE, Crowd, PeopleSpec, Walker
from ..sim.people.social_force import Obstacles, PeopleParams, RobotShape, accelerations
from ..sim.world import World, load_world, world_path

DENSITIES = (0.5, 1.0, 1.5, 2.0, 2.5, 3.0)
CROWDS = (10, 25, 50)
SUBSTEP = 0.002         # s, the simulator's substep the reference steps
CALLS = 300             # per timed repeat


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--densities", type=float, nargs="+", default=list(DENSITIES), help="people per m²")
    parser.add_argument("--seeds", type=int, default=3, help="corridor runs per density and population (default 3)")
    parser.add_argument("--repeats", type=int, default=7, help="timed repeats per crowd size (default 7)")


def diagram(densities, seeds: int) -> list[dict]:
    rows = []
    for density in densities:
        weidmanns = statistics.mean(corridor_speed(density, seed=s, warm_s=20.0, measure_s=30.0) for s in range(seeds))
        flows = statistics.mean(corridor_speed(density, seed=s, speeds=SPEED_RANGE, warm_s=20.0, measure_s=30.0)
                                for s in range(seeds))
        rows.append({"density": density, "weidmann": round(weidmann_speed(density), 3),
                     "model_weidmann_walkers": round(weidmanns, 3), "model_flow_walkers": round(flows, 3)})
    return rows


def walkers_in(world: World, n: int, rng: np.random.Generator) -> PeopleSpec:
    """n people, each looping between two free points of the world, none overlapping another."""
    xmin, ymin, xmax, ymax = world.extent
    chosen: list[np.ndarray] = []
    while len(chosen) < 2 * n:
        p = rng.uniform((xmin, ymin), (xmax, ymax))
        if world.distance(p) > 0.4 and all(np.hypot(*(p - q)) > 0.6 for q in chosen):
            chosen.append(p)
    return PeopleSpec(walkers=tuple(Walker(path=np.array([chosen[2 * k], chosen[2 * k + 1]]), waits=np.zeros(2),
                                           loop=True) for k in range(n)), max_people=n)


def reference_space(world: World, crowd: Crowd, params: PeopleParams) -> pymunk.Space:
    space = pymunk.Space()
    for quad in world.solids:
        space.add(pymunk.Poly(space.static_body, [tuple(p) for p in quad]))
    for x, y, r in world.circles:
        space.add(pymunk.Circle(space.static_body, float(r), (float(x), float(y))))
    for (x, y), r in zip(crowd.state.position, crowd.state.radius):
        body = pymunk.Body(params.mass, pymunk.moment_for_circle(params.mass, 0.0, float(r)))
        body.position = (float(x), float(y))
        space.add(body, pymunk.Circle(body, float(r)))
    return space


def per_call_us(call, repeats: int) -> float:
    times = []
    for _ in range(repeats):
        start = time.process_time()
        for _ in range(CALLS):
            call()
        times.append((time.process_time() - start) / CALLS)
    return statistics.median(times) * 1e6


def costs(repeats: int) -> list[dict]:
    world = load_world(world_path("warehouse"))
    params = PeopleParams()
    obstacles = Obstacles(world.segments, world.circles)
    robot = RobotShape(transform_points(world.robot.footprint, world.robot.start)[0], np.array([0.3, 0.0]))
    rows = []
    for n in CROWDS:
        crowd = Crowd(walkers_in(world, n, np.random.default_rng(n)), params)
        for k in range(100):                     # under way: spawned, walking, some near each other
            crowd.step(k * 0.01, 0.01, obstacles, robot)
        space = reference_space(world, crowd, params)
        accelerations(crowd.state, obstacles, robot, params)
        rows.append({"people": n, "segments": len(world.segments), "circles": len(world.circles),
                     "accelerations_us": round(per_call_us(lambda: accelerations(crowd.state, obstacles, robot,
                                                                                  params), repeats), 1),
                     "update_us": round(per_call_us(lambda: crowd.update(1.0, robot), repeats), 1),
                     "reference_pymunk_substep_us": round(per_call_us(lambda: space.step(SUBSTEP), repeats), 1)})
    return rows


def report(figures: dict) -> str:
    lines = ["mean walking speed (m/s) in a corridor without ends, Weidmann (1993) v0 1.34, γ 1.913, ρmax 5.4",
             f"{'ρ (1/m²)':>9} {'Weidmann':>9} {'model':>7} {'diff':>6} {'flow walkers':>13}"]
    for row in figures["diagram"]:
        diff = row["model_weidmann_walkers"] - row["weidmann"]
        lines.append(f"{row['density']:9.2f} {row['weidmann']:9.3f} {row['model_weidmann_walkers']:7.3f} "
                     f"{diff:+6.3f} {row['model_flow_walkers']:13.3f}")
    lines.append("")
    lines.append("cost per call (µs, median CPU time), warehouse world; reference: one 2 ms pymunk substep of "
                 "the same people")
    lines.append(f"{'people':>6} {'accelerations':>14} {'Crowd.update':>13} {'pymunk substep':>15}")
    for row in figures["cost"]:
        lines.append(f"{row['people']:6d} {row['accelerations_us']:14.1f} {row['update_us']:13.1f} "
                     f"{row['reference_pymunk_substep_us']:15.1f}")
    return "\n".join(lines)


def main(args: argparse.Namespace) -> int:
    figures = {"diagram": diagram(args.densities, args.seeds), "cost": costs(args.repeats)}
    print(json.dumps(figures) if args.json else report(figures), flush=True)
    return 0
