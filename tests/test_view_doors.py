"""The view's goal channel is closed unless `--allow-goals`, and then open only to a connection that
presents the run's token from no Origin or an allowed one (services/view/gate.py).

The view runs in this process on the test's router; each client speaks Foxglove's protocol over
`websockets`. That a goal was *not* forwarded is shown without waiting: after the client's goal, a
getParameters round trip proves the server handled it (one connection's messages are handled in
order), then the view's own goal publisher puts a marker goal; goals of one publisher arrive in
order, so once the marker is heard every goal the view forwarded before it has been too.
"""
from __future__ import annotations

import asyncio
import json
import logging
import math
import struct
import threading

import pytest
import websockets

from conftest import wait_until
from omninav.schemas import decode
from omninav.schemas.keys import KeyLayout
from omninav.schemas.messages import Goal, Header, Pose2D
from omninav.services.runtime.run import build_node
from omninav.services.runtime.zenoh_config import open_client
from omninav.services.view.gate import origin_allowed

SUBPROTOCOLS = ["foxglove.sdk.v1", "foxglove.websocket.v1"]
MARKER = "marker"


@pytest.fixture
def view(router_endpoint, request, capfd):
    """(the view node, goal ids heard on the bus, what it printed) for params request.param; stopped at the end."""
    node = build_node("view", overrides={"port": 0, **request.param})
    stop = threading.Event()
    thread = threading.Thread(target=node.run_live, args=(router_endpoint, stop))
    heard: list[str] = []
    with open_client(router_endpoint) as session:
        sub = session.declare_subscriber(KeyLayout("r1").resolve("goal"),
                                         lambda s: heard.append(decode(s.payload.to_bytes()).goal_id))
        thread.start()
        try:
            wait_until(lambda: node.server is not None and (node.gate is not None or not node.params.allow_goals),
                       60, what="the view's server")
            yield node, heard, capfd.readouterr().out
        finally:
            stop.set()
            thread.join()
            sub.undeclare()


def port_of(node) -> int:
    return node.gate.port if node.gate is not None else node.server.port


def pose(x: float) -> dict:
    return {"header": {"stamp": {"sec": 0, "nsec": 0}, "frame_id": "map"},
            "pose": {"position": {"x": x, "y": 0.0, "z": 0.0},
                     "orientation": {"x": 0.0, "y": 0.0, "z": math.sin(0.25), "w": math.cos(0.25)}}}


async def _send_goal(url: str, origin: str | None) -> None:
    async with websockets.connect(url, subprotocols=SUBPROTOCOLS, origin=origin) as ws:
        await ws.send(json.dumps({"op": "advertise", "channels": [
            {"id": 1, "topic": "/goal_pose", "encoding": "json", "schemaName": "geometry_msgs/msg/PoseStamped"}]}))
        await ws.send(struct.pack("<BI", 0x01, 1) + json.dumps(pose(1.5)).encode())
        await ws.send(json.dumps({"op": "getParameters", "parameterNames": [], "id": "handled"}))
        while True:     # until the server answered the request sent after the goal
            frame = await asyncio.wait_for(ws.recv(), 30)
            if isinstance(frame, str) and json.loads(frame).get("id") == "handled":
                return


def send_goal(node, origin: str | None = None, token: str | None = None) -> None:
    query = "" if token is None else f"?token={token}"
    asyncio.run(_send_goal(f"ws://127.0.0.1:{port_of(node)}/{query}", origin))


def forwarded(node, heard: list[str]) -> list[str]:
    """The goals the view forwarded so far (see the module's docstring)."""
    node.goal_pub.publish(Goal(Header(stamp_ns=0, frame_id="map"), MARKER, Pose2D(0.0, 0.0, 0.0)))
    wait_until(lambda: MARKER in heard, 30, what="the marker goal")
    goals = [g for g in heard if g != MARKER]
    heard.clear()
    return goals


@pytest.mark.parametrize("view", [{}], indirect=True)
def test_without_allow_goals_no_goal_a_client_sends_reaches_the_bus(view, caplog):
    node, heard, _ = view
    with caplog.at_level(logging.WARNING):
        send_goal(node)
        send_goal(node, origin="http://localhost:8080")
    assert forwarded(node, heard) == []
    assert node.gate is None and node.token is None
    assert "goals are off (start `omninav view --allow-goals`)" in caplog.text


@pytest.mark.parametrize("view", [{"allow_goals": True, "allow_origins": ["https://studio.example:8443"]}],
                         indirect=True)
def test_with_allow_goals_only_the_token_from_an_allowed_origin_sends_goals(view, caplog):
    node, heard, printed = view
    assert f"?token={node.token}" in printed      # the URL to connect to
    with caplog.at_level(logging.INFO):
        send_goal(node)                                             # no token
        send_goal(node, token="guessed")                            # a wrong one
        send_goal(node, origin="https://evil.example", token=node.token)
        send_goal(node, origin="null", token=node.token)            # a sandboxed page
        assert forwarded(node, heard) == []
        send_goal(node, token=node.token)                           # a program: no Origin
        send_goal(node, origin="https://app.foxglove.dev", token=node.token)
        send_goal(node, origin="http://127.0.0.1:5173", token=node.token)
        send_goal(node, origin="https://studio.example:8443", token=node.token)     # --allow-origin
        assert forwarded(node, heard) == ["foxglove-1", "foxglove-2", "foxglove-3", "foxglove-4"]
    refusals = [r.getMessage() for r in caplog.records if "goals refused" in r.getMessage() and "connection" in
                r.getMessage() and r.name == "omninav.view"]
    assert any("no token in its URL" in r for r in refusals)
    assert any("wrong token" in r for r in refusals)
    assert any("Origin https://evil.example is not allowed" in r for r in refusals)
    assert any("Origin null is not allowed" in r for r in refusals)
    assert node.token not in caplog.text                           # the token is printed, never logged


def test_allowed_origins():
    assert origin_allowed(None)
    assert origin_allowed("https://app.foxglove.dev")
    assert origin_allowed("http://localhost:8080") and origin_allowed("http://127.0.0.1")
    assert not origin_allowed("https://localhost.evil.example")
    assert not origin_allowed("http://app.foxglove.dev")           # not https
    assert not origin_allowed("https://app.foxglove.dev.evil.example")
    assert not origin_allowed("null")
    assert origin_allowed("https://x.example:1", ("https://x.example:1",))
