"""The ``ros2`` tables of services.toml: sessions (endpoints, TLS, plaintext refusal), actions and
events, their errors with file and line, and their check against the interface types. No sockets."""

from __future__ import annotations

from pathlib import Path

import pytest

from services.errors import LocationError
from services.location import parse_location
from services.results import Status
from services.ros2.config import (
    ActionKind,
    SessionSettings,
    check_action_types,
    check_event_types,
    endpoint_problems,
    parse_action_spec,
    parse_event_spec,
    parse_session,
    zenoh_config,
)
from services.ros2.errors import Ros2ConfigError
from services.ros2.graph import Dialect
from services.ros2.typestore import TypeStore, load_definitions

NODE = """
[nodes.robot]
host = "127.0.0.1"
port = 7300
"""


@pytest.fixture(scope="module")
def store() -> TypeStore:
    return TypeStore(load_definitions())


def test_the_session_defaults_follow_rmw_zenoh():
    settings = parse_session({})
    assert (settings.dialect, settings.domain_id, settings.mode, settings.connect) == \
        (Dialect.RMW_ZENOH, 0, "peer", ("tcp/127.0.0.1:7447",))
    config = zenoh_config(settings)
    assert config["scouting/multicast/enabled"] is False and config["scouting/gossip/enabled"] is True
    assert config["listen/endpoints"] == ["tcp/127.0.0.1:0"]
    assert settings.ros_node_name("alpha-1") == "petrobot_alpha_1"


def test_a_plaintext_endpoint_off_the_loopback_is_refused_unless_allowed():
    with pytest.raises(Ros2ConfigError, match="plaintext and not on the loopback.*allow_plaintext"):
        parse_session({"connect": ["tcp/192.168.1.20:7447"]})
    with pytest.raises(Ros2ConfigError, match="listen endpoint"):
        parse_session({"listen": ["tcp/0.0.0.0:0"]})
    allowed = parse_session({"connect": ["tcp/192.168.1.20:7447"], "allow_plaintext": True})
    assert endpoint_problems(allowed) == ["connect endpoint 'tcp/192.168.1.20:7447' is plaintext and not on the loopback"]
    for fine in (["tcp/localhost:7447"], ["tcp/[::1]:7447"], ["tls/router.lab:7447"], ["quic/10.0.0.1:7447"]):
        parse_session({"connect": fine, "tls": {"root_ca": "ca.pem"}})
    client = parse_session({"mode": "client", "listen": ["tcp/0.0.0.0:0"], "connect": ["tcp/127.0.0.1:7447"]})
    assert endpoint_problems(client) == []  # a client listens nowhere


def test_tls_and_user_password_make_the_zenoh_configuration(tmp_path):
    settings = parse_session({"connect": ["tls/router.lab:7447"], "tls": {"root_ca": "ca.pem", "cert": "me.pem",
                                                                         "key": "me.key"},
                              "user": "petrobot", "password_file": "zenoh.pass"}, directory=str(tmp_path))
    config = zenoh_config(settings, "secret")
    assert config["transport/link/tls/root_ca_certificate"] == str(tmp_path / "ca.pem")
    assert config["transport/link/tls/connect_certificate"] == str(tmp_path / "me.pem")
    assert config["transport/link/tls/enable_mtls"] is True
    assert (config["transport/auth/usrpwd/user"], config["transport/auth/usrpwd/password"]) == ("petrobot", "secret")


@pytest.mark.parametrize("table, words", [
    ({"dialect": "dds"}, "dialect must be one of"),
    ({"domain_id": 300}, "domain_id must be an integer in 0..232"),
    ({"mode": "router"}, "mode must be"),
    ({"connect": "tcp/127.0.0.1:7447"}, "must be a list"),
    ({"connect": ["serial/ttyUSB0"]}, "unknown protocol"),
    ({"connect": ["127.0.0.1:7447"]}, "not a Zenoh endpoint"),
    ({"tls": {"cert": "a.pem"}}, "tls needs root_ca"),
    ({"tls": {"root_ca": "ca.pem", "cert": "a.pem"}}, "both cert and key"),
    ({"password_file": "p"}, "password_file needs user"),
    ({"namespace": "robot1"}, "must be absolute"),
    ({"node_name": "my node"}, "node_name must be"),
    ({"colour": "blue"}, "unknown key"),
])
def test_malformed_session_tables_are_refused(table, words):
    with pytest.raises(Ros2ConfigError, match=words):
        parse_session(table)


