"""The map_server service: serves one map file on the map key, as ROS map_server does.

The map is loaded when the node is built, so a missing or broken file stops `omninav run` at once
(exit 2) with a message naming the file. It is published on the map key at the first opportunity,
and — because a message published once is missed by anyone who subscribes later — every `get` on
the map key is answered with the current map: the query is what gives latched-topic semantics.

When it is published. With publish_period_s = 0 (the default) the map is published once, at
start, stamped 0 (no clock seen yet; services never read the wall clock). A node without inputs gets
no call from its driver except tick(), so in that mode the node presents itself as a source with an
infinite period: LiveRunner ticks it once, as soon as its publishers are declared, and never again;
an in-process run ticks it at every step, and only the first tick publishes.
With publish_period_s > 0 the map is published at the first clock seen and then every
publish_period_s of sim time, stamped with the clock — driven by inputs only, so
`replay --into map_server --compare` reproduces it.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

from ...schemas.messages import OccupancyGrid
from ..runtime.node import Node
from .mapio import MapError, load_map
from ...parameters.declare import Parameters, param


@dataclass(frozen=True)
class MapServerParams(Parameters):
    yaml_filename: str = param("", nonempty=True)  # the map's YAML file (relative to the working directory)
    frame_id: str = "map"
    publish_period_s: float = param(0.0, ge=0)     # 0: publish once, at start; > 0: at the first clock, then every so much sim time


class MapServerNode(Node):
    service = "map_server"
    Params = MapServerParams

    def setup(self) -> None:
        try:
            self.map: OccupancyGrid = load_map(self.params.yaml_filename)
        except MapError as exc:
            raise MapError(f"yaml_filename: {exc}") from None
        self.map.header.frame_id = self.params.frame_id
        self.map_pub = self.publisher("map")
        self.queryable("map", lambda _params: self.map)
        self._published_at_start = False
        if self.params.publish_period_s > 0:
            self.every(self.params.publish_period_s, self.publish_map)

    def pace_s(self) -> float | None:
        # a single tick, at start, when there is no clock to publish on (see the module docstring)
        return math.inf if self.params.publish_period_s == 0 else None

    def tick(self) -> None:
        if not self._published_at_start:
            self._published_at_start = True
            self.publish_map()

    def publish_map(self) -> None:
        # the same object is answered on `get`, so a query sees the stamp and seq last published
        self.map.header.stamp_ns = self.now_ns
        self.map_pub.publish(self.map)
