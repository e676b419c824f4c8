"""The rmw_zenoh and zenoh-bridge-ros2dds wire, byte for byte, against the examples of rmw_zenoh's
design document (ros2/rmw_zenoh docs/design.md) and rcl_action's names (ros2/rcl
rcl_action/src/rcl_action/names.c). No sockets."""

from __future__ import annotations

import struct

import pytest

from services.ros2.errors import Ros2ConfigError, Ros2TypeError, Ros2WireError
from services.ros2.graph import (
    Attachment,
    BridgeToken,
    Dialect,
    Entity,
    EntityKind,
    data_keyexpr,
    gid_of,
    graph_keyexpr,
)
from services.ros2.names import action_names, action_type_names, check_name, dds_type_name, mangle, qualify, split_type
from services.ros2.qos import STATUS_QOS, Durability, Qos, Reliability, decode_qos, encode_qos, parse_qos

STRING_HASH = "RIHS01_df668c740482bbd48fb39d76a70dfd4bd59db1288021743503259e948f6b1a18"
ADD_HASH = "RIHS01_e118de6bf5eeb66a2491b5bda11202e7b68f198d6f67922cf30364858239c81a"
STRING_DDS = "std_msgs::msg::dds_::String_"
ADD_DDS = "example_interfaces::srv::dds_::AddTwoInts_"

# the liveliness tokens of rmw_zenoh's design document ("Graph Cache"), verbatim
LISTENER_NODE = "@ros2_lv/2/aac3178e146ba6f1fc6e6a4085e77f21/0/0/NN/%/%/listener"
LISTENER_SUB = (f"@ros2_lv/2/aac3178e146ba6f1fc6e6a4085e77f21/0/10/MS/%/%/listener/%chatter/{STRING_DDS}/"
                f"{STRING_HASH}/::,10:,:,:,,")
TALKER_PUB = (f"@ros2_lv/2/8b20917502ee955ac4476e0266340d5c/0/10/MP/%/%/talker/%chatter/{STRING_DDS}/"
              f"{STRING_HASH}/::,7:,:,:,,")
ADD_SERVER = (f"@ros2_lv/2/f9980ee0495eaafb3e38f0d19e2eae12/0/10/SS/%/%/add_two_ints_server/%add_two_ints/"
              f"{ADD_DDS}/{ADD_HASH}/::,10:,:,:,,")
ADD_CLIENT = (f"@ros2_lv/2/e1dc8d1b45ae8717fce78689cc655685/0/10/SC/%/%/add_two_ints_client/%add_two_ints/"
              f"{ADD_DDS}/{ADD_HASH}/::,10:,:,:,,")


def test_topic_and_service_keys_are_those_of_the_design_document():
    rmw = Dialect.RMW_ZENOH
    assert data_keyexpr(rmw, 0, "/chatter", dds_type_name("std_msgs/msg/String"), STRING_HASH) == \
        f"0/chatter/{STRING_DDS}/{STRING_HASH}"
    assert data_keyexpr(rmw, 0, qualify("chatter", "/robot1"), STRING_DDS, STRING_HASH) == \
        f"0/robot1/chatter/{STRING_DDS}/{STRING_HASH}"
    assert data_keyexpr(rmw, 2, "/add_two_ints", dds_type_name("example_interfaces/srv/AddTwoInts"), ADD_HASH) == \
        f"2/add_two_ints/{ADD_DDS}/{ADD_HASH}"


def test_the_bridge_dialect_keys_are_the_plain_names():
    assert data_keyexpr(Dialect.BRIDGE, 0, "/fibonacci/_action/send_goal", "", "") == "fibonacci/_action/send_goal"
    assert data_keyexpr(Dialect.BRIDGE, 7, "/bot1/cmd_vel", "ignored", "ignored") == "bot1/cmd_vel"


