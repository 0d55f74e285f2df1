"""`omninav bench regress [--save] [--json]`: about thirty lockstep missions across every generated
kind, DynaBARN, BARN, the shipped missions and buildings, and four with TEB — all on tuning seeds — one line each
with what changed since the result stored in the repo (bench/regress.json), so that a change
which fixes one world and breaks another is seen the day it is made. Lockstep missions are
deterministic, so any difference is the code's. `--save` stores this run as the new reference
(commit it with the change that made it). Run it before every resolve.
"""
from __future__ import annotations

import argparse
import json
import subprocess
import time
from dataclasses import asdict
from pathlib import Path

from ..experiments.barn import run_world
from ..experiments.dynabarn_bench import run_seed
from ..experiments.workers import run_in_workers
from ..services.local_planner.control import DEFAULT_CONTROLLER
from ..services.runtime.errors import UserError, exits_2_on_user_error
from ..sim.world import shared_data_dir
from .buildings import drive_building
from .missions import drive_mission
from .scenarios import drive_world

REPO = Path(__file__).resolve().parents[1]
STORED = Path(__file__).with_name("regress.json")
SCENARIO_KINDS = ("crossing", "headon", "overtake", "crowd", "doorway", "hall", "shelves", "clutter")
# (family, name, arguments): tuning seeds only (docs/seeds.md)
CASES = ([("scenario", f"{kind}-{seed}", (kind, seed)) for kind in SCENARIO_KINDS for seed in (0, 1)]
         + [("dynabarn", f"dynabarn-{d}-0", (d, 0)) for d in ("easy", "medium")]
         + [("barn", f"barn-{n}", (n,)) for n in (0, 60, 104)]
         + [("mission", f"mission-{w}-{d}", (w, d)) for w, d in (("office", "mecanum"), ("warehouse", "diff"),
                                                                  ("crossing", "omni3"))]
         + [("building", f"building-{r}-0", (r, 0)) for r in ("mecanum", "omni3", "diff", "jackal")]
         # TEB beside DWA, where it differs most
         + [("scenario", f"{kind}-{seed}-teb", (kind, seed, "teb")) for kind, seed in (("hall", 0), ("shelves", 0),
                                                                                     ("crossing", 1))]
         + [("dynabarn", "dynabarn-medium-1-teb", ("medium", 1, "teb"))])


def run_case(job: tuple[str, str, tuple, str]) -> dict:
    """One case, whatever its family, as {name, success, status, contacts, time_s, path_m}."""
    family, name, arguments, out = job
    began = time.monotonic()
    controller = arguments[2] if family in ("scenario", "dynabarn") and len(arguments) > 2 else DEFAULT_CONTROLLER
    if family == "scenario":
        row = drive_world((*arguments[:2], None, "amcl", 120.0, out, False, controller))
        outcome = (row["success"], row["status"], row["collisions"], row["time_s"], row["path_length_m"])
    elif family == "building":
        row = drive_building((*arguments, 240.0, out, False))
        outcome = (row["success"], row["status"], row["collisions"], row["time_s"], row["path_length_m"])
    elif family == "mission":
        args = argparse.Namespace(localization="amcl", seed=0, timeout=180.0, record=False)
        row = drive_mission((*arguments, args, out))
        outcome = (row["success"], "succeeded" if row["success"] else "failed", row["collisions"], row["time_s"],
                   row["path_length_m"])
    elif family == "dynabarn":
        folder = Path(out) / name
        folder.mkdir(parents=True, exist_ok=True)
        r = run_seed((*arguments[:2], str(folder), controller, "auto"))
        outcome = (r.success, "timeout" if r.timeout else "arrived" if r.time_s is not None else "contact",
                   r.robot_fault_collisions + r.mover_fault_collisions, r.time_s, None)
    else:
        worlds = shared_data_dir(Path(__file__)) / "barn"
        n = arguments[0]
        r = asdict(run_world(worlds / "worlds" / f"world_{n}.world", worlds / "path_files" / f"path_{n}.npy", 0))
        outcome = (r["success"], "timeout" if r["timeout"] else "collision" if r["collision"] else "arrived",
                   int(r["collision"]), r["time_s"], None)
    success, status, contacts, time_s, path_m = outcome
    return {"name": name, "success": bool(success), "status": status, "contacts": int(contacts or 0),
            "time_s": None if time_s is None else round(float(time_s), 2),
            "path_m": None if path_m is None else round(float(path_m), 2), "wall_s": round(time.monotonic() - began, 1)}


