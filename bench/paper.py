"""`omninav bench paper`: the mecanum paper's indoor-navigation experiment, repeated.

The paper drove its robot 20 times from the origin to (4.0 m, −3.0 m) facing +y (yaw 90°) with
AMCL on a map and reached the goal within 10 cm and ±5°. sim/worlds/paper.yaml lays out that
room (start at the origin, the goal in its `goals`); each run is the mission `omninav navigate
--world paper` drives, with its own seed (the simulator's noise and the filter's), and the final
error is measured against the ground truth where the robot came to rest. The aim here: every run
within 5 cm and 2°.

How the runs are driven: by default in lockstep in one process each (`navigate --in-process`,
experiments/lockstep_mission.py), --workers at once — the same figures every time, as fast as the
CPUs compute; `--processes`: every service its own process, in lockstep (`navigate --lockstep`),
one run after another; `--rate R`: as processes at R × real time, as a robot would run them.
In-process runs go through `omninav navigate` inside the worker process itself (the same
arguments, its JSON summary captured, its messages in the run's log): a worker imports the stack
and loads its JIT caches once, not once per run.
"""
from __future__ import annotations

import argparse
import contextlib
import io
import json
import statistics
import subprocess
import sys
import time
import traceback
from pathlib import Path

from ..experiments.mission_score import false_success_runs
from ..experiments.workers import run_in_workers

REPO = Path(__file__).resolve().parents[1]
RUN_TIMEOUT_S = 1800     # wall s for one navigate run (start-up included)

AIM_XY_M, AIM_YAW_DEG = 0.05, 2.0
PAPER_XY_M, PAPER_YAW_DEG = 0.10, 5.0


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--runs", type=int, default=20, help="runs, seeds 0..RUNS-1 (default 20)")
    parser.add_argument("--localization", choices=("amcl", "slam", "truth"), default="amcl",
                        help="as navigate's (default amcl, as the paper)")
    how = parser.add_mutually_exclusive_group()
    how.add_argument("--processes", action="store_true",
                     help="every service its own process, in lockstep (navigate --lockstep), one run at a time")
    how.add_argument("--rate", type=float, help="every service its own process at this many sim seconds per wall "
                                               "second (navigate --rate), one run at a time")
    parser.add_argument("--workers", type=int, default=2,
                        help="in-process runs at once, one process each (default 2)")
    parser.add_argument("-o", "--out", help="folder for the runs (default out/paper-<date>-<time>)")


def run_navigate(argv: list[str], log: Path) -> dict:
    """One navigate run as its own process: its JSON summary, or a failed row saying why (the log
    keeps the details)."""
    with open(log, "wb") as sink:
        try:
            done = subprocess.run([sys.executable, "-m", "omninav.cli.main", *argv], cwd=REPO, stdout=subprocess.PIPE,
                                  stderr=sink, timeout=RUN_TIMEOUT_S)
        except subprocess.TimeoutExpired:
            return {"success": False, "error": f"no result within {RUN_TIMEOUT_S} wall s; see {log}"}
    return summary_row(done.returncode, done.stdout.decode(errors="replace"), log)


def run_navigate_here(argv: list[str], log: Path) -> dict:
    """As run_navigate, in this process: `omninav navigate` with argv, its output captured."""
    from ..cli.main import main as omninav

    printed = io.StringIO()
    with open(log, "w") as sink, contextlib.redirect_stdout(printed), contextlib.redirect_stderr(sink):
        try:
            status = omninav(argv)
        except Exception:       # one broken run is a failed row, not the end of the experiment
            traceback.print_exc(file=sink)
            return {"success": False, "error": f"navigate raised; see {log}"}
    return summary_row(status, printed.getvalue(), log)


def summary_row(status: int, printed: str, log: Path) -> dict:
    """navigate's JSON summary (its last line; exit 0 or 1), or a failed row naming the exit."""
    lines = printed.strip().splitlines()
    if status in (0, 1) and lines:
        return json.loads(lines[-1])
    return {"success": False, "error": f"navigate exit {status}; see {log}"}


