"""The bridge against rmw_zenoh's own wire: golden vectors copied from rmw_zenoh and Zenoh (each cited
where it is used), the range of rmw_zenoh versions it drives and the refusal of older ones, the
/cmd_vel type (TwistStamped by default, as Jazzy's diff_drive_controller and Nav2) and the warning
when the robot's subscriber takes the other one, and the QoS its publishers get."""
from __future__ import annotations

import threading

import pytest
import zenoh

from conftest import free_port
from test_ros2_bridge import JAZZY_HASHES, header, stack_args
from omninav.parameters.declare import ParamError
from omninav.schemas.messages import Header, Twist
from omninav.services.ros2_bridge.graph import (cmd_vel_type_warning, graph_selectors, older_rmw_zenoh,
                                                parse_endpoint)
from omninav.services.ros2_bridge.rmw import (HEARTBEAT_S, KEEP_ALL, PUBLISHER, SUBSCRIPTION, SUPPORTED_RMW_ZENOH,
                                              TRANSIENT_LOCAL, NodeIdentity, Qos, pack_attachment, publishing,
                                              ros_type_name, topic_key, unpack_attachment)
from omninav.services.ros2_bridge.translate import Bridge, Ros2BridgeParams, ros_outputs, typestore
from omninav.services.runtime.zenoh_config import foreign_client_config, open_router

pytest.importorskip("rosbags")

@pytest.fixture(scope="module")
def store():
    return typestore()


STRING_HASH = JAZZY_HASHES["std_msgs/msg/String"]
TWIST_STAMPED = "geometry_msgs/msg/TwistStamped"

# ros2/rmw_zenoh docs/design.md (commit 99a6a2b), "Topic and Service name mapping" and "Graph Cache":
# demo_nodes_cpp's talker and listener
DESIGN_CHATTER_KEY = f"0/chatter/std_msgs::msg::dds_::String_/{STRING_HASH}"
DESIGN_NAMESPACED_KEY = f"0/robot1/chatter/std_msgs::msg::dds_::String_/{STRING_HASH}"
DESIGN_LISTENER_NODE = "@ros2_lv/2/aac3178e146ba6f1fc6e6a4085e77f21/0/0/NN/%/%/listener"
DESIGN_LISTENER_SUBSCRIPTION = ("@ros2_lv/2/aac3178e146ba6f1fc6e6a4085e77f21/0/10/MS/%/%/listener/%chatter/"
                                f"std_msgs::msg::dds_::String_/{STRING_HASH}/::,10:,:,:,,")
DESIGN_TALKER_PUBLISHER = ("@ros2_lv/2/8b20917502ee955ac4476e0266340d5c/0/10/MP/%/%/talker/%chatter/"
                           f"std_msgs::msg::dds_::String_/{STRING_HASH}/::,7:,:,:,,")

# The attachment of seq 7, source timestamp 1_700_000_000_123_456_789 ns, GID 00 01 .. 0f.
# rmw_zenoh 0.2.4 (ros2-gbp/rmw_zenoh-release release/jazzy/rmw_zenoh_cpp/0.2.4-1,
# src/detail/attachment_helpers.cpp, AttachmentData::serialize_to_zbytes) serializes the int64, the int64
# and the std::array<uint8_t, 16> with zenoh-cpp's ext::Serializer: an int64 as 8 bytes little-endian, an
# std::array as a sequence (LEB128 length 0x10, then the bytes: zenoh-cpp include/zenoh/api/ext/serialization.hxx)
GID = bytes(range(16))
GOLDEN_ATTACHMENT = bytes.fromhex("0700000000000000" "15cd853dfe9c9717" "10" "000102030405060708090a0b0c0d0e0f")
# 0.2.3 (release/jazzy/rmw_zenoh_cpp/0.2.3-1, same file) puts each field's name before it, a string
# serialized as LEB128 length + bytes
OLD_ATTACHMENT = (b"\x0fsequence_number" + bytes.fromhex("0700000000000000") + b"\x10source_timestamp"
                  + bytes.fromhex("15cd853dfe9c9717") + b"\x0asource_gid" + b"\x10" + GID)