@pytest.mark.parametrize("token, kind, node, name, qos", [
    (LISTENER_NODE, EntityKind.NODE, "listener", "", ""),
    (LISTENER_SUB, EntityKind.SUBSCRIPTION, "listener", "/chatter", "::,10:,:,:,,"),
    (TALKER_PUB, EntityKind.PUBLISHER, "talker", "/chatter", "::,7:,:,:,,"),
    (ADD_SERVER, EntityKind.SERVICE, "add_two_ints_server", "/add_two_ints", "::,10:,:,:,,"),
    (ADD_CLIENT, EntityKind.CLIENT, "add_two_ints_client", "/add_two_ints", "::,10:,:,:,,"),
])
def test_the_design_documents_liveliness_tokens_parse_and_rebuild_byte_for_byte(token, kind, node, name, qos):
    entity = Entity.parse(token)
    assert (entity.domain_id, entity.kind, entity.node_name, entity.namespace, entity.name, entity.qos) == \
        (2, kind, node, "/", name, qos)
    assert entity.token == token


def test_a_subscription_token_built_from_its_parts_is_the_documents():
    entity = Entity(domain_id=2, session_id="aac3178e146ba6f1fc6e6a4085e77f21", node_id=0, entity_id=10,
                    kind=EntityKind.SUBSCRIPTION, namespace="/", node_name="listener", name="/chatter",
                    dds_type=dds_type_name("std_msgs/msg/String"), type_hash=STRING_HASH, qos=encode_qos(Qos()))
    assert entity.token == LISTENER_SUB
    talker = Entity(domain_id=2, session_id="8b20917502ee955ac4476e0266340d5c", node_id=0, entity_id=10,
                    kind=EntityKind.PUBLISHER, namespace="/", node_name="talker", name="/chatter",
                    dds_type=STRING_DDS, type_hash=STRING_HASH, qos=encode_qos(Qos(depth=7)))
    assert talker.token == TALKER_PUB


def test_namespaces_and_names_are_mangled_in_tokens():
    entity = Entity(domain_id=0, session_id="ab", node_id=3, entity_id=4, kind=EntityKind.CLIENT,
                    namespace="/robot1/arm", node_name="petrobot_alpha", name="/robot1/arm/fibonacci/_action/send_goal",
                    dds_type="x::action::dds_::F_SendGoal_", type_hash="RIHS01_00", qos="::,10:,:,:,,")
    assert entity.token == ("@ros2_lv/0/ab/3/4/SC/%/%robot1%arm/petrobot_alpha/%robot1%arm%fibonacci%_action%send_goal/"
                            "x::action::dds_::F_SendGoal_/RIHS01_00/::,10:,:,:,,")
    assert Entity.parse(entity.token) == entity
    assert mangle("") == "%" and mangle("/a/b") == "%a%b"
    assert graph_keyexpr(3) == "@ros2_lv/3/**"


@pytest.mark.parametrize("token", [
    "@ros2_lv/0/zid/0/0/NN/%/%",                                  # too short
    "@ros2_lv/0/zid/0/0/XX/%/%/node",                             # unknown kind
    "@ros2_lv/0/zid/0/0/MP/%/%/node",                             # a publisher without its topic
    "@ros2_lv/x/zid/0/0/NN/%/%/node",                             # domain not a number
    "@ros2_lv/0/zid/0//NN/%/%/node",                              # empty chunk
    "@other/0/zid/0/0/NN/%/%/node",                               # not the admin space
])
def test_malformed_tokens_are_refused_with_a_wire_error(token):
    with pytest.raises(Ros2WireError):
        Entity.parse(token)


def test_the_bridges_tokens_parse_with_their_escaped_slashes():
    token = BridgeToken.parse("@/4f2a/@ros2_lv/AS/bot1§fibonacci/example_interfaces§action§Fibonacci")
    assert (token.bridge, token.kind, token.key, token.ros_type) == \
        ("4f2a", "AS", "bot1/fibonacci", "example_interfaces/action/Fibonacci")
    assert BridgeToken.parse("@/4f2a/@ros2_lv/MP/chatter/std_msgs§msg§String/qos").key == "chatter"
    with pytest.raises(Ros2WireError):
        BridgeToken.parse("@/4f2a/@ros2_lv/ZZ/chatter/std_msgs§msg§String")


def test_the_attachment_is_33_bytes_seq_stamp_length_and_gid_little_endian():
    gid = bytes(range(16))
    data = Attachment(sequence_number=1, timestamp_ns=0x0102030405060708, gid=gid).encode()
    assert data == struct.pack("<q", 1) + bytes.fromhex("0807060504030201") + b"\x10" + gid
    assert len(data) == 33
    assert Attachment.decode(data) == Attachment(1, 0x0102030405060708, gid)


