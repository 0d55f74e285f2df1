"""What the robot's ROS graph tells the bridge, read from its liveliness tokens (pure: no Zenoh here).

Two questions, asked before anything is sent and again for every endpoint that appears later:
- does the robot run an rmw_zenoh whose wire the bridge speaks (rmw.SUPPORTED_RMW_ZENOH)? An older
  one would take none of the bridge's samples and give it no cached /tf_static, silently: refused;
- does the robot's /cmd_vel subscriber take the type the bridge sends? The type is part of the data
  key, so one of the other type never hears a command and nothing on the robot says why: warned.
"""
from __future__ import annotations

from dataclasses import dataclass

from .rmw import (ADMIN_SPACE, PUBLISHER, SUBSCRIPTION, SUPPORTED_RMW_ZENOH, VOLATILE, demangle,
                  ros_type_name)
from .translate import CMD_VEL_TYPES, RosTopic

HUMBLE_TYPE_HASH = "TypeHashNotSupported"   # Humble's rmw_zenoh (0.1.x): rosidl there has no type hashes
# Zenoh < 1.3's advanced publisher announces itself as `@adv/pub/<zid>/<eid>/<meta>/@/<key>` (rmw.py)
OLD_ADVANCED_PUBLISHER = "@adv/pub/"
_ENDPOINT_PARTS = 13    # @ros2_lv/domain/zid/nid/id/kind/enclave/namespace/node/topic/type/hash/qos


def graph_selectors(domain: int) -> tuple[str, str]:
    """The liveliness key expressions that hold the robot's graph: rmw_zenoh's tokens, and Zenoh < 1.3's
    advanced publishers (a verbatim chunk such as `@adv` or `@` is matched only when spelled out)."""
    return f"{ADMIN_SPACE}/{domain}/**", f"{OLD_ADVANCED_PUBLISHER}**/@/{domain}/**"


@dataclass(frozen=True)
class Endpoint:
    """A publisher or subscription as its rmw_zenoh liveliness token describes it."""
    kind: str           # rmw.PUBLISHER or rmw.SUBSCRIPTION
    node: str           # fully qualified: '/diff_drive_controller', '/robot1/amcl'
    topic: str
    dds_type: str
    type_hash: str
    qos: str            # as the token writes it (rmw.qos_part)


def parse_endpoint(token: str) -> Endpoint | None:
    """The endpoint a token declares; None for a node's, a service's or a key that is not rmw_zenoh's."""
    parts = token.split("/")
    if len(parts) != _ENDPOINT_PARTS or parts[0] != ADMIN_SPACE or parts[5] not in (PUBLISHER, SUBSCRIPTION):
        return None
    namespace = demangle(parts[7]).rstrip("/")
    return Endpoint(kind=parts[5], node=f"{namespace}/{parts[8]}", topic=demangle(parts[9]),
                    dds_type=demangle(parts[10]), type_hash=demangle(parts[11]), qos=parts[12])


def older_rmw_zenoh(token: str) -> str | None:
    """What in this liveliness token shows a peer older than SUPPORTED_RMW_ZENOH, or None."""
    if token.startswith(OLD_ADVANCED_PUBLISHER):
        key = token.split("/@/", 1)[-1]
        return f"its publisher on {key} is announced as Zenoh < 1.3 does (rmw_zenoh 0.2.2-0.2.3)"
    endpoint = parse_endpoint(token)
    if endpoint is None:
        return None
    where = f"{endpoint.node}'s {'publisher' if endpoint.kind == PUBLISHER else 'subscription'} on {endpoint.topic}"
    if endpoint.type_hash == HUMBLE_TYPE_HASH:
        return f"{where} has no type hash (ROS 2 Humble)"
    durability = endpoint.qos.split(":")[1] if endpoint.qos.count(":") >= 2 else ""
    if durability == str(VOLATILE):
        # from 0.2.3 volatile is rmw_zenoh's default, which a token leaves out
        return f"{where} spells out durability volatile (rmw_zenoh 0.2.0-0.2.2, whose default was transient local)"
    return None


def refusal(reason: str) -> str:
    """The one line that ends the bridge when the robot is too old."""
    return (f"the robot's rmw_zenoh is older than {SUPPORTED_RMW_ZENOH}: {reason}; its attachments and "
            f"transient-local topics differ and it would never hear /cmd_vel: upgrade the robot's rmw_zenoh_cpp")


def cmd_vel_type_warning(token: str, sent: RosTopic) -> str | None:
    """The one-line warning for a robot's subscription on `sent`'s topic that takes another type, or None."""
    endpoint = parse_endpoint(token)
    if endpoint is None or endpoint.kind != SUBSCRIPTION or endpoint.topic != sent.name:
        return None
    try:
        theirs = ros_type_name(endpoint.dds_type)
    except ValueError:
        return None
    if theirs == sent.msgtype:
        return None
    choice = next((name for name, msgtype in CMD_VEL_TYPES.items() if msgtype == theirs), None)
    change = (f"start `omninav bridge ros2` with --cmd-vel-type {choice}" if choice
              else f"the bridge sends only {' or '.join(CMD_VEL_TYPES.values())}")
    return (f"the robot's {endpoint.node} subscribes to {sent.name} as {theirs} but the bridge sends {sent.msgtype}, "
            f"so it never hears a command: {change}")