# A transient-local publisher's liveliness token in Zenoh's advanced publisher (eclipse-zenoh/zenoh,
# zenoh-ext/src/advanced_publisher.rs): tag 1.2.1 (in rmw_zenoh 0.2.2-0.2.3) declares
# KE_ADV_PREFIX / KE_PUB / zid / eid / KE_EMPTY / KE_AT / key; tag 1.3.0 (rmw_zenoh 0.2.4+) key / @adv/pub/zid/eid/_
ROSOUT_KEY = "0/rosout/rcl_interfaces::msg::dds_::Log_/RIHS01_x"
ZENOH_1_2_ADVANCED_PUBLISHER = f"@adv/pub/8b20917502ee955ac4476e0266340d5c/3/_/@/{ROSOUT_KEY}"
ZENOH_1_3_ADVANCED_PUBLISHER = f"{ROSOUT_KEY}/@adv/pub/8b20917502ee955ac4476e0266340d5c/3/_"

# The talker's token as rmw_zenoh 0.2.0-0.2.2 writes it: qos.cpp there (release/jazzy/rmw_zenoh_cpp/0.2.2-1)
# has RMW_ZENOH_DEFAULT_DURABILITY TRANSIENT_LOCAL, so qos_to_keyexpr spells out volatile (2); 0.2.3 on:
# VOLATILE, left out as in DESIGN_TALKER_PUBLISHER
OLD_DEFAULT_TALKER = DESIGN_TALKER_PUBLISHER.replace("/::,7:", "/:2:,7:")
# Humble (release/humble/rmw_zenoh_cpp/0.1.9-1, rmw_publisher_data.cpp): type_hash_c_str = "TypeHashNotSupported"
HUMBLE_TALKER = DESIGN_TALKER_PUBLISHER.replace(STRING_HASH, "TypeHashNotSupported")

# Jazzy's diff_drive_controller listening on /cmd_vel: a TwistStamped subscription (the node and zid made up,
# the layout design.md's, the type hash JAZZY_HASHES')
DIFF_DRIVE_CMD_VEL = ("@ros2_lv/0/943f9ebc32acd3e072bfda12ce8c7ed2/0/12/MS/%/%/diff_drive_controller/%cmd_vel/"
                      f"geometry_msgs::msg::dds_::TwistStamped_/{JAZZY_HASHES[TWIST_STAMPED]}/::,1:,:,:,,")


# ---------------------------------------------------------------- golden vectors: keys, tokens, attachments

def test_golden_keys_of_rmw_zenohs_design():
    assert topic_key(0, "/chatter", "std_msgs/msg/String", STRING_HASH) == DESIGN_CHATTER_KEY
    assert topic_key(0, "/robot1/chatter", "std_msgs/msg/String", STRING_HASH) == DESIGN_NAMESPACED_KEY
    # what diff_drive_controller listens on, with Jazzy's TwistStamped hash from rosbags' Jazzy store
    stamped_hash = typestore().hash_rihs01(TWIST_STAMPED)
    assert topic_key(0, "/cmd_vel", TWIST_STAMPED, stamped_hash) == (
        "0/cmd_vel/geometry_msgs::msg::dds_::TwistStamped_/"
        "RIHS01_5f0fcd4f81d5d06ad9b4c4c63e3ea51b82d6ae4d0558f1d475229b1121db6f64")