def _show(row: dict) -> str:
    time_s = "-" if row["time_s"] is None else f"{row['time_s']:.2f} s"
    path = "" if row["path_m"] is None else f", {row['path_m']:.2f} m"
    return f"{'ok' if row['success'] else 'FAIL'} {row['status']}, {row['contacts']} contacts, {time_s}{path}"


def compare(row: dict, before: dict | None) -> str:
    """What changed in a case since the stored run: 'new', 'same', or the old outcome."""
    if before is None:
        return "new"
    fields = ("success", "status", "contacts", "time_s", "path_m")
    if all(row[f] == before.get(f) for f in fields):
        return "same"
    mark = "FIXED" if row["success"] and not before["success"] else "BROKEN" if before["success"] and not row["success"] else "changed"
    return f"{mark} (was {_show(before)})"


def stored() -> dict:
    return json.loads(STORED.read_text()) if STORED.is_file() else {"rows": []}


def _commit() -> str:
    """HEAD, marked -dirty when the tree has changes not committed (as a run before its commit has)."""
    try:
        return subprocess.run(["git", "describe", "--always", "--dirty"], cwd=REPO, capture_output=True, text=True,
                              check=True).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return "unknown"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--workers", type=int, default=2, help="missions driven at once (default 2)")
    parser.add_argument("--save", action="store_true", help=f"store this run as the reference ({STORED.name}, in the repo)")
    parser.add_argument("--only", nargs="+", metavar="NAME", help="run only these cases (by name)")
    parser.add_argument("-o", "--out", help="folder for the runs (default out/regress-<date>-<time>)")


@exits_2_on_user_error("bench regress")
def main(args: argparse.Namespace) -> int:
    unknown = sorted(set(args.only or ()) - {name for _, name, _ in CASES})
    if unknown:
        raise UserError(f"--only: no such case {', '.join(unknown)} (the cases: {', '.join(name for _, name, _ in CASES)})")
    out = Path(args.out or REPO / "out" / time.strftime("regress-%Y%m%d-%H%M%S")).resolve()
    out.mkdir(parents=True, exist_ok=True)
    data = shared_data_dir(Path(__file__))
    cases = [c for c in CASES if not args.only or c[1] in args.only]
    skipped = [name for family, name, _ in cases if family == "barn" and not (data and (data / "barn").is_dir())]
    jobs = [(*case, str(out)) for case in cases if case[1] not in skipped]
    before = {row["name"]: row for row in stored()["rows"]}
    began = time.monotonic()

    def say(row: dict) -> None:
        if not args.json:
            print(f"{row['name']:26} {_show(row):46} {compare(row, before.get(row['name']))}", flush=True)

    rows = run_in_workers(run_case, jobs, args.workers, say, unit="missions", quiet=args.json)
    changes = {row["name"]: compare(row, before.get(row["name"])) for row in rows}
    figures = {"commit": _commit(), "date": time.strftime("%Y-%m-%d"), "stored_commit": stored().get("commit"),
               "cases": len(rows), "successes": sum(r["success"] for r in rows), "skipped": skipped,
               "broken": sorted(n for n, c in changes.items() if c.startswith("BROKEN")),
               "fixed": sorted(n for n, c in changes.items() if c.startswith("FIXED")),
               "changed": sorted(n for n, c in changes.items() if c not in ("same", "new")),
               "wall_s": round(time.monotonic() - began, 1), "rows": rows}
    if args.json:
        print(json.dumps(figures))
    else:
        print(f"{figures['successes']}/{len(rows)} succeeded in {figures['wall_s']:.0f} wall s; against "
              f"{STORED.name} ({figures['stored_commit'] or 'none stored'}): {len(figures['broken'])} broken, "
              f"{len(figures['fixed'])} fixed, {len(figures['changed'])} changed"
              + (f"; skipped (no BARN data): {', '.join(skipped)}" if skipped else ""))
    if args.save:
        STORED.write_text(json.dumps({k: v for k, v in figures.items() if k != "stored_commit"}, indent=1) + "\n")
    return 1 if figures["broken"] else 0
