"""`omninav bench explore`: frontier exploration of generated worlds, scored against their truth.

    omninav bench explore [--kind maze] [--count N] [--seed S] [--workers W] [--max-time S] [--particles P] [--json]

World i is the scenario generator's `kind` drawn from numpy.random.default_rng(seed + i), written
to a temporary world file and explored as `omninav map --world` explores (build_map: sim, chassis,
lidar, slam, the navigation stack and the explore service in one process, in lockstep, seeded with
seed + i), so every row is the same on every run and machine. Rows run in `workers` processes.

Per world: the share of the truly free space reachable from the start that the map knows
(explored_share), the agreement with the true occupancy where both know the cells, collisions,
sim time, frontiers driven to, whether the explorer finished (no reachable frontier left) and the
frontiers it dropped, with their reasons. Overall: the share of worlds mapped to at least
MAPPED_ENOUGH, and the collisions. The aim: ≥ 95 % of the worlds mapped to ≥ 95 %, no collision.
"""
from __future__ import annotations

import argparse
import json
import multiprocessing
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import yaml

from ..experiments.progress import progress
from ..experiments.mapping import build_map, compare_with_truth, explored_share, slam_params_for
from ..sim.world import load_world
from ..experiments.scenarios import KINDS

MAPPED_ENOUGH = 0.95        # a world counts as explored when this share of its reachable free space is mapped
AIM = 0.95                  # … and the aim is this share of the worlds


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--kind", choices=sorted(KINDS), default="maze", help="generated world kind (default maze)")
    parser.add_argument("--count", type=int, default=10, help="worlds to explore (default 10)")
    parser.add_argument("--seed", type=int, default=0, help="world i is generated and explored with seed + i")
    parser.add_argument("--workers", type=int, default=2, help="worlds explored at once, one process each (default 2)")
    parser.add_argument("--max-time", type=float, default=900.0, metavar="S",
                        help="sim s per world before it counts as unfinished (default 900)")
    parser.add_argument("--particles", type=int, default=None,
                        help="slam particles (default: omninav map's, 30)")


def explore_one(kind: str, seed: int, max_sim_s: float, particles: int | None) -> dict:
    """Generate world `seed` of `kind`, explore it, and score the map."""
    began = time.monotonic()
    doc = KINDS[kind](np.random.default_rng(seed))
    with tempfile.TemporaryDirectory(prefix="omninav-explore-") as folder:
        path = Path(folder) / f"{kind}-{seed}.yaml"
        path.write_text(yaml.safe_dump(doc, sort_keys=False))
        world = load_world(path)
        overrides = {} if particles is None else {"particles": particles}
        result = build_map(str(path), seed=seed, params=slam_params_for(world, overrides, seed), max_sim_s=max_sim_s)
    row = {"seed": seed, "bounds": [float(v) for v in world.bounds], "finished": result.finished,
           "sim_s": round(result.sim_s, 1), "goals": result.goals, "collisions": result.collisions,
           "dropped": list(result.dropped), "explored": None, "agreement": None}
    if result.grid is not None:
        row.update(explored=round(explored_share(result.grid, world), 4),
                   agreement=round(compare_with_truth(result.grid, world).agreement, 4))
    row["wall_s"] = round(time.monotonic() - began, 1)
    return row


def _explore_row(job: tuple) -> dict:
    return explore_one(*job)


def row_text(row: dict) -> str:
    explored = "-" if row["explored"] is None else f"{100 * row['explored']:6.2f} %"
    agreement = "-" if row["agreement"] is None else f"{100 * row['agreement']:6.2f} %"
    width, height = row["bounds"]
    return (f"seed {row['seed']:4d}  {width:4.1f} × {height:3.1f} m  mapped {explored}  agreement {agreement}  "
            f"collisions {row['collisions']}  {row['sim_s']:6.1f} sim s  {row['goals']:3d} frontiers  "
            f"{'finished' if row['finished'] else 'UNFINISHED'}  dropped {len(row['dropped'])}  ({row['wall_s']:.0f} wall s)"
            + "".join(f"\n      dropped {text}" for text in row["dropped"]))


def summary(rows: list[dict]) -> dict:
    explored = [r["explored"] or 0.0 for r in rows]
    return {"worlds": len(rows),
            "mapped_enough_share": sum(e >= MAPPED_ENOUGH for e in explored) / len(rows),
            "explored_min": min(explored), "explored_median": statistics.median(explored),
            "collisions": sum(r["collisions"] for r in rows),
            "worlds_with_collisions": sum(r["collisions"] > 0 for r in rows),
            "unfinished": sum(not r["finished"] for r in rows),
            "sim_s_median": statistics.median(r["sim_s"] for r in rows),
            "goals_median": statistics.median(r["goals"] for r in rows)}


def main(args: argparse.Namespace) -> int:
    if args.count < 1 or args.workers < 1 or not args.max_time > 0:
        raise SystemExit("--count and --workers must be at least 1, --max-time positive")
    jobs = [(args.kind, args.seed + i, args.max_time, args.particles) for i in range(args.count)]
    rows = []
    with multiprocessing.get_context("spawn").Pool(min(args.workers, len(jobs))) as pool, \
            progress(len(jobs), "worlds", args.json) as bar:
        for row in pool.imap(_explore_row, jobs):
            rows.append(row)
            with bar.printing():
                print(row_text(row), file=sys.stderr if args.json else sys.stdout, flush=True)
            bar.advance()
    figures = summary(rows)
    if args.json:
        print(json.dumps({"kind": args.kind, "seed": args.seed, "max_sim_s": args.max_time,
                          "particles": args.particles, **figures, "rows": rows}))
    else:
        print(f"{figures['worlds']} {args.kind} worlds: {100 * figures['mapped_enough_share']:.0f} % mapped to "
              f"≥ {100 * MAPPED_ENOUGH:.0f} % of their reachable free space (min {100 * figures['explored_min']:.2f} %, "
              f"median {100 * figures['explored_median']:.2f} %), {figures['collisions']} collisions in "
              f"{figures['worlds_with_collisions']} worlds, {figures['unfinished']} unfinished, "
              f"median {figures['sim_s_median']:.0f} sim s and {figures['goals_median']:.0f} frontiers", flush=True)
    return 0 if figures["mapped_enough_share"] >= AIM and figures["collisions"] == 0 else 1
