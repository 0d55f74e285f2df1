"""Large messages on the bus: a 4000 x 4000 map (16 MB) arrives and answers `get`; a message over
what the transport carries is refused at the publisher, naming the key and the size."""
import logging
import threading

import numpy as np
import zenoh

from omninav.schemas import decode
from omninav.schemas.codec import encode
from omninav.schemas.messages import Chatter, Header, MapMetaData, OccupancyGrid
from omninav.services.runtime.live import LiveRunner
from omninav.services.runtime.node import Node
from omninav.services.runtime.zenoh_config import open_client

from conftest import wait_until


class MapHolder(Node):
    """Keeps the latest map, answers `get` on it, and says on echo how many cells it got."""
    service = "map_holder"

    def setup(self) -> None:
        self.grid: OccupancyGrid | None = None
        self.echo = self.publisher("echo")
        self.subscribe("map", self.on_map, synced=False)
        self.queryable("map", lambda _params: self.grid)

    def on_map(self, grid: OccupancyGrid) -> None:
        self.grid = grid
        self.echo.publish(Chatter(header=self.header(), text=f"cells {grid.data.size}"))


class Shouter(MapHolder):
    """Answers each map with an echo far longer than the limit the test sets."""
    service = "shouter"

    def on_map(self, grid: OccupancyGrid) -> None:
        self.grid = grid
        self.echo.publish(Chatter(header=self.header(), text="x" * 5000))


def running(node: Node, endpoint: str) -> tuple[LiveRunner, threading.Thread]:
    runner = LiveRunner(node, endpoint)
    thread = threading.Thread(target=runner.run, daemon=True)
    thread.start()
    return runner, thread


def big_map(cells: int) -> OccupancyGrid:
    data = np.zeros((cells, cells), np.int8)
    data[::7, ::5] = 100
    return OccupancyGrid(header=Header(stamp_ns=1), info=MapMetaData(resolution=0.05, width=cells, height=cells),
                         data=data)


def test_a_map_of_4000_by_4000_cells_reaches_the_subscriber_and_answers_get(router_endpoint):
    node = MapHolder()
    runner, thread = running(node, router_endpoint)
    grid = big_map(4000)
    payload = encode(grid)
    assert len(payload) > 16_000_000
    echoes = []
    with open_client(router_endpoint) as session:
        session.declare_subscriber(node.keys.robot("echo"), lambda s: echoes.append(decode(s.payload.to_bytes())))
        wait_until(lambda: any(r.ok is not None for r in session.liveliness().get(node.keys.alive(node.name), timeout=1)),
                   30, what="the map holder")
        session.put(node.keys.robot("map"), payload, congestion_control=zenoh.CongestionControl.BLOCK)
        wait_until(lambda: echoes, 30, what="the map holder saying it got the map")
        assert echoes[0].text == "cells 16000000"
        replies = list(session.get(node.keys.robot("map"), timeout=30))
        assert replies and replies[0].ok is not None
        served = decode(replies[0].ok.payload.to_bytes(), OccupancyGrid)
        assert np.array_equal(served.data, grid.data)
    runner.stop()
    thread.join(10)


def test_a_message_over_the_transport_limit_is_refused_at_the_publisher_naming_key_and_size(router_endpoint, caplog):
    node = Shouter()
    runner, thread = running(node, router_endpoint)
    runner.max_payload = 2000           # stands for the real limit: the echo is over it, diagnostics are not
    with open_client(router_endpoint) as session, caplog.at_level(logging.ERROR):
        wait_until(lambda: any(r.ok is not None for r in session.liveliness().get(node.keys.alive(node.name), timeout=1)),
                   30, what="the map holder")
        session.put(node.keys.robot("map"), encode(big_map(10)))
        wait_until(lambda: node.counters[f"handler_errors/{node.keys.robot('map')}"] == 1, 30,
                   what="the refused echo counted")
    runner.stop()
    thread.join(10)
    assert node.grid is not None and node.grid.data.size == 100     # the input itself was handled
    refused = [r for r in caplog.records if r.exc_info and "PayloadTooLarge" in repr(r.exc_info[1].__class__)]
    assert refused and "omninav/r1/echo: a Chatter of" in str(refused[0].exc_info[1])
    assert "bytes is over the 2,000 bytes" in str(refused[0].exc_info[1])
