"""ROS navfn beside omninav's planner, in the same run (`omninav bench planner --navfn DIR`).

navfn is not part of omninav and none of its code is in this repository: DIR is a copy of navfn's
sources the user has (the `navfn` package of ros-planning/navigation, or any folder holding
navfn.cpp and navfn/navfn.h). The bench compiles them with its own driver (navfn/driver.cpp; a
stand-in for roscpp's logging header in navfn/ros/) into out/navfn-<hash>/ once, hands the driver
the very costmap and pairs omninav planned, and reads back each pair's fastest times (CPU time of
the planning thread, as the bench measures its own).
"""
from __future__ import annotations

import hashlib
import shutil
import subprocess
import tempfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..services.runtime.errors import UserError

HERE = Path(__file__).resolve().parent / "navfn"
REPO = Path(__file__).resolve().parents[1]
COMPILE_TIMEOUT_S, RUN_TIMEOUT_S = 300, 1800


@dataclass(frozen=True)
class NavfnTimes:
    ok: bool
    astar_ms: float            # setCostmap + calcNavFnAstar, as navfn_ros's makePlan does each plan
    astar_search_ms: float     # calcNavFnAstar alone (set-up, wavefront, path)
    dijkstra_ms: float
    dijkstra_search_ms: float


def navfn_sources(folder: Path) -> tuple[Path, Path]:
    """navfn.cpp and the folder to include navfn/navfn.h from, found under `folder`."""
    if not folder.is_dir():
        raise UserError(f"--navfn {folder}: no such folder (give navfn's sources: navfn.cpp and navfn/navfn.h)")
    source = next(iter(sorted(folder.rglob("navfn.cpp"))), None)
    header = next(iter(sorted(folder.rglob("navfn/navfn.h"))), None)
    if source is None or header is None:
        missing = " and ".join(name for name, found in (("navfn.cpp", source), ("navfn/navfn.h", header)) if not found)
        raise UserError(f"--navfn {folder}: {missing} not found under it")
    return source, header.parent.parent


def build(folder: Path, out: Path | None = None) -> Path:
    """The driver compiled against navfn's sources in `folder` (reused while the sources are the same)."""
    source, include = navfn_sources(folder)
    compiler = shutil.which("c++") or shutil.which("g++")
    if compiler is None:
        raise UserError("--navfn: no C++ compiler (c++ or g++) on PATH to build the navfn reference")
    driver, shim = HERE / "driver.cpp", HERE / "ros" / "console.h"
    digest = hashlib.sha256(b"".join(p.read_bytes() for p in (source, include / "navfn" / "navfn.h", driver, shim)))
    digest = digest.hexdigest()
    binary = (out or REPO / "out") / f"navfn-{digest[:12]}" / "navfn_driver"
    if binary.exists():
        return binary
    binary.parent.mkdir(parents=True, exist_ok=True)
    command = [compiler, "-O2", "-std=c++14", "-I", str(HERE), "-I", str(include), str(driver), str(source),
               "-o", str(binary)]
    done = subprocess.run(command, capture_output=True, text=True, timeout=COMPILE_TIMEOUT_S)
    if done.returncode != 0:
        raise UserError(f"--navfn {folder}: the navfn reference did not compile:\n{done.stderr.strip()[-2000:]}")
    return binary


def plan_times(binary: Path, costs: np.ndarray, pairs: list[tuple], runs: int) -> list[NavfnTimes]:
    """navfn's times on `costs` (costmap_2d values, row = y) for each (start, goal) pair of (row, column) cells."""
    with tempfile.TemporaryDirectory(prefix="omninav-navfn-") as folder:
        height, width = costs.shape
        with open(Path(folder) / "costs.bin", "wb") as f:
            f.write(np.array([width, height], np.int32).tobytes())
            f.write(np.ascontiguousarray(costs, np.uint8).tobytes())
        (Path(folder) / "pairs.txt").write_text("".join(f"{s[0]} {s[1]} {g[0]} {g[1]}\n" for s, g in pairs))
        done = subprocess.run([str(binary), folder, str(runs)], capture_output=True, text=True, timeout=RUN_TIMEOUT_S)
    if done.returncode != 0:
        raise UserError(f"the navfn reference failed: {done.stderr.strip()[-2000:]}")
    rows = [line.split() for line in done.stdout.splitlines() if line.strip()]
    if len(rows) != len(pairs):
        raise UserError(f"the navfn reference answered {len(rows)} of {len(pairs)} pairs")
    return [NavfnTimes(row[0] == "1", *(float(v) for v in row[1:5])) for row in rows]
