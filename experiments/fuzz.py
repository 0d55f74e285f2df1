"""Fuzzing a service's inputs in-process: every input key gets random bytes, valid messages of the
wrong type, and valid messages with one field set to an edge value (0, negative, NaN, ±inf, huge,
empty, a mismatched shape). Each payload goes the way a live one goes (decode, then Node.process);
a death is an exception that escapes either. Used by the tests (a small budget) and by
`omninav bench fuzz` (a large one).
"""
from __future__ import annotations

import copy
import math
from collections import Counter
from dataclasses import dataclass, field
from typing import Iterator

import msgspec
import numpy as np

from ..schemas import MessageError, all_types, decode, encode
from ..schemas.messages import LaserScan, MapMetaData
from ..services.runtime.node import Node

EDGE_NUMBERS = (0, -1, 2**63 - 1, -(2**63), 1e300, -1e300, math.nan, math.inf, -math.inf, 0.5)
EDGE_TEXTS = ("", "x" * 10_000, "\x00")


def example(cls: type):
    """A sound message of the type: its defaults, with what the defaults leave inconsistent filled in."""
    msg = cls()
    if isinstance(msg, LaserScan):
        msg.angle_min, msg.angle_increment, msg.angle_max = -1.0, 0.5, 1.0
        msg.range_max, msg.ranges = 10.0, np.full(5, 2.0, np.float32)
    if isinstance(getattr(msg, "info", None), MapMetaData):
        msg.info.width = msg.info.height = 4
        msg.data = np.zeros((4, 4), msg.data.dtype)
    if getattr(msg, "drive", None) is not None:
        msg.drive, msg.velocities = "diff", np.zeros(2)
        if hasattr(msg, "positions"):
            msg.positions = np.zeros(2)
    return msg


def _edge_values(value) -> list:
    if isinstance(value, dict) and set(value) == {"dtype", "shape", "data"}:     # an array field
        dtype, shape = np.dtype(value["dtype"]), value["shape"]
        big = np.full(max(1, math.prod(shape)), 1e300 if dtype.kind == "f" else np.iinfo(dtype).max, dtype)
        return [{**value, "shape": [], "data": b""}, {**value, "shape": [*shape, 1], "data": bytes(value["data"])},
                {**value, "data": bytes(value["data"])[:-1]}, {**value, "dtype": "<i8"},
                {**value, "shape": [len(big)] + [1] * (len(shape) - 1), "data": big.tobytes()},
                {**value, "shape": [1] + [1] * (len(shape) - 1), "data": np.full(1, np.nan, dtype).tobytes()}]
    if isinstance(value, str):
        return [*EDGE_TEXTS, 0]
    if isinstance(value, (bool, dict)):
        return [None, "x", -1]
    return [*EDGE_NUMBERS, "1", None]


def _leaves(wire: dict, path: tuple = ()) -> Iterator[tuple[tuple, object]]:
    for name, value in wire.items():
        if name.startswith("_"):
            continue
        if isinstance(value, dict) and set(value) != {"dtype", "shape", "data"} and name != "values":
            yield from _leaves(value, (*path, name))
        else:
            yield (*path, name), value


def mutated_payloads(msg) -> Iterator[bytes]:
    """The message with one field at a time set to each of its edge values."""
    wire = msgspec.msgpack.decode(encode(msg))      # plain maps and bytes, safe to copy
    for path, value in _leaves(wire):
        for edge in _edge_values(value):
            changed = copy.deepcopy(wire)
            node = changed
            for name in path[:-1]:
                node = node[name]
            node[path[-1]] = edge
            yield msgspec.msgpack.encode(changed)


@dataclass
class FuzzResult:
    sent: int = 0
    rejected: int = 0            # refused by the codec: counted as malformed/<key>
    handled: int = 0             # decoded and handed to the node
    deaths: list[str] = field(default_factory=list)       # exceptions that escaped, with where
    handler_errors: Counter = field(default_factory=Counter)    # the node's own guard counts, per key


def fuzz_node(node: Node, rng: np.random.Generator, random_per_key: int = 20) -> FuzzResult:
    """Every input of the node: random bytes, every other message type, one-field mutations."""
    result = FuzzResult()
    types = sorted(all_types().items())
    for index, inp in enumerate(node.inputs):
        payloads = [rng.bytes(int(rng.integers(0, 256))) for _ in range(random_per_key)]
        payloads += [encode(example(cls)) for _, cls in types]
        payloads += list(mutated_payloads(example(inp.msg_type)))
        for payload in payloads:
            result.sent += 1
            try:
                msg = decode(payload, inp.msg_type, key=inp.key)
            except MessageError as exc:
                node.reject(inp.key, exc)
                result.rejected += 1
                continue
            except Exception as exc:        # the codec must refuse with MessageError only
                result.deaths.append(f"decode {inp.key}: {type(exc).__name__}: {exc}")
                continue
            result.handled += 1
            try:
                node.process(index, msg)
            except Exception as exc:
                result.deaths.append(f"{node.name} {inp.key}: {type(exc).__name__}: {exc}")
    result.handler_errors = Counter({k.partition("/")[2]: v for k, v in node.counters.items()
                                     if k.startswith("handler_errors/")})
    return result


# ---------------------------------------------------------------- omninav bench fuzz

def add_arguments(parser) -> None:
    parser.add_argument("--random-per-key", type=int, default=2000,
                        help="random payloads per input key, besides the typed mutations (default 2000)")
    parser.add_argument("--seed", type=int, default=0)


def main(args) -> int:
    import json
    import time
    from pathlib import Path

    from ..services.runtime.service_registry import SERVICES
    from ..services.runtime.run import build_node

    if args.random_per_key < 0:
        raise SystemExit("--random-per-key must be >= 0")
    room_map = Path(__file__).resolve().parents[1] / "compose" / "maps" / "room.yaml"
    overrides = {"map_server": {"yaml_filename": str(room_map)}}
    rows, rng = {}, np.random.default_rng(args.seed)
    for service in sorted(set(SERVICES) - {"recorder"}):
        node = build_node(service, overrides=overrides.get(service))
        began = time.perf_counter()
        result = fuzz_node(node, rng, args.random_per_key)
        seconds = time.perf_counter() - began
        rows[service] = {"sent": result.sent, "rejected": result.rejected, "handled": result.handled,
                         "deaths": len(result.deaths), "handler_errors": sum(result.handler_errors.values()),
                         "msgs_per_s": result.sent / seconds if seconds > 0 else 0.0}
        for death in result.deaths[:3]:
            print(f"DEATH {death}", flush=True)
    total = {name: sum(r[name] for r in rows.values()) for name in ("sent", "rejected", "handled", "deaths",
                                                                    "handler_errors")}
    if args.json:
        print(json.dumps({"services": rows, **total}))
    else:
        for service, r in rows.items():
            print(f"{service:18s} sent {r['sent']:7d}  refused by the codec {r['rejected']:7d}  handled "
                  f"{r['handled']:6d}  handler errors {r['handler_errors']:4d}  deaths {r['deaths']}  "
                  f"{r['msgs_per_s']:9.0f} msgs/s")
        print(f"all: {total['sent']} sent, {total['deaths']} deaths, {total['handler_errors']} handler errors")
    return 1 if total["deaths"] else 0
