"""The `people:` key of a world file (docs/people.md): walkers with routes and flows of arriving people.

`people_from_mapping(value, keys)` validates the parsed YAML with the world loader's key reader
(sim/world.py passes its own, so every error names the file and the key path, as the rest of a
world file's errors do) and returns a PeopleSpec.
"""
from __future__ import annotations

import math

import numpy as np

from .plans import RADIUS_RANGE, SPEED_RANGE, Area, Flow, PeopleSpec, Walker

MAX_GROUP = 4
WALKER_KEYS = ("path", "waits", "loop", "group", "speed", "radius", "distracted", "start_s")
FLOW_KEYS = ("source", "goal", "via", "rate_per_min", "arrivals", "start_s", "stop_s", "groups", "distracted",
             "speed", "radius")
ARRIVALS = ("poisson", "regular")


def people_from_mapping(value, keys, where: str = "people") -> PeopleSpec:
    """The PeopleSpec of a world file's `people:` mapping; `keys` is the loader's key reader (sim/world.py),
    whose fail() raises WorldError naming the file and `where`.key."""
    doc = keys.mapping(value, where, optional=("seed", "max_people", "walkers", "flows"))
    seed = _integer(keys, doc.get("seed", 0), f"{where}.seed", 0)
    walkers = tuple(_walker(keys, w, f"{where}.walkers[{i}]") for i, w in enumerate(keys.items(doc.get("walkers"),
                                                                                                 f"{where}.walkers")))
    flows = tuple(_flow(keys, f, f"{where}.flows[{i}]") for i, f in enumerate(keys.items(doc.get("flows"),
                                                                                        f"{where}.flows")))
    max_people = None
    if doc.get("max_people") is not None:
        max_people = _integer(keys, doc["max_people"], f"{where}.max_people", 1)
        largest = max([w.group for w in walkers] + [len(f.groups) for f in flows], default=1)
        if max_people < largest:
            keys.fail(f"{where}.max_people", f"{max_people} cannot hold a group of {largest}")
    return PeopleSpec(seed=seed, walkers=walkers, flows=flows, max_people=max_people)


def _integer(keys, value, where: str, minimum: int, maximum: int | None = None) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or value < minimum or (maximum is not None and
                                                                                    value > maximum):
        limits = f"{minimum}..{maximum}" if maximum is not None else f"≥ {minimum}"
        keys.fail(where, f"expected a whole number {limits}, got {value!r}")
    return value


def _table(keys, value, where: str) -> dict:
    """A mapping with keys of the caller's choosing (waypoint indices, group sizes)."""
    if not isinstance(value, dict):
        keys.fail(where, f"expected a mapping, got {value!r}")
    return value


def _flag(keys, value, where: str) -> bool:
    if not isinstance(value, bool):
        keys.fail(where, f"expected true or false, got {value!r}")
    return value


def _range(keys, value, where: str, default: tuple[float, float]) -> tuple[float, float]:
    """A number, or [low, high] to draw from; both positive."""
    if value is None:
        return default
    if isinstance(value, list):
        low, high = keys.numbers(value, where, 2, "a positive number or [low, high] with 0 < low ≤ high",
                                 positive=True)
        if low > high:
            keys.fail(where, f"expected [low, high] with low ≤ high, got {value!r}")
        return float(low), float(high)
    number = keys.number(value, where, positive=True)
    return number, number


def _area(keys, value, where: str) -> Area:
    doc = keys.mapping(value, where, required=("center",), optional=("size",))
    center = keys.numbers(doc["center"], f"{where}.center", 2, "a point [x, y]")
    size = keys.numbers(doc.get("size", [0.0, 0.0]), f"{where}.size", 2, "[w, h] (two numbers ≥ 0)")
    if (size < 0).any():
        keys.fail(f"{where}.size", f"expected [w, h] (two numbers ≥ 0), got {doc['size']!r}")
    return Area((float(center[0]), float(center[1])), (float(size[0]), float(size[1])))


def _walker(keys, value, where: str) -> Walker:
    doc = keys.mapping(value, where, required=("path",), optional=WALKER_KEYS)
    path = keys.points(doc["path"], f"{where}.path", 1)
    waits = np.zeros(len(path))
    for index, seconds in _table(keys, doc.get("waits", {}), f"{where}.waits").items():
        index = _integer(keys, index, f"{where}.waits", 0, len(path) - 1)
        waits[index] = keys.number(seconds, f"{where}.waits.{index}", nonnegative=True)
    return Walker(path=path, waits=waits, loop=_flag(keys, doc.get("loop", False), f"{where}.loop"),
                  group=_integer(keys, doc.get("group", 1), f"{where}.group", 1, MAX_GROUP),
                  speed=_range(keys, doc.get("speed"), f"{where}.speed", SPEED_RANGE),
                  radius=_range(keys, doc.get("radius"), f"{where}.radius", RADIUS_RANGE),
                  distracted=_flag(keys, doc.get("distracted", False), f"{where}.distracted"),
                  start_s=keys.number(doc.get("start_s", 0.0), f"{where}.start_s", nonnegative=True))


def _flow(keys, value, where: str) -> Flow:
    doc = keys.mapping(value, where, required=("source", "goal", "rate_per_min"), optional=FLOW_KEYS)
    arrivals = doc.get("arrivals", "poisson")
    if arrivals not in ARRIVALS:
        keys.fail(f"{where}.arrivals", f"expected one of {' | '.join(ARRIVALS)}, got {arrivals!r}")
    start_s = keys.number(doc.get("start_s", 0.0), f"{where}.start_s", nonnegative=True)
    stop_s = math.inf
    if doc.get("stop_s") is not None:
        stop_s = keys.number(doc["stop_s"], f"{where}.stop_s")
        if stop_s <= start_s:
            keys.fail(f"{where}.stop_s", f"expected a time after start_s ({start_s}), got {stop_s!r}")
    weights = [0.0] * MAX_GROUP
    for size, weight in _table(keys, doc.get("groups", {1: 1.0}), f"{where}.groups").items():
        size = _integer(keys, size, f"{where}.groups", 1, MAX_GROUP)
        weights[size - 1] = keys.number(weight, f"{where}.groups.{size}", nonnegative=True)
    if sum(weights) <= 0:
        keys.fail(f"{where}.groups", "expected at least one group size with a positive weight")
    while weights[-1] == 0:
        weights.pop()
    distracted = keys.number(doc.get("distracted", 0.0), f"{where}.distracted", nonnegative=True)
    if distracted > 1:
        keys.fail(f"{where}.distracted", f"expected a share in [0, 1], got {distracted!r}")
    return Flow(source=_area(keys, doc["source"], f"{where}.source"), goal=_area(keys, doc["goal"], f"{where}.goal"),
                rate_per_min=keys.number(doc["rate_per_min"], f"{where}.rate_per_min", positive=True),
                via=keys.points(doc.get("via"), f"{where}.via", 0).reshape(-1, 2), regular=arrivals == "regular",
                start_s=start_s, stop_s=stop_s, groups=tuple(weights), distracted=distracted,
                speed=_range(keys, doc.get("speed"), f"{where}.speed", SPEED_RANGE),
                radius=_range(keys, doc.get("radius"), f"{where}.radius", RADIUS_RANGE))
