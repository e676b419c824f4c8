"""Interface types from the definition files: RIHS01 hashes against rmw_zenoh's design document and
against rosbags' own Jazzy store, the composed service and action types, CDR bytes, checked fields.
No sockets."""

from __future__ import annotations

import pytest
from rosbags.typesys import Stores, get_typestore

from services.ros2.errors import Ros2FieldError, Ros2TypeError, Ros2WireError
from services.ros2.typestore import DEFINITIONS, TypeStore, load_definitions
from sim.ros2.robot import JAZZY_HASHES


@pytest.fixture(scope="module")
def store() -> TypeStore:
    return TypeStore(load_definitions())


def test_std_msgs_string_hashes_to_the_design_documents_value(store):
    assert store.hash("std_msgs/msg/String") == \
        "RIHS01_df668c740482bbd48fb39d76a70dfd4bd59db1288021743503259e948f6b1a18"


def test_the_add_two_ints_service_hashes_to_the_design_documents_value(store):
    # the hash of the service type (request, response and event messages), not of its request
    assert store.hash("example_interfaces/srv/AddTwoInts") == \
        "RIHS01_e118de6bf5eeb66a2491b5bda11202e7b68f198d6f67922cf30364858239c81a"


def test_the_fibonacci_actions_parts_hash_as_a_jazzy_machine_has_them(store):
    # the values the stand-in robot announces (those of example_interfaces' generated code)
    for name, value in JAZZY_HASHES.items():
        assert store.hash(name) == value, name
    assert store.hash("example_interfaces/action/Fibonacci") == \
        "RIHS01_9508051da1ea4658de144b09bd0690ff3de52104683d847aed764d2915906f51"
    assert store.hash("std_srvs/srv/Trigger") == \
        "RIHS01_eeff2cd6fa5ad9d27cdf4dec64818317839b62f212a91e6b5304b634b2062c5f"


def test_every_shipped_message_hashes_as_rosbags_jazzy_store_does(store):
    jazzy = get_typestore(Stores.ROS2_JAZZY)
    shared = [n for n in store.names() if n in jazzy.types and "/msg/" in n]
    assert len(shared) >= 15
    for name in shared:
        if name == "service_msgs/msg/ServiceEventInfo":
            continue  # rosbags hashes its char[16] as char; rosidl (and this store) as uint8
        assert store.hash(name) == jazzy.hash_rihs01(name), name


def test_char_fields_are_uint8_as_rosidl_makes_them(store):
    assert str(store.fields("service_msgs/msg/ServiceEventInfo")["client_gid"]) == "uint8[16]"


def test_string_hi_encodes_to_the_known_cdr_bytes(store):
    assert store.encode("std_msgs/msg/String", {"data": "hi"}).hex() == "0001000003000000686900"
    assert store.decode("std_msgs/msg/String", bytes.fromhex("0001000003000000686900")) == {"data": "hi"}


def test_the_composed_action_messages_round_trip(store):
    request = {"goal_id": {"uuid": bytes(range(16))}, "goal": {"order": 5}}
    data = store.encode("example_interfaces/action/Fibonacci_SendGoal_Request", request)
    assert data.hex() == "00010000" + bytes(range(16)).hex() + "05000000"
    assert store.decode("example_interfaces/action/Fibonacci_SendGoal_Request", data) == \
        {"goal_id": {"uuid": list(range(16))}, "goal": {"order": 5}}
    reply = {"status": 4, "result": {"sequence": [0, 1, 1, 2, 3, 5]}}
    data = store.encode("example_interfaces/action/Fibonacci_GetResult_Response", reply)
    assert store.decode("example_interfaces/action/Fibonacci_GetResult_Response", data) == reply
    assert store.kind("example_interfaces/action/Fibonacci") == "action"
    assert store.service("example_interfaces/action/Fibonacci_SendGoal").request == \
        "example_interfaces/action/Fibonacci_SendGoal_Request"


@pytest.mark.parametrize("value, path, words", [
    ({}, "goal.order", "missing (int32)"),
    ({"order": "5"}, "goal.order", "expected an integer (int32)"),
    ({"order": True}, "goal.order", "expected an integer"),
    ({"order": 2 ** 31}, "goal.order", "out of range for int32"),
    ({"order": 5, "speed": 1}, "goal.speed", "has no such field (its fields: order)"),
])
def test_a_bad_goal_field_is_an_error_naming_it(store, value, path, words):
    with pytest.raises(Ros2FieldError) as caught:
        store.check("example_interfaces/action/Fibonacci_Goal", value, what="goal")
    assert caught.value.path == path and words in str(caught.value)


