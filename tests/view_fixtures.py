"""Shared by the view tests: one message on every key the view shows, and decoding Foxglove's
well-known messages the way a viewer does, from the protobuf schema that travels with the channel
(a FileDescriptorSet), not from compiled classes."""
import json

import numpy as np

from mcap.records import Schema
from mcap.decoder import DecoderFactory as McapDecoderFactory
from mcap_protobuf.decoder import DecoderFactory

from omninav.schemas import messages as m
from omninav.schemas.keys import KeyLayout

S = 1_000_000_000
# topic -> schema name of what the view shows for the messages of stack_messages
VIEW_CHANNELS = {
    "/map": "foxglove.Grid", "/costmap/global": "foxglove.Grid", "/costmap/local": "foxglove.Grid",
    "/scan": "foxglove.LaserScan", "/tf": "foxglove.FrameTransforms", "/truth/robot": "foxglove.SceneUpdate",
    "/truth/movers": "foxglove.SceneUpdate", "/tracks": "foxglove.SceneUpdate", "/localizer/pose": "foxglove.PoseInFrame",
    "/localizer/particles": "foxglove.PosesInFrame", "/plan": "foxglove.PosesInFrame",
    "/local_plan": "foxglove.PosesInFrame", "/goal": "foxglove.PosesInFrame",
    "/diagnostics/costmap": "omninav.Diagnostic"}

_factory = DecoderFactory()
_schema_ids: dict[tuple[str, bytes], int] = {}


def decode_with_schema(encoding: str, schema_name: str, schema_encoding: str, schema_data: bytes, data: bytes):
    """A decoded message: a protobuf message for protobuf channels, a dict for JSON ones."""
    if encoding == "json":
        return json.loads(data)
    # the factory caches generated classes by schema id: give each distinct schema its own
    schema_id = _schema_ids.setdefault((schema_name, schema_data), len(_schema_ids) + 1)
    decoder = _factory.decoder_for(encoding, Schema(id=schema_id, name=schema_name, encoding=schema_encoding,
                                                    data=schema_data))
    assert decoder is not None, f"no decoder for {encoding} / {schema_encoding} {schema_name}"
    return decoder(data)


class JsonDecoderFactory(McapDecoderFactory):
    """For the mcap reader: JSON channels (diagnostics) decode to dicts."""

    def decoder_for(self, message_encoding, schema):
        return json.loads if message_encoding == "json" else None


def decode_foxglove(message):
    """A foxglove.messages instance, encoded and decoded again."""
    schema = type(message).get_schema()
    return decode_with_schema("protobuf", schema.name, schema.encoding, schema.data, message.encode())


def stack_messages(stamp_ns: int) -> dict[str, object]:
    """One message on every key the view shows, as the services would publish them."""
    h = lambda frame: m.Header(stamp_ns=stamp_ns, frame_id=frame)     # noqa: E731
    info = m.MapMetaData(0.1, 4, 3, m.Pose2D(-0.2, -0.1, 0.0))
    poses = np.array([[0.0, 0.0, 0.0], [1.0, 0.5, 0.3]])
    keys = KeyLayout("r1")
    return {
        keys.resolve("map"): m.OccupancyGrid(h("map"), info, np.zeros((3, 4), np.int8)),
        keys.resolve("costmap/global"): m.Costmap(h("map"), info, np.full((3, 4), 254, np.uint8)),
        keys.resolve("costmap/local"): m.Costmap(h("odom"), info, np.zeros((3, 4), np.uint8)),
        keys.resolve("scan"): m.LaserScan(h("laser"), -0.1, 0.1, 0.1, range_max=5.0,
                                          ranges=np.array([1.0, 2.0, np.inf], np.float32)),
        keys.resolve("sim/truth"): m.Odometry(h("world"), "base_link", m.Pose2D(1.0, 2.0, 0.5)),
        keys.resolve("odom"): m.Odometry(h("odom"), "base_link", m.Pose2D(0.9, 2.1, 0.4)),
        keys.resolve("tf/map_odom"): m.Transform(h("map"), "odom", m.Pose2D(0.1, -0.1, 0.1)),
        keys.resolve("pose"): m.PoseWithCovariance(h("map"), m.Pose2D(1.0, 2.0, 0.5)),
        keys.resolve("particlecloud"): m.ParticleCloud(h("map"), poses, np.full(2, 0.5)),
        keys.resolve("plan"): m.Path(h("map"), poses, goal_id="g1"),
        keys.resolve("local_plan"): m.Path(h("odom"), poses, goal_id="g1"),
        keys.resolve("goal"): m.Goal(h("map"), "g1", m.Pose2D(3.0, 4.0, 0.0)),
        keys.resolve("sim/movers"): m.Obstacles(h("world"), np.array([[2.0, 2.0, 0.3]]), np.zeros((1, 2))),
        keys.resolve("tracks"): m.Tracks(h("odom"), np.array([7]), np.array([[2.5, 1.5, 0.0, -0.8]]),
                                          np.tile(np.eye(4), (1, 1, 1)), np.array([0.25])),
        keys.diagnostics("costmap"): m.Diagnostic(h(""), "costmap", 0, "ok", {"received/scan": 3}),
    }