def test_golden_liveliness_tokens_of_rmw_zenohs_design():
    listener = NodeIdentity(domain=2, zid="aac3178e146ba6f1fc6e6a4085e77f21", name="listener")
    assert listener.node_token() == DESIGN_LISTENER_NODE
    assert listener.entity_token(10, SUBSCRIPTION, "/chatter", "std_msgs/msg/String", STRING_HASH,
                                 Qos(depth=10)) == DESIGN_LISTENER_SUBSCRIPTION
    talker = NodeIdentity(domain=2, zid="8b20917502ee955ac4476e0266340d5c", name="talker")
    assert talker.entity_token(10, PUBLISHER, "/chatter", "std_msgs/msg/String", STRING_HASH,
                               Qos(depth=7)) == DESIGN_TALKER_PUBLISHER
    # and read back
    endpoint = parse_endpoint(DESIGN_LISTENER_SUBSCRIPTION)
    assert (endpoint.kind, endpoint.node, endpoint.topic, endpoint.type_hash, endpoint.qos) == (
        SUBSCRIPTION, "/listener", "/chatter", STRING_HASH, "::,10:,:,:,,")
    assert ros_type_name(endpoint.dds_type) == "std_msgs/msg/String"
    assert parse_endpoint(DESIGN_LISTENER_NODE) is None
    assert parse_endpoint("@ros2_lv/0/z/0/1/MP/%/%/ns_node/%a%b/t/h/q").node == "/ns_node"


def test_golden_attachment_of_rmw_zenoh_0_2_4():
    assert pack_attachment(7, 1_700_000_000_123_456_789, GID) == GOLDEN_ATTACHMENT
    assert unpack_attachment(GOLDEN_ATTACHMENT) == (7, 1_700_000_000_123_456_789, GID)
    with pytest.raises(ValueError, match=r"field names, as before 0\.2\.4: the robot's rmw_zenoh is older than "
                                         r"rmw_zenoh_cpp 0\.2\.4 or later"):
        unpack_attachment(OLD_ATTACHMENT)


def test_rmw_zenohs_qos_rules_for_publishers():
    """rmw_publisher_data.cpp (release/jazzy/rmw_zenoh_cpp/0.2.4-1 to 0.2.10-1): DROP unless RELIABLE +
    KEEP_ALL; transient local: a cache of `depth` samples, announced; and, reliable, a sporadic heartbeat
    every SAMPLE_MISS_DETECTION_HEARTBEAT_PERIOD = 500 ms."""
    assert HEARTBEAT_S == 0.5
    assert publishing(Qos()).block is False
    assert publishing(Qos(history=KEEP_ALL)).block is True
    assert publishing(Qos(reliability=2, history=KEEP_ALL)).block is False
    latched = publishing(Qos(durability=TRANSIENT_LOCAL, depth=3))
    assert (latched.cache_depth, latched.heartbeat_s, latched.reliable) == (3, 0.5, True)
    best_effort_latched = publishing(Qos(reliability=2, durability=TRANSIENT_LOCAL, depth=1))
    assert (best_effort_latched.cache_depth, best_effort_latched.heartbeat_s) == (1, None)


# ---------------------------------------------------------------- the supported range and older peers

def test_tokens_of_an_older_rmw_zenoh_are_recognised_and_supported_ones_are_not():
    assert SUPPORTED_RMW_ZENOH == "rmw_zenoh_cpp 0.2.4 or later (ROS 2 Jazzy)"
    for supported in (DESIGN_LISTENER_NODE, DESIGN_LISTENER_SUBSCRIPTION, DESIGN_TALKER_PUBLISHER, DIFF_DRIVE_CMD_VEL,
                      ZENOH_1_3_ADVANCED_PUBLISHER):
        assert older_rmw_zenoh(supported) is None, supported
    assert older_rmw_zenoh(OLD_DEFAULT_TALKER) == (
        "/talker's publisher on /chatter spells out durability volatile (rmw_zenoh 0.2.0-0.2.2, whose default "
        "was transient local)")
    assert older_rmw_zenoh(HUMBLE_TALKER) == "/talker's publisher on /chatter has no type hash (ROS 2 Humble)"
    assert older_rmw_zenoh(ZENOH_1_2_ADVANCED_PUBLISHER) == (
        f"its publisher on {ROSOUT_KEY} is announced as Zenoh < 1.3 does (rmw_zenoh 0.2.2-0.2.3)")
    assert graph_selectors(3) == ("@ros2_lv/3/**", "@adv/pub/**/@/3/**")


