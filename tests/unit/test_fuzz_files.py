"""Fuzzing the file readers: mutated net files, PNML models and location files.

Every example net (``nets/*.toml``, ``nets/examples/*.toml``), the Model Checking Contest models of
``tests/data/mcc`` and the location files are mutated (bit flips, truncations, deletions, inserted
bytes and tokens, 10^5-deep nesting, absurd numbers) and read back. The only acceptable outcomes are
a valid net (which must then survive TOML, PNML and DOT export) or a ``NetError`` /
``NetFileError`` / ``LocationError`` whose message starts ``FILE:LINE:`` with a line of the file;
never another exception. The runs are derandomised (the same examples every time) and bounded in
count; ``PETROBOT_FUZZ_EXAMPLES`` raises the count for a longer hunt.
"""

from __future__ import annotations

import os
import re
from datetime import timedelta
from pathlib import Path
from typing import Any

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from coordinator.errors import NetError
from coordinator.netfile import dump_net, load_net, loads_net
from coordinator.netfile.dot import to_dot
from coordinator.netfile.pnml import dump_pnml, load_pnml, loads_pnml
from services.errors import LocationError
from services.location import load_location

ROOT = Path(__file__).resolve().parents[2]
NETS = sorted((ROOT / "nets").glob("*.toml")) + sorted((ROOT / "nets" / "examples").glob("*.toml"))
MODELS = sorted((ROOT / "tests" / "data" / "mcc").glob("*/model.pnml")) + [
    ROOT / "tests" / "data" / "two_pages.pnml", ROOT / "tests" / "data" / "old_dialect.xml"]
LOCATIONS = [ROOT / "services.toml", ROOT / "tests" / "data" / "services_demo.toml"]

EXAMPLES = int(os.environ.get("PETROBOT_FUZZ_EXAMPLES", "250"))
FUZZ = settings(
    max_examples=EXAMPLES,
    derandomize="PETROBOT_FUZZ_EXAMPLES" not in os.environ,  # the suite sees the same examples each run
    database=None,
    deadline=timedelta(seconds=20),  # each example takes milliseconds; this only stops a runaway
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large],
)

TOKENS = [
    b"\x00", b"\xff\xfe", b"\xfe\xff", b"\xef\xbb\xbf", b"\xc3", b"\xed\xa0\x80", b"\r\n", b"\t", b"\x1b",
    b"[", b"]", b"{", b"}", b"[[", b"]]", b'"', b"'", b'"""', b"'''", b"\\", b"\n", b"=", b"#", b".", b",",
    b"inf", b"nan", b"-inf", b"-1", b"0", b"1e999", b"2147483648", b"9223372036854775808",
    b"99999999999999999999999", b"\\u0000", b"\\n", b"1979-05-27T07:32:00Z",
    b"[[place]]\n", b"[net]\n", b"[[transition]]\n", b"[[arc]]\n", b"[task.x]\n", b'id = "p"\n',
    b'inputs = { p = 1 }\n', b'home = { nowhere = 1 }\n', b'[nodes.x]\nhost = "h"\nport = 1\n',
    b"<!DOCTYPE x>", b"<!ENTITY e 'x'>", b"&amp;", b"&e;", b"<page>", b"</page>", b"<place id='z'/>",
    b"<arc id='q' source='z' target='z'/>", b"<toolspecific tool='petrobot' version='1'/>", b"<![CDATA[",
    b"<text>", b"</text>", b"Default,", b"&#0;", b"&#10;",
]
NESTERS = [b"[", b"{a=", b"[{a=", b"<page id='d'>", b"<x>", b"a."]
# Values put in place of a key's value, an attribute's value or a label's text: well-formed enough
# to reach the checks after parsing.
VALUES = [
    b"-1", b"0", b"1", b"2", b"2147483647", b"2147483648", b"-2147483649", b"9223372036854775807",
    b"1.5", b"inf", b"nan", b"-0.0", b"1e308", b"true", b"[]", b"{}", b"[1, 2]", b"{ a = 1 }",
    b'"x"', b'""', b'"p\\u0001"', b'"a\\nb"', b'"' + b"a" * 300 + b'"', b'"ext:tick"', b'"int:a.b"',
    b'"int:sense.ok"', b'"infinite"', b'"exponential"', b'"primitive_task"', b'"resource"', b'"robot"',
    b"{ nowhere = 1 }", b'["ext:a", "ext:a"]', b"1979-05-27", b"x", b"p", b"t", b"Default,-3",
    b"a b", b"&#1;", b"&lt;", b"idle", b"runs_remaining", b"sense", b"ok", b"error",
]