def test_action_tables_parse_by_kind():
    action = parse_action_spec({"action": "/fibonacci", "type": "example_interfaces/action/Fibonacci",
                                "success": "len(sequence) > 0", "aborted": "error", "cancel_wait_s": 2}, "[a]")
    assert (action.kind, action.name, action.aborted, action.cancel_wait_s) == \
        (ActionKind.ACTION, "/fibonacci", Status.ERROR, 2.0)
    service = parse_action_spec({"service": "add_two_ints", "type": "example_interfaces/srv/AddTwoInts"}, "[a]")
    assert (service.kind, service.name) == (ActionKind.SERVICE, "add_two_ints")
    publish = parse_action_spec({"publish": "/cmd_vel", "type": "geometry_msgs/msg/Twist", "rate_hz": 10,
                                 "until": {"topic": "/arrived", "type": "std_msgs/msg/Bool", "when": "data"}}, "[a]")
    assert publish.kind == ActionKind.PUBLISH and publish.until is not None and publish.until.topic == "/arrived"
    wait = parse_action_spec({"until": {"topic": "/arrived", "type": "std_msgs/msg/Bool"}}, "[a]")
    assert wait.kind == ActionKind.WAIT


@pytest.mark.parametrize("table, words", [
    ({"action": "/f", "service": "/g", "type": "a/action/B"}, "one of action, service and publish"),
    ({"type": "std_msgs/msg/Bool"}, "needs action"),
    ({"action": "/f", "type": "example_interfaces/srv/AddTwoInts"}, "is a srv type, a action type is needed"),
    ({"service": "/f", "type": "example_interfaces/srv/AddTwoInts", "aborted": "error"}, "only apply to"),
    ({"publish": "/f", "type": "std_msgs/msg/Bool", "success": "data"}, "success only applies"),
    ({"action": "/f", "type": "x/action/Y", "success": "len("}, "success: condition"),
    ({"publish": "/f", "type": "std_msgs/msg/Bool", "duration_s": 2}, "duration_s needs rate_hz"),
    ({"publish": "/f", "type": "std_msgs/msg/Bool", "rate_hz": 0}, "rate_hz must be a number above 0"),
    ({"action": "f//g", "type": "x/action/Y"}, "not a ROS 2 name"),
    ({"action": "/f", "type": "x/action/Y", "aborted": "maybe"}, "aborted must be"),
])
def test_malformed_action_tables_are_refused(table, words):
    with pytest.raises(Ros2ConfigError, match=words):
        parse_action_spec(table, "[actions.a]: ros2")


def test_event_tables_parse_and_are_checked():
    event = parse_event_spec({"topic": "/crossfire", "type": "std_msgs/msg/Bool", "when": "data == true",
                              "fields": ["data"]}, "[e]")
    assert event.when is not None and event.fields == ("data",) and event.edge == "rising"
    with pytest.raises(Ros2ConfigError, match="edge must be"):
        parse_event_spec({"topic": "/x", "type": "std_msgs/msg/Bool", "edge": "falling"}, "[e]")


def test_services_toml_places_ros2_actions_events_and_their_driver():
    location = parse_location(NODE + """
[ros2]
domain_id = 4
[nodes.robot.ros2]
node_name = "bench_robot"
[actions.fibonacci]
node = "robot"
deadline_s = 20.0
ros2 = { action = "/fibonacci", type = "example_interfaces/action/Fibonacci" }
[events.crossfire]
node = "robot"
ros2 = { topic = "/crossfire", type = "std_msgs/msg/Bool", when = "data" }
""")
    placement = location.actions["fibonacci"]
    assert placement.impl == "services.ros2.actions:Ros2Primitive" and placement.ros2 is not None
    assert location.drivers["ros2.robot"].impl == "services.ros2.driver:Ros2Driver"
    assert location.nodes["robot"].ros2 == SessionSettings(domain_id=4, node_name="bench_robot")
    assert location.ros2_events["crossfire"].topic == "/crossfire"
    assert location.publisher_of("crossfire") == "robot"