def test_this_zenoh_announces_transient_local_publishers_as_rmw_zenoh_0_2_4_does():
    """eclipse-zenoh >= 1.3 (pyproject): an advanced publisher's token is `<key>/@adv/pub/<zid>/<eid>/_`,
    found where rmw_zenoh 0.2.4+ subscriptions look for late publishers; never at Zenoh 1.2's place."""
    from zenoh.ext import declare_advanced_publisher
    from omninav.services.ros2_bridge.node import publisher_options
    robot = f"tcp/127.0.0.1:{free_port()}"
    amcl_pose = next(topic for topic in ros_outputs() if topic.name == "/amcl_pose")
    key = topic_key(0, amcl_pose.name, amcl_pose.msgtype, "H")
    with open_router(robot), zenoh.open(foreign_client_config(robot)) as session:
        publisher = declare_advanced_publisher(session, key, **publisher_options(amcl_pose))
        # (a set: the session's own token may answer both locally and through the router)
        tokens = {str(r.ok.key_expr) for r in session.liveliness().get(f"{key}/@adv/pub/**", timeout=5.0) if r.ok}
        assert len(tokens) == 1
        zid, entity, meta = tokens.pop().removeprefix(f"{key}/@adv/pub/").split("/")
        assert (zid, entity.isdigit(), meta) == (str(session.info.zid()), True, "_")
        assert not [r for r in session.liveliness().get(graph_selectors(0)[1], timeout=5.0) if r.ok]
        publisher.undeclare()


def old_robot(endpoint: str, *tokens: str):
    """The robot's router at endpoint, with a session holding these liveliness tokens, moved to the
    bridge's domain 0 (design.md's are in domain 2), until closed."""
    router = open_router(endpoint)
    session = zenoh.open(foreign_client_config(endpoint))
    held = [session.liveliness().declare_token(token.replace("@ros2_lv/2/", "@ros2_lv/0/")) for token in tokens]
    return router, session, held


@pytest.mark.parametrize("token", [OLD_DEFAULT_TALKER, ZENOH_1_2_ADVANCED_PUBLISHER, HUMBLE_TALKER])
def test_bridge_ros2_refuses_an_older_rmw_zenoh_in_one_line_before_the_stack(capsys, monkeypatch, token):
    from omninav.cli import bridge
    from omninav.cli.bridge import main

    def no_stack(_):
        raise AssertionError("the stack was started")
    monkeypatch.setattr(bridge.launcher, "main", no_stack)
    robot = f"tcp/127.0.0.1:{free_port()}"
    router, session, _ = old_robot(robot, DESIGN_TALKER_PUBLISHER, token)
    with router, session:
        for laser in ([0.0, 0.0, 0.0], None):       # given, or looked for on the robot first
            assert main(stack_args(router=robot, laser=laser, tf_timeout=5.0)) == 2
            err = capsys.readouterr().err
            assert err == (f"error: the robot's rmw_zenoh is older than {SUPPORTED_RMW_ZENOH}: {older_rmw_zenoh(token)}"
                           "; its attachments and transient-local topics differ and it would never hear /cmd_vel: "
                           "upgrade the robot's rmw_zenoh_cpp\n")


def test_the_bridge_service_refuses_an_older_rmw_zenoh_before_declaring_cmd_vel(processes):
    robot = f"tcp/127.0.0.1:{free_port()}"
    router, session, _ = old_robot(robot, OLD_DEFAULT_TALKER)
    declared = []
    with router, session:
        # every token the bridge ever declares on the robot's graph, from before it starts
        watch = session.liveliness().declare_subscriber("@ros2_lv/0/**", lambda s: declared.append(str(s.key_expr)))
        node = processes.omninav("run", "ros2_bridge", "--set", f"ros_router={robot}")
        assert node.wait(120) != 0
        watch.undeclare()
    log = processes.log_of(node)
    assert f"the robot's rmw_zenoh is older than {SUPPORTED_RMW_ZENOH}: /talker's publisher on /chatter" in log
    assert not [token for token in declared if "omninav_bridge" in token]    # not even its node, let alone /cmd_vel


