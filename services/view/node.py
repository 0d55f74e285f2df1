"""The view service: the running stack in the Foxglove app, through foxglove-sdk's WebSocket server.

It subscribes to the keys of convert.ROUTES (none of them synced: a viewer never holds anything up),
converts each message and logs it to the server; grids only when they change (convert.Throttle).
The server listens on 127.0.0.1 only. Goals are off unless `allow_goals` (`omninav view --allow-goals`):
then the door (gate.py) stands on the port, the SDK's server behind it on another loopback port, and
a client may publish on one channel, GOAL_TOPIC, whose JSON poses become Goals on the navigator's
goal key, only if the door admitted its connection (the run's token in its URL, its Origin absent or
allowed). Any other client channel is refused, so nothing a viewer sends reaches the motion keys.
"""
from __future__ import annotations

import logging
import secrets
import threading
from dataclasses import dataclass
from urllib.parse import quote

import foxglove
from foxglove.websocket import Capability, ChannelView, Client, ClientChannel, ServerListener

from ..runtime.node import Node
from .bus import follow_the_bus
from .channels import ChannelSet
from .convert import Converter, ROUTES, Route, RouteTable, ViewParams, goal_from_client
from .gate import TOKEN_PARAM, Gate, admit_message, normal_origin
from ...parameters.declare import Rule, param

LOOPBACK = "127.0.0.1"
GOAL_TOPIC = "/goal_pose"       # the topic the Foxglove app's "Publish pose" tool uses by default
GOAL_ENCODING = "json"
ADMIT_PARAM = "omninav/admit"   # the parameter the door sets, with an in-process secret, for an admitted client


@dataclass(frozen=True)
class ViewNodeParams(ViewParams):
    port: int = param(8765, ge=0, le=65535)  # 0: any free port (tests)
    grid_period_s: float = param(1.0, ge=0)  # sim time between two publications of one grid, at least
    allow_goals: bool = False                 # forward goals from clients the door admits (gate.py); else none
    allow_origins: tuple[str, ...] = ()       # browser origins admitted besides the Foxglove app's and localhost's

    rules = (Rule("allow_origins", lambda p: all(_is_origin(o) for o in p.allow_origins), "origins http(s)://host[:port]"),)


def _is_origin(text: str) -> bool:
    try:
        normal_origin(text)
    except ValueError:
        return False
    return True


class GoalForwarder(ServerListener):
    """The server's listener: accepts client publishing on GOAL_TOPIC only and turns each message
    into a Goal for `publish`; resends a channel's latest message to a viewer that subscribes."""

    def __init__(self, node: "ViewNode", admit_secret: str | None):
        self.node = node
        self.log = logging.getLogger(f"omninav.{node.name}")
        self._admit_secret = admit_secret                       # None: goals are off
        self._admitted: set[int] = set()                        # client ids the door admitted
        self._told: set[int] = set()                            # clients told their goals are refused
        self._goal_channels: set[tuple[int, int]] = set()      # (client id, client channel id)
        self._count = 0
        self._lock = threading.Lock()

    def on_subscribe(self, client: Client, channel: ChannelView) -> None:
        self.node.channels.resend_latest(channel.topic)

    def on_set_parameters(self, client: Client, parameters: list, request_id: str | None = None) -> list:
        """The door's admission (the only parameter there is); nothing is stored or sent back."""
        for parameter in parameters:
            value = parameter.get_value()
            if (parameter.name == ADMIT_PARAM and self._admit_secret is not None and isinstance(value, str)
                    and secrets.compare_digest(value.encode(), self._admit_secret.encode())):
                self._admitted.add(client.id)
        return []

    def on_client_advertise(self, client: Client, channel: ClientChannel) -> None:
        if channel.topic == GOAL_TOPIC and channel.encoding == GOAL_ENCODING:
            if client.id in self._admitted:
                self._goal_channels.add((client.id, channel.id))
            elif client.id not in self._told:
                self._told.add(client.id)
                self.log.warning("client %d: goals refused, %s", client.id,
                                 "its connection was not admitted (the door said why)" if self._admit_secret
                                 else "goals are off (start `omninav view --allow-goals`)")
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
        self.server = self.gate = None
        self.token: str | None = None
        for route in ROUTES:
            self.subscribe(self.routes.key_expr(route), lambda msg, route=route: self.show(route, msg), synced=False)

    def show(self, route: Route, msg) -> None:
        for topic, message in self.converter.outputs(route, msg):
            self.channels.log(topic, message)

    def start_server(self) -> foxglove.WebSocketServer:
        """The SDK's server on the port, or with allow_goals behind the door on it; prints the URL with
        the run's token for goals (never logged)."""
        p = self.params
        admit_secret = secrets.token_urlsafe(32) if p.allow_goals else None
        self.server = foxglove.start_server(
            name=f"omninav {self.keys.robot_name}", host=LOOPBACK, port=0 if p.allow_goals else p.port,
            context=self.context, capabilities=[Capability.ClientPublish, Capability.Parameters],
            supported_encodings=[GOAL_ENCODING], server_listener=GoalForwarder(self, admit_secret))
        if not p.allow_goals:
            self.log.info("Foxglove WebSocket server on ws://%s:%d (goals off: --allow-goals)", LOOPBACK,
                          self.server.port)
            return self.server
        self.token = secrets.token_urlsafe(24)
        try:
            self.gate = Gate(LOOPBACK, p.port, self.server.port, self.token, p.allow_origins,
                             admit_message(ADMIT_PARAM, admit_secret), self.log)
        except OSError as exc:
            raise RuntimeError(str(exc)) from None
        url = f"ws://{LOOPBACK}:{self.gate.port}/?{TOKEN_PARAM}={self.token}"
        self.log.info("Foxglove WebSocket server on ws://%s:%d, goals from connections with this run's token",
                      LOOPBACK, self.gate.port)
        print(f"view: goals are accepted from a connection to {url}\n"
              f"view: in the Foxglove app: https://app.foxglove.dev/~/view?ds=foxglove-websocket&ds.url="
              f"{quote(url, safe='')}", flush=True)
        return self.server

    def run_live(self, router: str | None, stop_event: threading.Event) -> None:
        """Serve viewers while the bus is followed; the server lives only as long as the live run."""
        try:
            self.start_server()
        except RuntimeError as exc:     # the SDK's FoxgloveError, e.g. the port is taken
            raise SystemExit(f"view: cannot serve on {LOOPBACK}:{self.params.port}: {exc}") from None
        follow_the_bus(self, router, stop_event)

    def close(self) -> None:
        if self.gate is not None:
            self.gate.stop()
            self.gate = None
        if self.server is not None:
            self.server.stop()
            self.server = None
        self.channels.close()