@pytest.mark.parametrize("text, line, words", [
    ('[actions.f]\nnode = "robot"\nros2 = { action = "/f" }\n', 7, "type must be a ROS 2 interface type"),
    ('[ros2]\nconnect = ["tcp/10.0.0.9:7447"]\n', 5, "plaintext"),
    ('[events.e]\nnode = "robot"\nros2 = { topic = "/e", type = "std_msgs/msg/Bool", when = "data ==" }\n', 7,
     "when: condition"),
    ('[drivers."ros2.robot"]\nnode = "robot"\nimpl = "a:b"\n[actions.f]\nnode = "robot"\n'
     'ros2 = { service = "/f", type = "std_srvs/srv/Trigger" }\n', 5, "reserved"),
])
def test_a_bad_ros2_table_is_reported_with_file_and_line(text, line, words):
    with pytest.raises(LocationError) as caught:
        parse_location(NODE + text, path="services.toml")
    assert str(caught.value).startswith(f"services.toml:{line}:") and words in str(caught.value)


def test_specs_are_checked_against_the_types(store):
    good = parse_action_spec({"action": "/f", "type": "example_interfaces/action/Fibonacci",
                              "success": "len(sequence) > 1"}, "[a]")
    check_action_types(good, store, "[a]")
    bad = parse_action_spec({"action": "/f", "type": "example_interfaces/action/Fibonacci",
                             "success": "sequense[0] == 0"}, "[a]")
    with pytest.raises(Ros2ConfigError, match="has no field 'sequense'"):
        check_action_types(bad, store, "[a]")
    unknown = parse_action_spec({"action": "/nav", "type": "nav2_msgs/action/NavigateToPose"}, "[a]")
    with pytest.raises(Ros2ConfigError, match="unknown interface type"):
        check_action_types(unknown, store, "[a]")
    deep = parse_event_spec({"topic": "/pose", "type": "geometry_msgs/msg/PoseStamped",
                             "when": "pose.position.z.w > 0"}, "[e]")
    with pytest.raises(Ros2ConfigError, match="is a float64"):
        check_event_types(deep, store, "[e]")
    fields = parse_event_spec({"topic": "/c", "type": "std_msgs/msg/Bool", "fields": ["value"]}, "[e]")
    with pytest.raises(Ros2ConfigError, match="fields reads 'value'"):
        check_event_types(fields, store, "[e]")


def test_petrobot_check_names_a_bad_goal_field_of_the_net_and_a_bad_condition_of_services_toml(tmp_path, capsys):
    from coordinator.cli import main

    root = Path(__file__).resolve().parents[2]
    net = tmp_path / "ros2.toml"
    net.write_text((root / "nets" / "ros2.toml").read_text().replace("order = 10", 'order = "ten"'))
    assert main(["check", str(net), "--services", str(root / "services.toml")]) == 2
    said = "".join(capsys.readouterr())
    assert "task 'count': the parameters of ROS 2 action 'fibonacci' do not fit " \
           "example_interfaces/action/Fibonacci_Goal: goal field 'goal.order': expected an integer (int32)" in said
    services = tmp_path / "services.toml"
    services.write_text((root / "services.toml").read_text().replace("len(sequence) > 1", "len(sequense) > 1"))
    assert main(["check", "--services-only", "--services", str(services)]) == 2
    said = "".join(capsys.readouterr())
    assert f"{services}:" in said and "[actions.fibonacci]: ros2: success reads 'sequense'" in said
    assert main(["check", str(root / "nets" / "ros2.toml"), "--services", str(root / "services.toml")]) == 0


def test_the_goal_ledger_survives_the_process_and_a_damaged_one_is_ignored(tmp_path):
    from services.ros2.driver import GoalLedger

    ledger = GoalLedger(tmp_path / "state" / "ros2-goals.json")
    ledger.add("ab" * 16, "/fibonacci")
    ledger.add("cd" * 16, "/navigate")
    ledger.remove("cd" * 16)
    assert GoalLedger(ledger.path).left_over() == {"ab" * 16: "/fibonacci"}
    ledger.clear()
    assert GoalLedger(ledger.path).left_over() == {}
    ledger.path.write_text("{not json")
    assert GoalLedger(ledger.path).left_over() == {}
    assert GoalLedger(tmp_path / "absent.json").left_over() == {}
