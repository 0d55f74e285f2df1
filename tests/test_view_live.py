"""`omninav view` as a process on the bus, watched by a scripted client speaking Foxglove's WebSocket
protocol (serverInfo, advertise, subscribe, binary messageData; client advertise + messageData for goals)."""
import asyncio
import base64
import json
import math
import re
import socket
import struct
import threading

import numpy as np
import pytest
import websockets

from omninav.schemas import decode
from omninav.schemas.codec import encode
from omninav.schemas.keys import KeyLayout
from omninav.services.runtime.compose import ComposeError, load_compose
from omninav.services.runtime.zenoh_config import open_client

from conftest import free_port, wait_until
from view_fixtures import S, VIEW_CHANNELS, decode_with_schema, stack_messages

# the SDK's current subprotocol and the one older Foxglove servers speak; the app offers both
SUBPROTOCOLS = ["foxglove.sdk.v1", "foxglove.websocket.v1"]
MESSAGE_DATA = 0x01     # binary opcode, server → client and client → server


class FoxgloveClient:
    """The protocol as the Foxglove app speaks it, enough to watch channels and publish goals."""

    def __init__(self, ws):
        self.ws = ws
        self.channels: dict[int, dict] = {}         # channel id -> advertised channel
        self.decoded: dict[str, list] = {}          # topic -> decoded messages

    async def receive(self, until, timeout_s: float) -> None:
        """Subscribe to every advertised channel and decode what comes, until until(self) holds."""
        async def loop():
            while not until(self):
                frame = await self.ws.recv()
                if isinstance(frame, str):
                    await self._control(json.loads(frame))
                else:
                    self._data(frame)
        await asyncio.wait_for(loop(), timeout_s)

    async def _control(self, message: dict) -> None:
        if message["op"] == "advertise":
            new = [c for c in message["channels"] if c["id"] not in self.channels]
            self.channels.update({c["id"]: c for c in new})
            # subscription id = channel id: one subscription per channel
            await self.ws.send(json.dumps({"op": "subscribe",
                                           "subscriptions": [{"id": c["id"], "channelId": c["id"]} for c in new]}))

    def _data(self, frame: bytes) -> None:
        assert frame[0] == MESSAGE_DATA
        subscription, _log_time = struct.unpack_from("<IQ", frame, 1)
        channel = self.channels[subscription]
        schema = base64.b64decode(channel["schema"]) if channel.get("schemaEncoding") == "protobuf" else b""
        message = decode_with_schema(channel["encoding"], channel["schemaName"], channel.get("schemaEncoding", ""),
                                     schema, frame[1 + 12:])
        self.decoded.setdefault(channel["topic"], []).append(message)

    async def publish(self, channel_id: int, topic: str, payload: dict) -> None:
        await self.ws.send(json.dumps({"op": "advertise", "channels": [
            {"id": channel_id, "topic": topic, "encoding": "json", "schemaName": "geometry_msgs/msg/PoseStamped"}]}))
        await self.ws.send(struct.pack("<BI", MESSAGE_DATA, channel_id) + json.dumps(payload).encode())


def pose_stamped(x: float, y: float, yaw: float) -> dict:
    return {"header": {"stamp": {"sec": 0, "nsec": 0}, "frame_id": "map"},
            "pose": {"position": {"x": x, "y": y, "z": 0.0},
                     "orientation": {"x": 0.0, "y": 0.0, "z": math.sin(yaw / 2), "w": math.cos(yaw / 2)}}}


TREE = {("world", "map"), ("map", "odom"), ("odom", "base_link"), ("base_link", "laser")}


def frames(client: FoxgloveClient) -> set[tuple[str, str]]:
    """(parent, child) of every transform seen on /tf (each message holds one of them)."""
    return {(t.parent_frame_id, t.child_frame_id) for tf in client.decoded.get("/tf", []) for t in tf.transforms}


def from_foxglove(goals: list) -> list:
    """The goals the view forwarded (the test itself also publishes goal g1, as a navigator user would)."""
    return [g for g in goals if g.goal_id.startswith("foxglove-")]


def goal_url(processes, view) -> str:
    """The URL with the run's token that `view --allow-goals` prints once it serves."""
    found = re.search(r"goals are accepted from a connection to (\S+)", wait_until(
        lambda: "?token=" in processes.log_of(view) and processes.log_of(view), 120, what="the view's goal URL"))
    return found.group(1)