def navigate_arguments(seed: int, args: argparse.Namespace, out: Path) -> list[str]:
    pace = ["--rate", str(args.rate)] if args.rate is not None else \
        ["--lockstep"] if args.processes else ["--in-process"]
    return ["navigate", "--world", "paper", "--localization", args.localization, "--seed", str(seed), *pace,
            "-o", str(out / f"seed{seed}"), "--json"]


def in_process(args: argparse.Namespace) -> bool:
    return args.rate is None and not args.processes


def one_run(job: tuple[int, argparse.Namespace, str]) -> dict:
    seed, args, out = job
    argv, log = navigate_arguments(seed, args, Path(out)), Path(out) / f"seed{seed}.log"
    row = (run_navigate_here if in_process(args) else run_navigate)(argv, log)
    row["seed"] = seed
    row["within_aim"] = bool(row["success"] and row["final_xy_error_m"] <= AIM_XY_M
                             and row["final_yaw_error_deg"] <= AIM_YAW_DEG)
    return row


def main(args: argparse.Namespace) -> int:
    if args.runs < 1 or args.workers < 1 or (args.rate is not None and not args.rate > 0):
        raise SystemExit("omninav bench paper: --runs and --workers must be ≥ 1 and --rate positive")
    out = Path(args.out or REPO / "out" / time.strftime("paper-%Y%m%d-%H%M%S")).resolve()
    out.mkdir(parents=True, exist_ok=True)
    began = time.monotonic()
    jobs = [(seed, args, str(out)) for seed in range(args.runs)]
    rows = run_in_workers(one_run, jobs, args.workers if in_process(args) else 1,
                          on_result=None if args.json else print_row, unit="runs", quiet=args.json)
    result = summarize(rows, args.localization)
    result["wall_s"] = round(time.monotonic() - began, 1)
    if args.json:
        print(json.dumps(result))
    else:
        print(f"{result['reached']}/{len(rows)} reached; within {AIM_XY_M * 100:.0f} cm and {AIM_YAW_DEG:g}°: "
              f"{result['within_aim']}; within the paper's {PAPER_XY_M * 100:.0f} cm and {PAPER_YAW_DEG:g}°: "
              f"{result['within_paper']}; collisions {result['collisions']}; false successes "
              f"{len(result['false_successes'])} {result['false_successes'] or ''}; {result['wall_s']:g} wall s")
        if result["xy_error_m"]:
            xy, yaw = result["xy_error_m"], result["yaw_error_deg"]
            print(f"final error: mean {xy['mean'] * 100:.2f} cm (max {xy['max'] * 100:.2f}), "
                  f"mean {yaw['mean']:.2f}° (max {yaw['max']:.2f}); runs in {out}")
    return 0 if result["within_aim"] == len(rows) and result["collisions"] == 0 else 1


def print_row(row: dict) -> None:
    detail = (f"error {row['final_xy_error_m'] * 100:.1f} cm {row['final_yaw_error_deg']:.2f} deg, "
              f"{row['time_s']:.1f} s, {row['path_length_m']:.2f} m, collisions {row['collisions']}"
              if row.get("final_xy_error_m") is not None else row.get("error", ""))
    print(f"seed {row['seed']:2d}: {'reached' if row['success'] else 'FAILED'} {detail}", flush=True)


def summarize(rows: list[dict], localization: str) -> dict:
    scored = [r for r in rows if r.get("final_xy_error_m") is not None]
    xy = [r["final_xy_error_m"] for r in scored]
    yaw = [r["final_yaw_error_deg"] for r in scored]
    return {
        "runs": len(rows), "reached": sum(bool(r["success"]) for r in rows),
        "false_successes": false_success_runs(rows, "seed"),
        "within_aim": sum(r["within_aim"] for r in rows),
        "within_paper": sum(bool(r["success"]) and r["final_xy_error_m"] <= PAPER_XY_M
                            and r["final_yaw_error_deg"] <= PAPER_YAW_DEG for r in scored),
        "xy_error_m": {"mean": statistics.fmean(xy), "max": max(xy)} if xy else None,
        "yaw_error_deg": {"mean": statistics.fmean(yaw), "max": max(yaw)} if yaw else None,
        "collisions": sum(r.get("collisions") or 0 for r in rows),
        "localization": localization, "rows": rows,
    }
