"""rmw_zenoh's wire layout, as far as a bridge needs it: data keys, liveliness tokens, GIDs, attachments.

Every format here follows rmw_zenoh (ROS 2 Jazzy's rmw_zenoh_cpp), read from its sources:
- data key `<domain>/<topic without leading and trailing '/'>/<DDS type name>/<type hash>`:
  liveliness_utils.cpp, TopicInfo::TopicInfo (ros2-gbp/rmw_zenoh-release, commit 091acf7);
- liveliness token `@ros2_lv/<domain>/<zid>/<nid>/<id>/<NN|MP|MS>/<enclave>/<namespace>/<node>` and,
  for publishers and subscriptions, `/<topic>/<DDS type>/<type hash>/<qos>`, every '/' inside a part
  replaced by '%' (mangle_name), the QoS as qos_to_keyexpr writes it: Entity::Entity, same file;
- the QoS defaults a token leaves out (reliable, volatile, keep last 42, infinite durations):
  qos.cpp (ros2/rmw_zenoh, commit 5e10d47);
- an entity's GID: XXH3-128 of its token, low 64 bits then high 64 bits, little-endian (Entity::Entity);
- the attachment of every sample: zenoh-ext serialization of (int64 sequence number, int64 source
  timestamp, uint8[16] GID) = 8 + 8 + (1 length byte) + 16 = 33 bytes: AttachmentData::
  serialize_to_zbytes, attachment_helpers.cpp. A sample without it is dropped by rmw_zenoh's subscriptions.
Rmw enum values (rmw/types.h): reliability RELIABLE 1, BEST_EFFORT 2; durability TRANSIENT_LOCAL 1,
VOLATILE 2; history KEEP_LAST 1, KEEP_ALL 2.

Supported: rmw_zenoh_cpp 0.2.4 and later on Jazzy (read up to 0.2.10 in ros2-gbp/rmw_zenoh-release's
release/jazzy/rmw_zenoh_cpp/0.2.x-1 tags). Older peers speak another wire and are refused (graph.py):
- the attachment: up to 0.2.3 each field is preceded by its name as a zenoh-ext string
  ("sequence_number", "source_timestamp", "source_gid"), and a subscription that finds no name
  throws: our samples would never reach them, nor theirs us (attachment_helpers.cpp, 0.2.3 -> 0.2.4);
- transient local: 0.2.2-0.2.3 run Zenoh 1.2, whose advanced publisher announces itself at
  `@adv/pub/<zid>/<eid>/<meta>/@/<key>` where Zenoh >= 1.3 (and so this bridge: pyproject) uses
  `<key>/@adv/pub/<zid>/<eid>/<meta>`, so neither side finds the other's cache (/tf_static, /map);
  0.2.0-0.2.1 have no advanced publisher at all (a publication cache);
- the QoS part of tokens: up to 0.2.2 rmw_zenoh's default durability is transient local (qos.cpp), so
  a volatile endpoint writes its durability "2" where 0.2.3 and later leave it empty;
- Humble (0.1.x) has no type hashes: its keys and tokens say "TypeHashNotSupported".
The heartbeat: from 0.2.4 a RELIABLE + TRANSIENT_LOCAL publisher sends a sporadic heartbeat every
500 ms (its last sequence number, only when it changed: rmw_publisher_data.cpp,
SAMPLE_MISS_DETECTION_HEARTBEAT_PERIOD) and such subscriptions recover a missed last sample from the
publisher's cache (rmw_subscription_data.cpp); congestion control is DROP unless RELIABLE + KEEP_ALL.
"""
from __future__ import annotations

import struct
from dataclasses import dataclass

SUPPORTED_RMW_ZENOH = "rmw_zenoh_cpp 0.2.4 or later (ROS 2 Jazzy)"
ADMIN_SPACE = "@ros2_lv"
NODE, PUBLISHER, SUBSCRIPTION = "NN", "MP", "MS"
GID_SIZE = 16
_ATTACHMENT = struct.Struct("<qqB16s")     # the length byte is zenoh-ext's LEB128 of 16: one byte
ATTACHMENT_SIZE = _ATTACHMENT.size         # 33
RELIABLE, BEST_EFFORT = 1, 2
TRANSIENT_LOCAL, VOLATILE = 1, 2
KEEP_LAST, KEEP_ALL = 1, 2
HEARTBEAT_S = 0.5          # rmw_zenoh's sporadic heartbeat of a reliable transient-local publisher
# what an rmw_zenoh <= 0.2.3 attachment starts with: the zenoh-ext string "sequence_number" (LEB128 length 15)
KEYED_ATTACHMENT_START = b"\x0fsequence_number"


@dataclass(frozen=True)
class Qos:
    """A ROS 2 QoS profile (durations infinite, liveliness automatic: all that the bridge uses)."""
    reliability: int = RELIABLE
    durability: int = VOLATILE
    history: int = KEEP_LAST
    depth: int = 10                        # rclcpp's and rclpy's usual depth


_RMW_ZENOH_DEFAULT = Qos(depth=42)


@dataclass(frozen=True)
class Publishing:
    """How rmw_zenoh (0.2.4+, rmw_publisher_data.cpp) puts a publisher of this QoS on Zenoh."""
    reliable: bool
    block: bool                            # congestion control BLOCK; else DROP (a full queue drops the sample)
    cache_depth: int | None                # transient local: an advanced publisher's cache, announced to late joiners
    heartbeat_s: float | None              # sporadic heartbeat: subscribers detect a missed last sample and fetch it