async def watch_and_send_goals(url: str, heard: dict) -> FoxgloveClient:
    ws = await websockets.connect(url, subprotocols=SUBPROTOCOLS, max_size=None)
    async with ws:
        assert ws.subprotocol in SUBPROTOCOLS
        client = FoxgloveClient(ws)
        await client.receive(lambda c: set(VIEW_CHANNELS) <= set(c.decoded) and TREE <= frames(c), 90)
        # a client channel on a motion topic is refused; the goal channel reaches the navigator's key
        await client.publish(1, "/cmd_vel", pose_stamped(9.0, 9.0, 0.0))
        await client.publish(2, "/goal_pose", pose_stamped(1.5, -2.0, 0.8))
        await client.receive(lambda c: from_foxglove(heard["goal"]), 30)
        return client


def test_the_view_serves_every_channel_and_forwards_goals_only_to_the_goal_key(processes, router_endpoint):
    port = free_port()
    view = processes.omninav("view", "--port", str(port), "--router", router_endpoint, "--allow-goals")
    url = goal_url(processes, view)
    assert url.startswith(f"ws://127.0.0.1:{port}/?token=")
    heard = {"goal": [], "cmd_vel": []}
    stop = threading.Event()
    with open_client(router_endpoint) as session:
        keys = KeyLayout("r1")
        subscribers = [session.declare_subscriber(keys.resolve(name), lambda s, name=name: heard[name].append(
            decode(s.payload.to_bytes()))) for name in heard]

        def publish_stack():     # again and again: the view may subscribe after the first round
            publishers = {key: session.declare_publisher(key) for key in stack_messages(0)}
            stamp = 0
            while not stop.is_set():
                stamp += S // 10
                for key, msg in stack_messages(stamp).items():
                    publishers[key].put(encode(msg))
                stop.wait(0.1)

        publisher = threading.Thread(target=publish_stack)
        publisher.start()
        try:
            client = asyncio.run(watch_and_send_goals(url, heard))
        finally:
            stop.set()
            publisher.join()
        for sub in subscribers:
            sub.undeclare()
    assert processes.stop(view) == 0

    advertised = {c["topic"]: c["schemaName"] for c in client.channels.values()}
    assert {topic: advertised[topic] for topic in VIEW_CHANNELS} == VIEW_CHANNELS
    assert all(c["encoding"] in ("protobuf", "json") for c in client.channels.values())
    grid = client.decoded["/map"][0]
    assert (grid.column_count, grid.cell_size.x) == (4, 0.1)
    assert list(client.decoded["/scan"][0].ranges[:2]) == [1.0, 2.0]
    assert TREE <= frames(client)
    assert client.decoded["/diagnostics/costmap"][0]["values"] == {"received/scan": 3}
    (track,) = client.decoded["/tracks"][0].entities
    assert (track.frame_id, track.cylinders[0].size.x, track.arrows[0].shaft_length) == ("odom", 0.5, 0.8)
    assert [(p.position.x, p.position.y) for p in client.decoded["/plan"][0].poses] == [(0.0, 0.0), (1.0, 0.5)]
    (goal,) = from_foxglove(heard["goal"])
    assert goal.header.frame_id == "map"
    assert np.allclose((goal.pose.x, goal.pose.y, goal.pose.theta), (1.5, -2.0, 0.8))
    assert heard["cmd_vel"] == []


def test_compose_files_run_the_view_by_name_with_its_port(tmp_path):
    compose = tmp_path / "view.yaml"
    compose.write_text("services:\n  - name: view\n    service: view\n    params: {port: 8766, grid_period_s: 2.0}\n")
    (spec,) = load_compose(compose).services
    assert (spec.service, spec.params) == ("view", {"port": 8766, "grid_period_s": 2.0})
    compose.write_text("services:\n  - name: view\n    service: view\n    params: {host: 0.0.0.0}\n")
    with pytest.raises(ComposeError, match="host"):       # no parameter opens it beyond loopback
        load_compose(compose)


def test_a_taken_port_stops_the_view_with_one_line_saying_so(processes):
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        view = processes.omninav("view", "--port", str(taken.getsockname()[1]))
        assert view.wait(60) != 0
    assert "cannot serve on 127.0.0.1:" in processes.log_of(view)
