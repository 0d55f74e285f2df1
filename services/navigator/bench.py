"""`omninav bench missions`: navigation missions over the shipped worlds for each drive.

Each row is one `omninav navigate` run (every service its own process), with fixed goals per world
chosen in free space away from the start: through doors in the corridor and the office, along the
aisles of the warehouse where the forklift and two people move, across the real Willow Garage map,
and through the crossing hall where two people walk across the planned path.
A row reports the navigate summary (success, goals reached, collisions, final errors against the
ground truth, sim time, the true path length and the first global plans' length, min clearance);
the table adds the driven path over the planned one. The aim: every mission succeeds, no collision.
"""
from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time
from pathlib import Path

from ..chassis.kinematics import DRIVES

REPO = Path(__file__).resolve().parents[2]
# world -> goals (x m, y m, yaw degrees), visited in order from the world's start
MISSIONS: dict[str, tuple[tuple[float, float, float], ...]] = {
    "room": ((8.3, 3.5, 90.0), (3.0, 4.8, 180.0)),
    "corridor": ((10.0, 6.4, 90.0), (18.5, 4.0, 0.0)),
    "office": ((8.0, 8.3, 90.0), (11.5, 2.5, -90.0)),
    "warehouse": ((13.0, 4.25, 0.0), (18.5, 9.0, 90.0)),
    "willow": ((19.1, 28.6, 90.0),),
    "crossing": ((9.0, 3.0, 0.0),),     # two movers cross the straight way (the mecanum paper's dynamic test)
}
ROW_TIMEOUT_S = 1800     # wall s for one navigate run (start-up included)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--worlds", nargs="+", choices=sorted(MISSIONS), default=list(MISSIONS),
                        help="worlds to run (default: all)")
    parser.add_argument("--drives", nargs="+", choices=DRIVES, default=list(DRIVES), help="drives (default: all)")
    parser.add_argument("--localization", choices=("amcl", "slam", "truth"), default="amcl",
                        help="as navigate's (default amcl)")
    parser.add_argument("--timeout", type=float, default=180.0, metavar="S", help="sim s per goal (default 180)")
    parser.add_argument("--rate", type=float, default=1.0, help="sim seconds per wall second (default 1)")
    parser.add_argument("-o", "--out", help="folder for the runs (default out/missions-<date>-<time>)")


def navigate_command(world: str, drive: str, args: argparse.Namespace, out: Path, seed: int = 0) -> list[str]:
    goals = [str(v) for goal in MISSIONS[world] for v in ("--goal", *goal)]
    return [sys.executable, "-m", "omninav.cli.main", "navigate", "--world", world, "--drive", drive, *goals,
            "--localization", args.localization, "--timeout", str(args.timeout), "--rate", str(args.rate),
            "--seed", str(seed), "-o", str(out), "--json"]


def run_navigate(cmd: list[str], log: Path) -> dict:
    """One navigate run: its JSON summary, or a failed row saying why (the log keeps the details)."""
    with open(log, "wb") as sink:
        try:
            done = subprocess.run(cmd, cwd=REPO, stdout=subprocess.PIPE, stderr=sink, timeout=ROW_TIMEOUT_S)
        except subprocess.TimeoutExpired:
            return {"success": False, "error": f"no result within {ROW_TIMEOUT_S} wall s; see {log}"}
    lines = done.stdout.decode(errors="replace").strip().splitlines()
    if done.returncode in (0, 1) and lines:
        return json.loads(lines[-1])
    return {"success": False, "error": f"navigate exit {done.returncode}; see {log}"}


def _fmt(value, spec: str) -> str:
    return "-" if value is None else format(value, spec)


def table(rows: list[dict]) -> list[str]:
    lines = [f"{'world':10} {'drive':8} {'ok':3} {'goals':6} {'coll':4} {'xy err m':>8} {'yaw err°':>8} "
             f"{'time s':>7} {'path m':>7} {'plan m':>7} {'path/plan':>9} {'clear m':>7}"]
    for r in rows:
        ratio = (r["path_length_m"] / r["plan_length_m"]) if r.get("plan_length_m") else None
        lines.append(f"{r['world']:10} {r['drive']:8} {'yes' if r['success'] else 'NO':3} "
                     f"{_fmt(r.get('goals_reached'), 'd')}/{_fmt(r.get('goals_total'), 'd'):4} "
                     f"{_fmt(r.get('collisions'), 'd'):>4} {_fmt(r.get('final_xy_error_m'), '8.3f')} "
                     f"{_fmt(r.get('final_yaw_error_deg'), '8.2f')} {_fmt(r.get('time_s'), '7.1f')} "
                     f"{_fmt(r.get('path_length_m'), '7.2f')} {_fmt(r.get('plan_length_m'), '7.2f')} "
                     f"{_fmt(ratio, '9.2f')} {_fmt(r.get('min_clearance_m'), '7.3f')}"
                     + (f"  {r['error']}" if r.get("error") else ""))
    return lines


def main(args: argparse.Namespace) -> int:
    out = Path(args.out or REPO / "out" / time.strftime("missions-%Y%m%d-%H%M%S")).resolve()
    out.mkdir(parents=True, exist_ok=True)
    rows = []
    if not args.json:
        print(table([])[0], flush=True)
    for world in args.worlds:
        for drive in args.drives:
            folder = out / f"{world}-{drive}"
            began = time.monotonic()
            row = run_navigate(navigate_command(world, drive, args, folder), out / f"{world}-{drive}.log")
            row.update(world=world, drive=drive, wall_s=round(time.monotonic() - began, 1))
            rows.append(row)
            if not args.json:
                print(table([row])[-1], flush=True)
    success_rate = sum(bool(r["success"]) for r in rows) / len(rows)
    collisions = sum(r.get("collisions") or 0 for r in rows)
    if args.json:
        print(json.dumps({"rows": rows, "success_rate": success_rate, "collisions": collisions,
                          "localization": args.localization}))
    else:
        print(f"success rate {success_rate:.0%}, collisions {collisions} ({args.localization} localization; runs in {out})")
    return 0 if success_rate == 1.0 and collisions == 0 else 1
