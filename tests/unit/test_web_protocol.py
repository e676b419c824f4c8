"""Every message a console page sends is checked in one place; a bad one is a violation with a reason
(the server closes that socket with it), never an exception that reaches the run."""

from __future__ import annotations

import json

import pytest

from coordinator.operator import Command
from coordinator.web.protocol import (
    CLOSE_POLICY,
    CLOSE_TOO_BIG,
    MAX_DEPTH,
    MAX_MESSAGE_BYTES,
    PROTOCOL_VERSION,
    ProtocolViolation,
    parse_client_message,
)


def msg(**fields: object) -> str:
    return json.dumps(fields)


def test_hello_with_the_spoken_version_and_a_token_is_accepted():
    m = parse_client_message(msg(type="hello", v=PROTOCOL_VERSION, token="abc"))
    assert m.type == "hello" and m.fields["token"] == "abc"


def test_hello_of_another_version_is_refused_with_a_reason_naming_both_versions():
    with pytest.raises(ProtocolViolation, match="version 2 is not spoken here"):
        parse_client_message(msg(type="hello", v=2))


def test_a_command_becomes_an_operator_command_with_place_and_count():
    m = parse_client_message(msg(type="command", id=3, command="remove", place="runs_remaining", count=2))
    assert (m.id, m.fields["command"], m.fields["place"], m.fields["count"]) == (3, Command.REMOVE, "runs_remaining", 2)


def test_a_command_without_place_count_defaults_and_pause_takes_no_place():
    assert parse_client_message(msg(type="command", id=1, command="insert", place="p")).fields["count"] == 1
    with pytest.raises(ProtocolViolation, match="takes no place"):
        parse_client_message(msg(type="command", id=1, command="pause", place="p"))


@pytest.mark.parametrize("text, reason", [
    ("not json at all", "not JSON"),
    ("[1, 2]", "must be a JSON object"),
    (msg(type=5), "string 'type'"),
    (msg(type="launch_missiles", id=1), "unknown message type"),
    (msg(type="command", id=1, command="explode"), "unknown operator command"),
    (msg(type="command", id=1, command="insert"), "needs a place"),
    (msg(type="command", id=1, command="insert", place="p", count=0), "count must be an integer"),
    (msg(type="command", id=1, command="insert", place="p", count=True), "count must be an integer"),
    (msg(type="command", id=1, command="insert", place="p\nq"), "control character"),
    (msg(type="command", id=-1, command="pause"), "id must be an integer"),
    (msg(type="command", id=1, command="pause", extra=1), "unknown key"),
    (msg(type="validate", id=1), "missing key 'draft'"),
    (msg(type="validate", id=1, draft=[]), "draft must be an object"),
    (msg(type="validate", id=1, draft={"places": {}}), "draft.places must be an array"),
    (msg(type="validate", id=1, draft={"places": [1]}), "objects only"),
    (msg(type="validate", id=1, draft={"wat": 1}), "unknown key"),
    (msg(type="analyze", id=1, draft={}, kind="rm -rf"), "analyze.kind must be one of"),
    (msg(type="save", id=1, draft={}, path=7), "save.path must be a string"),
    ('{"type": "ping", "id": 1, "t": NaN}', "not finite"),
])
def test_malformed_messages_are_violations_with_a_reason(text: str, reason: str):
    with pytest.raises(ProtocolViolation, match=reason) as err:
        parse_client_message(text)
    assert err.value.code == CLOSE_POLICY
    assert len(err.value.reason.encode()) <= 120


def test_a_message_nested_too_deep_is_refused_before_any_recursion_trouble():
    deep = '{"type": "validate", "id": 1, "draft": {"net": ' + "[" * (MAX_DEPTH + 5) + "]" * (MAX_DEPTH + 5) + "}}"
    with pytest.raises(ProtocolViolation, match="nested deeper"):
        parse_client_message(deep)
    very_deep = "[" * 200_000 + "]" * 200_000
    with pytest.raises(ProtocolViolation):
        parse_client_message(very_deep)


def test_an_oversized_message_is_refused_with_the_too_big_close_code():
    with pytest.raises(ProtocolViolation) as err:
        parse_client_message(" " * (MAX_MESSAGE_BYTES + 1))
    assert err.value.code == CLOSE_TOO_BIG


def test_binary_frames_are_not_part_of_the_protocol():
    with pytest.raises(ProtocolViolation, match="binary"):
        parse_client_message(b'{"type": "hello", "v": 1}')


def test_a_long_reason_is_cut_to_fit_a_websocket_close_frame():
    violation = ProtocolViolation("é" * 500)
    assert len(violation.reason.encode("utf-8")) <= 120