def test_an_older_rmw_zenoh_that_joins_later_stops_the_bridge_at_once():
    from omninav.services.runtime.run import build_node
    node = build_node("ros2_bridge")
    sent, stop = [], threading.Event()
    node.ros_sink = lambda topic, payload, stamp: sent.append(topic.name)
    node.read_graph_token(DESIGN_TALKER_PUBLISHER, stop)
    assert not stop.is_set() and node.refused is None
    node.read_graph_token(HUMBLE_TALKER, stop)
    assert stop.is_set() and node.ros_sink is None
    assert node.refused.startswith(f"the robot's rmw_zenoh is older than {SUPPORTED_RMW_ZENOH}: /talker's")
    node.process(0, Twist(header=Header(stamp_ns=11)))     # cmd_vel, after the refusal: not sent
    assert sent == []


# ---------------------------------------------------------------- /cmd_vel: its type, and the warning

def test_cmd_vel_is_twist_stamped_by_default_stamped_by_the_bridges_clock(store):
    t = store.types
    bridge = Bridge(Ros2BridgeParams())
    cmd_vel = next(topic for topic in bridge.outputs if topic.omninav == "cmd_vel")
    assert cmd_vel.msgtype == TWIST_STAMPED
    vector = t["geometry_msgs/msg/Vector3"]
    twist = t["geometry_msgs/msg/Twist"](linear=vector(x=0.5, y=-0.25, z=0.0), angular=vector(x=0.0, y=0.0, z=0.75))
    command = Twist(header=Header(stamp_ns=2_000_000_123), linear_x=0.5, linear_y=-0.25, angular_z=0.75)

    def stamped(stamp_ns, frame="base_link"):
        return bytes(store.serialize_cdr(t[TWIST_STAMPED](header=header(t, stamp_ns, frame), twist=twist), TWIST_STAMPED))
    assert bridge.to_ros(cmd_vel, command) == stamped(2_000_000_123)
    # the robot's clock (its latest scan or odometry) has gone on since the scan the command came from
    bridge.clock_ns = 2_050_000_000
    payload = bridge.to_ros(cmd_vel, command)
    assert payload == stamped(2_050_000_000)
    decoded = store.deserialize_cdr(payload, TWIST_STAMPED)       # what diff_drive_controller reads
    assert (decoded.header.frame_id, decoded.twist.linear.x, decoded.twist.angular.z) == ("base_link", 0.5, 0.75)
    framed = Bridge(Ros2BridgeParams(cmd_vel_frame_id="base_footprint"))
    assert framed.to_ros(cmd_vel, command) == stamped(2_000_000_123, "base_footprint")


def test_cmd_vel_twist_when_asked(store):
    t, bridge = store.types, Bridge(Ros2BridgeParams(cmd_vel_type="twist"))
    cmd_vel = next(topic for topic in bridge.outputs if topic.omninav == "cmd_vel")
    assert cmd_vel.msgtype == "geometry_msgs/msg/Twist"
    vector = t["geometry_msgs/msg/Vector3"]
    twist = t["geometry_msgs/msg/Twist"](linear=vector(x=0.5, y=-0.25, z=0.0), angular=vector(x=0.0, y=0.0, z=0.75))
    assert bridge.to_ros(cmd_vel, Twist(linear_x=0.5, linear_y=-0.25, angular_z=0.75)) == \
        bytes(store.serialize_cdr(twist, "geometry_msgs/msg/Twist"))
    with pytest.raises(ParamError, match="parameter cmd_vel_type must be one of 'twist_stamped', 'twist', got 'twst'"):
        Ros2BridgeParams(cmd_vel_type="twst")


