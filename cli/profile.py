"""Robot profiles: a robot described as data (compose/profiles/NAME.yaml), not code.

A profile names the robot's drive, its footprint and costmap footprint_padding, the costmaps'
common parameter file and optionally the local costmap's (in compose/params), and parameters merged over the services' compose
parameters (`params: {service: {name: value}}`). `compose_for` (cli/navigate.py) applies it: the
footprint goes to the simulator, the local planner and the collision monitor, the padding to the
local planner; the costmaps read theirs from the common file. `body` (sim/body.py's BodyParams)
is the robot as it is — its real outline, mass, wheels and how the floor carries it — and goes
to the simulator alone: the navigation stack works with the footprint and parameters it is given.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import yaml

from ..parameters.declare import ParamError
from ..parameters.from_mapping import load_params
from ..services.chassis.kinematics import DRIVES
from ..services.runtime.errors import UserError
from ..sim.body import BodyParams

REPO = Path(__file__).resolve().parents[1]
PROFILES_DIR = REPO / "compose" / "profiles"
PARAMS_DIR = REPO / "compose" / "params"


class ProfileError(UserError):
    """A profile that cannot be used; the message names the file and the key."""


@dataclass(frozen=True)
class Profile:
    name: str
    drive: str
    footprint: tuple[tuple[float, float], ...]
    footprint_padding: float
    costmap_common_params: Path
    costmap_local_params: Path | None = None       # None: the sample local costmap (compose/params)
    params: dict = field(default_factory=dict)     # service name -> parameters
    body: dict = field(default_factory=dict)       # BodyParams by name: the simulator's robot


def profile_path(name_or_path: str) -> Path:
    """A shipped profile by name ('jackal') or any profile file by path."""
    candidate = Path(name_or_path)
    return candidate if candidate.suffix in (".yaml", ".yml") else PROFILES_DIR / f"{name_or_path}.yaml"


def shipped_profiles() -> list[str]:
    return sorted(p.stem for p in PROFILES_DIR.glob("*.yaml"))


def load_profile(name_or_path: str) -> Profile:
    path = profile_path(name_or_path)
    if not path.is_file():
        raise ProfileError(f"profile {name_or_path!r}: no such file {path} (shipped: {', '.join(shipped_profiles())})")
    try:
        doc = yaml.safe_load(path.read_text())
    except yaml.YAMLError as exc:
        raise ProfileError(f"{path}: not valid YAML ({str(exc).splitlines()[0]})") from None
    if not isinstance(doc, dict):
        raise ProfileError(f"{path}: expected a mapping of profile keys, got {doc!r}")

    def fail(key: str, message: str):
        raise ProfileError(f"{path}: {key}: {message}")

    drive = doc.get("drive")
    if drive not in DRIVES:
        fail("drive", f"expected one of {' | '.join(DRIVES)}, got {drive!r}")
    footprint = doc.get("footprint")
    if not (isinstance(footprint, list) and len(footprint) >= 3 and all(
            isinstance(p, list) and len(p) == 2 and all(_finite(v) for v in p) for p in footprint)):
        fail("footprint", f"expected at least 3 points [x, y] (m), got {footprint!r}")
    padding = doc.get("footprint_padding", 0.0)
    if not (_finite(padding) and padding >= 0):
        fail("footprint_padding", f"expected a number ≥ 0 (m), got {padding!r}")
    files = {}
    for key, required in (("costmap_common_params", True), ("costmap_local_params", False)):
        name = doc.get(key)
        if name is None and not required:
            files[key] = None
        elif not isinstance(name, str) or not (PARAMS_DIR / name).is_file():
            fail(key, f"expected a parameter file in {PARAMS_DIR}, got {name!r}")
        else:
            files[key] = PARAMS_DIR / name
    params = doc.get("params") or {}
    if not isinstance(params, dict) or not all(isinstance(v, dict) for v in params.values()):
        fail("params", f"expected a mapping of service names to parameter mappings, got {params!r}")
    body = doc.get("body") or {}
    if not isinstance(body, dict):
        fail("body", f"expected a mapping of BodyParams names to values (sim/body.py), got {body!r}")
    try:
        load_params(BodyParams, body, "BodyParams")
    except ParamError as exc:
        fail("body", str(exc))
    return Profile(name=path.stem, drive=drive, footprint=tuple((float(x), float(y)) for x, y in footprint),
                   footprint_padding=float(padding), params=params, body=body, **files)


def _finite(value) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)
