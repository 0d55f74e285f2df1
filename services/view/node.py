"""The view service: the running stack in the Foxglove app, through foxglove-sdk's WebSocket server.

It subscribes to the keys of convert.ROUTES (none of them synced: a viewer never holds anything up),
converts each message and logs it to the server; grids only when they change (convert.Throttle).
The server listens on 127.0.0.1 only. Clients may publish on one channel, GOAL_TOPIC, whose JSON
poses become Goals on the navigator's goal key; any other client channel is refused, so nothing a
viewer sends reaches the motion keys.
"""
from __future__ import annotations

import logging
import threading
from dataclasses import dataclass

import foxglove
from foxglove.websocket import Capability, ChannelView, Client, ClientChannel, ServerListener

from ..runtime.live import LiveRunner
from ..runtime.node import Node
from ..runtime.zenoh_config import open_client
from .channels import ChannelSet
from .convert import Converter, ROUTES, Route, RouteTable, ViewParams, goal_from_client
from ...parameters.declare import param

LOOPBACK = "127.0.0.1"
GOAL_TOPIC = "/goal_pose"       # the topic the Foxglove app's "Publish pose" tool uses by default
GOAL_ENCODING = "json"


@dataclass(frozen=True)
class ViewNodeParams(ViewParams):
    port: int = param(8765, ge=0, le=65535)  # 0: any free port (tests)
    grid_period_s: float = param(1.0, ge=0)  # sim time between two publications of one grid, at least


class GoalForwarder(ServerListener):
    """The server's listener: accepts client publishing on GOAL_TOPIC only and turns each message
    into a Goal for `publish`; resends a channel's latest message to a viewer that subscribes."""

    def __init__(self, node: "ViewNode"):
        self.node = node
        self.log = logging.getLogger(f"omninav.{node.name}")
        self._goal_channels: set[tuple[int, int]] = set()      # (client id, client channel id)
        self._count = 0
        self._lock = threading.Lock()

    def on_subscribe(self, client: Client, channel: ChannelView) -> None:
        self.node.channels.resend_latest(channel.topic)

    def on_client_advertise(self, client: Client, channel: ClientChannel) -> None:
        if channel.topic == GOAL_TOPIC and channel.encoding == GOAL_ENCODING:
            self._goal_channels.add((client.id, channel.id))
        else:
            self.log.warning("client %d advertised %s (%s); only %s in %s is accepted (goals), ignoring it",
                             client.id, channel.topic, channel.encoding, GOAL_TOPIC, GOAL_ENCODING)

    def on_client_unadvertise(self, client: Client, client_channel_id: int) -> None:
        self._goal_channels.discard((client.id, client_channel_id))

    def on_message_data(self, client: Client, client_channel_id: int, data: bytes) -> None:
        if (client.id, client_channel_id) not in self._goal_channels:
            return
        with self._lock:    # the server may call from several threads; goal ids and seqs stay unique
            self._count += 1
            try:
                goal = goal_from_client(data, self.node.now_ns, f"foxglove-{self._count}")
            except ValueError as exc:
                self.log.warning("goal from client %d refused: %s", client.id, exc)
                return
            self.node.goal_pub.publish(goal)
        self.log.info("goal %s from the Foxglove app: %.2f %.2f %.2f", goal.goal_id, goal.pose.x, goal.pose.y,
                      goal.pose.theta)


class ViewNode(Node):
    service = "view"
    Params = ViewNodeParams

    def setup(self) -> None:
        self.converter = Converter(self.params, self.params.grid_period_s)
        self.routes = RouteTable(self.keys)
        self.context = foxglove.Context()
        self.channels = ChannelSet(self.context)
        self.goal_pub = self.publisher("goal")
        self.server = None
        for route in ROUTES:
            self.subscribe(self.routes.key_expr(route), lambda msg, route=route: self.show(route, msg), synced=False)

    def show(self, route: Route, msg) -> None:
        for topic, message in self.converter.outputs(route, msg):
            self.channels.log(topic, message)

    def start_server(self) -> foxglove.WebSocketServer:
        self.server = foxglove.start_server(
            name=f"omninav {self.keys.robot_name}", host=LOOPBACK, port=self.params.port, context=self.context,
            capabilities=[Capability.ClientPublish], supported_encodings=[GOAL_ENCODING],
            server_listener=GoalForwarder(self))
        self.log.info("Foxglove WebSocket server on ws://%s:%d", LOOPBACK, self.server.port)
        return self.server

    def run_live(self, router: str | None, stop_event: threading.Event) -> None:
        """Serve viewers while the bus is followed; the server lives only as long as the live run."""
        runner = LiveRunner(self, router)
        runner.stop_event = stop_event
        try:
            self.start_server()
        except RuntimeError as exc:     # the SDK's FoxgloveError, e.g. the port is taken
            raise SystemExit(f"view: cannot serve on {LOOPBACK}:{self.params.port}: {exc}") from None
        try:
            # as a tool: the run's read-only identity where $OMNINAV_CREDENTIALS names none (joining.py)
            session = open_client(router, stopped=stop_event.is_set, as_tool=True, warn=self.log.warning)
            if session is not None:     # else stopped while waiting for the router
                with session:
                    runner.run(session)
        finally:
            self.close()

    def close(self) -> None:
        if self.server is not None:
            self.server.stop()
            self.server = None
        self.channels.close()