_position = st.integers(min_value=0, max_value=2**32)
_mutation = st.one_of(
    st.tuples(st.just("flip"), _position, st.integers(0, 7)),
    st.tuples(st.just("truncate"), _position),
    st.tuples(st.just("delete"), _position, st.integers(1, 64)),
    st.tuples(st.just("insert"), _position, st.one_of(st.sampled_from(TOKENS), st.binary(min_size=1, max_size=8))),
    st.tuples(st.just("nest"), _position, st.sampled_from(NESTERS), st.sampled_from([2, 63, 64, 65, 300, 5000, 100_000])),
    st.tuples(st.just("repeat_line"), _position, st.integers(2, 50)),
    st.tuples(st.just("value"), _position, st.sampled_from(VALUES)),
    st.tuples(st.just("value"), _position, st.sampled_from(VALUES)),  # twice as likely: most reach the loader
    st.tuples(st.just("move_line"), _position, _position),
)
_mutations = st.lists(_mutation, min_size=1, max_size=4)


def mutate(data: bytes, mutations: list[tuple[Any, ...]]) -> bytes:
    """Apply mutations to a file's bytes; positions are taken modulo the current length."""
    for op, where, *rest in mutations:
        at = where % (len(data) + 1)
        if op == "flip" and data:
            at %= len(data)
            data = data[:at] + bytes([data[at] ^ (1 << rest[0])]) + data[at + 1:]
        elif op == "truncate":
            data = data[:at]
        elif op == "delete":
            data = data[:at] + data[at + rest[0]:]
        elif op == "insert":
            data = data[:at] + rest[0] + data[at:]
        elif op == "nest":
            data = data[:at] + rest[0] * rest[1] + data[at:]
        elif op == "repeat_line":
            start = data.rfind(b"\n", 0, at) + 1
            end = data.find(b"\n", at)
            line = data[start:end + 1 if end >= 0 else len(data)]
            data = data[:start] + line * rest[0] + data[start:]
        elif op == "move_line":
            lines = data.split(b"\n")
            line = lines.pop(where % len(lines))
            lines.insert(rest[0] % (len(lines) + 1), line)
            data = b"\n".join(lines)
        elif op == "value":
            data = _replace_value(data, where, rest[0])
    return data


def _replace_value(data: bytes, which: int, value: bytes) -> bytes:
    """Put ``value`` in place of the value of a TOML key, an XML attribute or a label's text."""
    spots = [m.end() for m in re.finditer(rb'= ?"?|<text>', data)]
    if not spots:
        return data
    at = spots[which % len(spots)]
    if data[at - 1:at] == b'"' and data[at - 2:at - 1] != b" ":  # an attribute: up to its quote
        end = data.find(b'"', at)
    elif data[at - 6:at] == b"<text>":
        end = data.find(b"</text>", at)
    else:
        at -= data[at - 1:at] == b'"'
        end = data.find(b"\n", at)
    return data[:at] + value + data[end if end >= 0 else len(data):]


def assert_located(exc: Exception, path: Path, data: bytes) -> None:
    """The message is ``FILE:LINE: problem`` with a line that exists in the file."""
    message = str(exc)
    match = re.match(re.escape(str(path)) + r":(\d+): \S", message)
    assert match, f"no FILE:LINE: in {message[:300]!r}"
    lines = len(re.split(rb"\r\n|\r|\n", data))  # XML counts a lone CR as a line break too
    assert 1 <= int(match.group(1)) <= lines, message[:300]


@pytest.fixture(scope="module")
def scratch(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return tmp_path_factory.mktemp("fuzz")


def _survives_export(net: Any) -> None:
    """A net that loads can be written as TOML and PNML and read back equal, and drawn."""
    assert loads_net(dump_net(net), interpreted=False) == net
    assert loads_pnml(dump_pnml(net)) == net
    to_dot(net)


@FUZZ
@given(source=st.sampled_from(NETS), mutations=_mutations)
def test_mutated_net_files_load_or_fail_with_file_and_line(scratch: Path, source: Path,
                                                           mutations: list[tuple[Any, ...]]) -> None:
    data = mutate(source.read_bytes(), mutations)
    path = scratch / "net.toml"
    path.write_bytes(data)
    try:
        net = load_net(path)
    except NetError as exc:
        assert_located(exc, path, data)
        return
    _survives_export(net)


@FUZZ
@given(source=st.sampled_from(MODELS), mutations=_mutations)
def test_mutated_pnml_models_load_or_fail_with_file_and_line(scratch: Path, source: Path,
                                                             mutations: list[tuple[Any, ...]]) -> None:
    data = mutate(source.read_bytes(), mutations)
    path = scratch / "model.pnml"
    path.write_bytes(data)
    try:
        net = load_pnml(path)
    except NetError as exc:
        assert_located(exc, path, data)
        return
    _survives_export(net)


@FUZZ
@given(source=st.sampled_from(LOCATIONS), mutations=_mutations)
def test_mutated_location_files_load_or_fail_with_file_and_line(scratch: Path, source: Path,
                                                                mutations: list[tuple[Any, ...]]) -> None:
    data = mutate(source.read_bytes(), mutations)
    path = scratch / "services.toml"
    path.write_bytes(data)
    try:
        load_location(path)
    except LocationError as exc:
        assert_located(exc, path, data)


@FUZZ
@given(text=st.text(max_size=200))
def test_arbitrary_text_loads_or_fails_as_a_net_error(text: str) -> None:
    for load in (loads_net, loads_pnml):
        try:
            load(text, "x")
        except NetError as exc:
            assert str(exc).startswith("x:")