def test_a_cmd_vel_subscriber_of_the_other_type_is_named_with_the_flag_to_change():
    twist = next(topic for topic in ros_outputs("twist") if topic.name == "/cmd_vel")
    assert cmd_vel_type_warning(DIFF_DRIVE_CMD_VEL, twist) == (
        "the robot's /diff_drive_controller subscribes to /cmd_vel as geometry_msgs/msg/TwistStamped but the bridge "
        "sends geometry_msgs/msg/Twist, so it never hears a command: start `omninav bridge ros2` with "
        "--cmd-vel-type twist_stamped")
    stamped = next(topic for topic in ros_outputs() if topic.name == "/cmd_vel")
    assert cmd_vel_type_warning(DIFF_DRIVE_CMD_VEL, stamped) is None
    twist_subscriber = DIFF_DRIVE_CMD_VEL.replace("TwistStamped_", "Twist_")
    assert cmd_vel_type_warning(twist_subscriber, stamped).endswith("--cmd-vel-type twist")
    assert cmd_vel_type_warning(DIFF_DRIVE_CMD_VEL.replace("/MS/", "/MP/"), twist) is None     # a publisher
    assert cmd_vel_type_warning(DIFF_DRIVE_CMD_VEL.replace("%cmd_vel", "%other"), twist) is None
    # neither of the two: says what the bridge sends
    odd = DIFF_DRIVE_CMD_VEL.replace("geometry_msgs::msg::dds_::TwistStamped_", "my_msgs::msg::dds_::Drive_")
    assert cmd_vel_type_warning(odd, stamped).endswith(
        "the bridge sends only geometry_msgs/msg/TwistStamped or geometry_msgs/msg/Twist")


def test_the_node_warns_once_about_the_robots_cmd_vel_type(caplog):
    from omninav.services.runtime.run import build_node
    node = build_node("ros2_bridge", overrides={"cmd_vel_type": "twist"})
    stop = threading.Event()
    with caplog.at_level("WARNING"):
        for _ in range(3):
            node.read_graph_token(DIFF_DRIVE_CMD_VEL, stop)
    warnings = [r.getMessage() for r in caplog.records if "never hears a command" in r.getMessage()]
    assert warnings == [cmd_vel_type_warning(DIFF_DRIVE_CMD_VEL, node.cmd_vel)]
    assert "--cmd-vel-type twist_stamped" in warnings[0] and not stop.is_set()


def test_bridge_ros2_passes_the_cmd_vel_type_and_frame():
    from omninav.cli.bridge import bridge_params, stack
    assert bridge_params(stack(stack_args(laser=[0.0, 0.0, 0.0]))).cmd_vel_type == "twist_stamped"
    params = bridge_params(stack(stack_args(laser=[0.0, 0.0, 0.0], cmd_vel_type="twist", cmd_vel_frame_id="base")))
    assert (params.cmd_vel_type, params.cmd_vel_frame_id) == ("twist", "base")


# ---------------------------------------------------------------- QoS: what may delay /cmd_vel

def test_no_output_blocks_and_cmd_vel_goes_ahead_of_the_map():
    """What keeps a large /map over a slow link from stalling /cmd_vel: no put blocks the node's one
    thread (all DROP, as rmw_zenoh's KEEP_LAST publishers), and /cmd_vel has a higher priority than every
    other output (Zenoh queues each priority apart and sends the higher first), express (not batched)."""
    from omninav.services.ros2_bridge.node import publisher_options
    options = {topic.name: publisher_options(topic) for topic in ros_outputs()}
    assert all(o["congestion_control"] == zenoh.CongestionControl.DROP for o in options.values())
    assert all(o["reliability"] == zenoh.Reliability.RELIABLE for o in options.values())
    cmd_vel = options.pop("/cmd_vel")
    assert cmd_vel["express"] and all(int(cmd_vel["priority"]) < int(o["priority"]) for o in options.values())
    # transient local as Nav2's map_server and amcl publish them: cached for late subscribers, announced,
    # with rmw_zenoh's heartbeat
    for name in ("/map", "/amcl_pose"):
        assert options[name]["publisher_detection"] and "cache" in options[name] and \
            "sample_miss_detection" in options[name], name
    for name in ("/plan", "/tf"):
        assert not options[name]["publisher_detection"] and "cache" not in options[name], name