def test_nested_and_array_fields_are_checked_by_path(store):
    pose = store.zero("geometry_msgs/msg/PoseStamped")
    pose["pose"]["position"]["x"] = "far"
    with pytest.raises(Ros2FieldError) as caught:
        store.check("geometry_msgs/msg/PoseStamped", pose)
    assert caught.value.path == "pose.position.x"
    with pytest.raises(Ros2FieldError) as caught:
        store.check("unique_identifier_msgs/msg/UUID", {"uuid": [0] * 15 + [256]})
    assert caught.value.path == "uuid[15]" and "out of range for uint8" in str(caught.value)
    with pytest.raises(Ros2FieldError) as caught:
        store.check("unique_identifier_msgs/msg/UUID", {"uuid": bytes(15)})
    assert "exactly 16 elements" in str(caught.value)
    with pytest.raises(Ros2FieldError) as caught:
        store.check("example_interfaces/action/Fibonacci_Result", {"sequence": [1, "2"]})
    assert caught.value.path == "sequence[1]"
    with pytest.raises(Ros2FieldError):
        store.check("std_msgs/msg/String", {"data": "nul\x00inside"})


def test_fill_gives_missing_fields_their_defaults(store):
    assert store.zero("geometry_msgs/msg/Quaternion") == {"x": 0.0, "y": 0.0, "z": 0.0, "w": 1.0}
    data = store.encode("geometry_msgs/msg/PoseStamped", {"header": {"frame_id": "map"}}, fill=True)
    pose = store.decode("geometry_msgs/msg/PoseStamped", data)
    assert pose["header"]["frame_id"] == "map" and pose["pose"]["orientation"]["w"] == 1.0


def test_garbage_bytes_are_a_wire_error_not_a_crash(store):
    with pytest.raises(Ros2WireError):
        store.decode("example_interfaces/action/Fibonacci_GetResult_Response", b"\x00\x01\x00\x00\xff\xff")


def test_an_unknown_type_says_which_packages_are_known(store):
    with pytest.raises(Ros2TypeError, match="nav2_msgs/action/NavigateToPose.*known packages"):
        store.fields("nav2_msgs/action/NavigateToPose")


def test_a_labs_own_definitions_directory_adds_types(tmp_path):
    (tmp_path / "lab_msgs" / "action").mkdir(parents=True)
    (tmp_path / "lab_msgs" / "msg").mkdir(parents=True)
    (tmp_path / "lab_msgs" / "msg" / "Target.msg").write_text("string name\nfloat64 x\n")
    (tmp_path / "lab_msgs" / "action" / "Reach.action").write_text(
        "Target target  # same package\ngeometry_msgs/Point offset\n---\nbool reached\n---\nfloat32 distance\n")
    store = TypeStore(load_definitions([DEFINITIONS, tmp_path]))
    fields = store.fields("lab_msgs/action/Reach_Goal")
    assert str(fields["target"]) == "lab_msgs/msg/Target" and str(fields["offset"]) == "geometry_msgs/msg/Point"
    assert store.hash("lab_msgs/action/Reach_SendGoal").startswith("RIHS01_")


@pytest.mark.parametrize("definitions, words", [
    ({"lab_msgs/msg/A": "Missing m\n"}, "'lab_msgs/msg/Missing', which is not defined"),
    ({"lab_msgs/srv/S": "int32 a\n"}, "expected 2 parts"),
    ({"lab_msgs/action/A": "int32 a\n---\nint32 b\n"}, "expected 3 parts"),
    ({"lab_msgs/msg/W": "wstring w\n"}, "wstring fields are not supported"),
    ({"lab_msgs/msg/D": "float64 x not_a_number\n"}, "default of field 'x'"),
])
def test_malformed_definitions_are_type_errors(definitions, words):
    with pytest.raises(Ros2TypeError, match=words):
        TypeStore(definitions)


def test_a_missing_interface_directory_is_named(tmp_path):
    with pytest.raises(Ros2TypeError, match="does not exist"):
        load_definitions([tmp_path / "absent"])
