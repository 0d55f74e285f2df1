"""BARN Challenge worlds (Gazebo SDF `.world` files) read as omninav worlds.

The obstacles are the models named `unit_cylinder_*`, placed where the world's `<state>` block
puts them (the pose Gazebo restores), each a cylinder of radius 0.075 m; the ground plane and
the light are scenery. The robot is the challenge's Clearpath Jackal at the challenge's start,
and the goal is the challenge's, 10 m ahead (the BARN rules in ../shared/data/barn/README.md).
The bounds hold the obstacles, the start and the goal with BOUNDS_MARGIN to spare: the cylinders
wall the cluttered area in on its left, right and rear, so the only way out towards the goal is
through the clutter, as in the challenge; the outer walls omninav adds along the bounds stay
beyond that margin.
"""
from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np

CYLINDER_PREFIX = "unit_cylinder"
CYLINDER_RADIUS = 0.075                      # m, BARN's unit cylinders
START = (-2.25, 3.0, math.pi / 2)            # x, y, yaw: the challenge's start, facing +y
GOAL = (-2.25, 13.0, math.pi / 2)            # 10 m ahead of the start
JACKAL_FOOTPRINT = ((-0.21, -0.165), (0.21, -0.165), (0.21, 0.165), (-0.21, 0.165))   # m, counter-clockwise
JACKAL_DRIVE = "diff"
BOUNDS_MARGIN = 2.0                          # m of open ground around obstacles, start and goal


class BarnWorldError(ValueError):
    """A BARN world file that cannot be read; the message names the file and what is wrong."""


def cylinder_centres(path: str | Path) -> np.ndarray:
    """The (N, 2) x, y of the world's unit cylinders, from its `<state>` block."""
    path = Path(path)
    try:
        root = ET.parse(path).getroot()
    except FileNotFoundError:
        raise BarnWorldError(f"{path}: no such file") from None
    except (ET.ParseError, OSError) as exc:
        raise BarnWorldError(f"{path}: not a readable SDF world file ({exc})") from None
    state = root.find("world/state")
    if state is None:
        raise BarnWorldError(f"{path}: no <world><state> block (is it a BARN world file?)")
    centres = []
    for model in state.findall("model"):
        name = model.get("name", "")
        if not name.startswith(CYLINDER_PREFIX):
            continue
        pose = model.findtext("pose")
        try:
            values = [float(v) for v in (pose or "").split()]
        except ValueError:
            values = []
        if len(values) != 6 or not all(math.isfinite(v) for v in values):
            raise BarnWorldError(f"{path}: state model {name!r}: expected a pose of 6 numbers, got {pose!r}")
        centres.append(values[:2])
    if not centres:
        raise BarnWorldError(f"{path}: the <state> block holds no {CYLINDER_PREFIX}_* models")
    return np.array(centres)


def barn_world_doc(path: str | Path) -> dict:
    """The world file mapping (docs/worlds.md) of a BARN world: its cylinders, the Jackal at the
    challenge's start and the challenge's goal."""
    centres = cylinder_centres(path)
    points = np.vstack([centres, [START[:2], GOAL[:2]]])
    low = points.min(axis=0) - CYLINDER_RADIUS - BOUNDS_MARGIN
    high = points.max(axis=0) + CYLINDER_RADIUS + BOUNDS_MARGIN
    return {"name": Path(path).stem,
            "origin": [float(v) for v in low], "bounds": [float(v) for v in high - low],
            "circles": [{"center": [float(x), float(y)], "radius": CYLINDER_RADIUS} for x, y in centres],
            "robot": {"start": list(START), "drive": JACKAL_DRIVE, "footprint": [list(p) for p in JACKAL_FOOTPRINT]},
            "goals": [list(GOAL)]}