def test_an_attachment_as_zenoh_ros2_sdk_echoes_it_decodes():
    # a reply attachment seen from zenoh-ros2-sdk's service server: seq 1, a stamp, 16, the client's GID
    seen = bytes.fromhex("0100000000000000" "00fded909044ea18" "10" "000102030405060708090a0b0c0d0e0f")
    reply = Attachment.decode(seen)
    assert reply.sequence_number == 1 and reply.gid == bytes(range(16))


@pytest.mark.parametrize("data", [b"", bytes(32), bytes(34), bytes(16) + b"\x08" + bytes(16)])
def test_malformed_attachments_are_refused(data):
    with pytest.raises(Ros2WireError):
        Attachment.decode(data)


def test_a_gid_must_be_16_bytes_to_encode():
    with pytest.raises(Ros2WireError):
        Attachment(1, 2, b"short").encode()
    assert len(gid_of("@ros2_lv/0/x")) == 16 and gid_of("a") != gid_of("b")


def test_qos_text_elides_rmw_zenohs_defaults():
    assert encode_qos(Qos()) == "::,10:,:,:,,"
    assert encode_qos(STATUS_QOS) == ":1:,1:,:,:,,"
    assert encode_qos(Qos(reliability=Reliability.BEST_EFFORT, depth=42)) == "2::,:,:,:,,"
    assert decode_qos("::,10:,:,:,,") == Qos()
    assert decode_qos(":1:,1:,:,:,,") == STATUS_QOS
    assert decode_qos("2:2:1,5:1,0:,:1,2,3") == Qos(Reliability.BEST_EFFORT, Durability.VOLATILE, depth=5)


@pytest.mark.parametrize("text", ["", "::,10:,:,:", "::10:,:,:,,", "9::,10:,:,:,,", "::,x:,:,:,,", "::,10:,:,:,"])
def test_malformed_qos_text_is_refused(text):
    with pytest.raises(Ros2WireError):
        decode_qos(text)


def test_qos_tables_of_services_toml_are_checked():
    assert parse_qos({"reliability": "best_effort", "depth": 1}) == Qos(Reliability.BEST_EFFORT, depth=1)
    for bad in ({"depth": 0}, {"reliability": "sometimes"}, {"lifespan": 1}, "fast"):
        with pytest.raises(Ros2ConfigError):
            parse_qos(bad)


def test_action_names_are_rcl_actions():
    names = action_names("/fibonacci")
    assert (names.send_goal, names.cancel_goal, names.get_result, names.feedback, names.status) == (
        "/fibonacci/_action/send_goal", "/fibonacci/_action/cancel_goal", "/fibonacci/_action/get_result",
        "/fibonacci/_action/feedback", "/fibonacci/_action/status")
    types = action_type_names("example_interfaces/action/Fibonacci")
    assert (types.send_goal, types.get_result, types.feedback_message, types.cancel_goal, types.status) == (
        "example_interfaces/action/Fibonacci_SendGoal", "example_interfaces/action/Fibonacci_GetResult",
        "example_interfaces/action/Fibonacci_FeedbackMessage", "action_msgs/srv/CancelGoal",
        "action_msgs/msg/GoalStatusArray")
    assert dds_type_name(types.send_goal) == "example_interfaces::action::dds_::Fibonacci_SendGoal_"


def test_names_are_checked_and_qualified():
    assert qualify("cmd_vel", "/robot1") == "/robot1/cmd_vel"
    assert qualify("/cmd_vel", "/robot1") == "/cmd_vel"
    assert qualify("cmd_vel") == "/cmd_vel"
    for bad in ("", "/a//b", "/a/", "/1a", "~/private", "/a b", "/{node}"):
        with pytest.raises(Ros2ConfigError):
            check_name(bad)
    with pytest.raises(Ros2ConfigError):
        action_names("fibonacci")
    assert split_type("std_msgs/Bool") == ("std_msgs", "msg", "Bool")
    for bad in ("Bool", "std_msgs/msgs/Bool", "Std/msg/Bool", "std_msgs/msg/bool"):
        with pytest.raises(Ros2TypeError):
            split_type(bad)