def publishing(qos: Qos) -> Publishing:
    reliable = qos.reliability == RELIABLE
    latched = qos.durability == TRANSIENT_LOCAL
    return Publishing(reliable=reliable, block=reliable and qos.history == KEEP_ALL,
                      cache_depth=qos.depth if latched else None,
                      heartbeat_s=HEARTBEAT_S if latched and reliable else None)


def dds_type_name(msgtype: str) -> str:
    """'sensor_msgs/msg/LaserScan' -> 'sensor_msgs::msg::dds_::LaserScan_' (rosidl's DDS naming)."""
    package, kind, name = _split_type(msgtype)
    return f"{package}::{kind}::dds_::{name}_"


def _split_type(msgtype: str) -> tuple[str, str, str]:
    parts = msgtype.split("/")
    if len(parts) != 3 or not all(parts):
        raise ValueError(f"ROS type {msgtype!r}: expected package/msg/Name")
    return parts[0], parts[1], parts[2]


def topic_key(domain: int, topic: str, msgtype: str, type_hash: str) -> str:
    """The Zenoh key rmw_zenoh publishes a topic's samples on."""
    return f"{domain}/{topic.strip('/')}/{dds_type_name(msgtype)}/{type_hash}"


def mangle(name: str) -> str:
    return name.replace("/", "%")


def demangle(name: str) -> str:
    return name.replace("%", "/")


def ros_type_name(dds_type: str) -> str:
    """'geometry_msgs::msg::dds_::Twist_' -> 'geometry_msgs/msg/Twist' (dds_type_name's inverse; ValueError
    for anything else)."""
    parts = dds_type.split("::")
    if len(parts) != 4 or parts[2] != "dds_" or not parts[3].endswith("_"):
        raise ValueError(f"DDS type {dds_type!r}: expected package::msg::dds_::Name_")
    return f"{parts[0]}/{parts[1]}/{parts[3][:-1]}"


def qos_part(qos: Qos) -> str:
    """The QoS part of a token: each value left empty where it equals rmw_zenoh's default."""
    def value(mine: int, default: int) -> str:
        return "" if mine == default else str(mine)
    d = _RMW_ZENOH_DEFAULT
    return (f"{value(qos.reliability, d.reliability)}:{value(qos.durability, d.durability)}:"
            f"{value(qos.history, d.history)},{value(qos.depth, d.depth)}:,:,:,,")


@dataclass(frozen=True)
class NodeIdentity:
    """Who the bridge is on the ROS graph: one node in one session."""
    domain: int
    zid: str                               # the Zenoh session id, as its string form
    name: str
    namespace: str = "/"
    enclave: str = "/"
    nid: int = 0                           # rmw_zenoh numbers a session's entities from 0

    def _prefix(self, entity_id: int, kind: str) -> str:
        return (f"{ADMIN_SPACE}/{self.domain}/{self.zid}/{self.nid}/{entity_id}/{kind}/{mangle(self.enclave)}/"
                f"{mangle(self.namespace)}/{mangle(self.name)}")

    def node_token(self) -> str:
        return self._prefix(self.nid, NODE)

    def entity_token(self, entity_id: int, kind: str, topic: str, msgtype: str, type_hash: str, qos: Qos) -> str:
        if kind not in (PUBLISHER, SUBSCRIPTION):
            raise ValueError(f"entity kind {kind!r}: expected {PUBLISHER} or {SUBSCRIPTION}")
        return (f"{self._prefix(entity_id, kind)}/{mangle(topic)}/{mangle(dds_type_name(msgtype))}/"
                f"{mangle(type_hash)}/{qos_part(qos)}")


def entity_gid(token: str) -> bytes:
    """The GID rmw_zenoh derives from an entity's liveliness token."""
    import xxhash    # the optional [rosbag] extra, like rosbags
    return xxhash.xxh3_128(token.encode()).intdigest().to_bytes(GID_SIZE, "little")


def pack_attachment(sequence_number: int, source_timestamp_ns: int, gid: bytes) -> bytes:
    if len(gid) != GID_SIZE:
        raise ValueError(f"a GID has {GID_SIZE} bytes, not {len(gid)}")
    return _ATTACHMENT.pack(sequence_number, source_timestamp_ns, GID_SIZE, gid)


def unpack_attachment(data: bytes) -> tuple[int, int, bytes]:
    """(sequence number, source timestamp ns, GID); ValueError naming what is wrong."""
    if data.startswith(KEYED_ATTACHMENT_START):
        raise ValueError(f"an rmw_zenoh attachment with field names, as before 0.2.4: "
                         f"the robot's rmw_zenoh is older than {SUPPORTED_RMW_ZENOH}")
    if len(data) != ATTACHMENT_SIZE:
        raise ValueError(f"an rmw_zenoh attachment has {ATTACHMENT_SIZE} bytes, not {len(data)}")
    seq, stamp, length, gid = _ATTACHMENT.unpack(data)
    if length != GID_SIZE:
        raise ValueError(f"attachment GID length {length}, expected {GID_SIZE}")
    return seq, stamp, gid
