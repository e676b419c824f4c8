"""Hostile input files: every one gets ``FILE:LINE: problem``, exit status 2 and nothing written.

Samples small enough to keep are in ``tests/data/hostile/``; the big ones (10^5-deep nesting,
5,000 nested PNML pages, files over the size cap) are generated here.
"""

from __future__ import annotations

import argparse
import os
import socket
from pathlib import Path

import pytest

from coordinator.cli import main as petrobot
from coordinator.commands import check as check_cmd
from coordinator.commands import export as export_cmd
from coordinator.errors import NetError, NetFileError
from coordinator.netfile import lint_net, load_any, load_net, loads_net
from coordinator.netfile.limits import MAX_COUNT, MAX_NAME
from coordinator.netfile.pnml import MAX_XML_DEPTH, load_pnml, loads_pnml
from services.errors import LocationError
from services.location import load_location, parse_location
from services.location_check import check_location_file
from services.textfile import MAX_FILE_BYTES
from services.tomllines import MAX_DEPTH, TomlLines, parse_toml

ROOT = Path(__file__).resolve().parents[2]
HOSTILE = ROOT / "tests" / "data" / "hostile"
DEMO = ROOT / "nets" / "demo.toml"
SERVICES = ROOT / "tests" / "data" / "services_demo.toml"
PTNET = "http://www.pnml.org/version-2009/grammar/ptnet"

# (sample, line, words of the problem)
SAMPLES = [
    ("22_tokens_negative.toml", 10, "place 'robot' has a negative initial marking (-1)"),
    ("empty.toml", 1, "no net in this file: it has no [net] table"),
    ("only_comments.toml", 1, "no net in this file: it has no [net] table"),
    ("utf16_bom.toml", 1, "not UTF-8 text: the file starts with a UTF-16 byte-order mark"),
    ("utf16_no_bom.toml", 1, "not UTF-8 text: NUL bytes throughout"),
    ("latin1.toml", 2, "not UTF-8 text: byte 0xe9 at column 12"),
    ("nul_byte.toml", 5, "NUL character at column 18"),
    ("nul_in_name.toml", 2, "NUL character in the string net.name"),
    ("newline_in_id.toml", 5, "bad place id 'p\\n'"),
    ("tokens_too_large.toml", 6, "initial marking of place 'p' is 2147483648; the limit is 2147483647"),
    ("weight_infinite.toml", 10, "weight of transition 't' is inf; it must be a finite number"),
    ("billion_laughs.pnml", 2, "a document type declaration (<!DOCTYPE>) is not allowed"),
    ("external_entity.pnml", 2, "a document type declaration (<!DOCTYPE>) is not allowed"),
    ("utf16_bom.pnml", 1, "not UTF-8 text: the file starts with a UTF-16 byte-order mark"),
]


def _args(command: object, argv: list[str]) -> argparse.Namespace:
    parser = argparse.ArgumentParser(prog="petrobot")
    sub = parser.add_subparsers(dest="command")
    command.add_parser(sub)  # type: ignore[attr-defined]
    return parser.parse_args(argv)


def _net(places: str = '[[place]]\nid = "p"\ntokens = 1\n', rest: str = "") -> str:
    return f'[net]\nname = "n"\n\n{places}\n{rest}'


# ----------------------------------------------------------------------------------- the samples
@pytest.mark.parametrize(("sample", "line", "words"), SAMPLES, ids=[s[0] for s in SAMPLES])
def test_each_hostile_sample_is_refused_with_its_file_line_and_problem(sample: str, line: int, words: str) -> None:
    path = HOSTILE / sample
    with pytest.raises(NetError) as info:
        load_any(path)
    assert (info.value.path, info.value.line) == (str(path), line)
    assert words in info.value.problem
    assert str(info.value).startswith(f"{path}:{line}: ")


@pytest.mark.parametrize(("sample", "line", "words"), SAMPLES, ids=[s[0] for s in SAMPLES])
def test_check_prints_file_line_problem_for_each_sample_and_exits_2(
        sample: str, line: int, words: str, capsys: pytest.CaptureFixture[str]) -> None:
    path = HOSTILE / sample
    assert check_cmd.run(_args(check_cmd, ["check", str(path), "--services", str(SERVICES)])) == 2
    out = capsys.readouterr().out.splitlines()
    assert len(out) == 1 and out[0].startswith(f"{path}:{line}: ") and words in out[0]


def test_a_negative_token_count_is_the_only_problem_not_a_cascade_of_unknown_places() -> None:
    text = (HOSTILE / "22_tokens_negative.toml").read_text()
    net, problems = lint_net(text, "22.toml")
    assert net is None
    assert [(p.line, p.problem) for p in problems] == [(10, "place 'robot' has a negative initial marking (-1)")]


def test_a_broken_transition_does_not_make_its_arcs_report_an_unknown_end() -> None:
    text = _net(rest='[[transition]]\nid = "t"\nweight = -1\n\n[[arc]]\nfrom = "p"\nto = "t"\n')
    _, problems = lint_net(text)
    assert [p.problem for p in problems] == ["transition 't' has weight -1; weights must be > 0"]


def test_a_duplicate_id_is_reported_even_when_the_first_element_is_broken() -> None:
    text = _net('[[place]]\nid = "p"\ntokens = -1\n\n[[place]]\nid = "p"\n')
    _, problems = lint_net(text)
    assert [p.problem for p in problems] == ["place 'p' has a negative initial marking (-1)", "duplicate place id 'p'"]


def test_a_net_without_places_says_so_at_its_net_table() -> None:
    with pytest.raises(NetError, match="the net has no places") as info:
        loads_net('# a header only\n[net]\nname = "x"\n')
    assert info.value.line == 2


# ----------------------------------------------------------------------------------- big TOML
@pytest.mark.parametrize("value", [
    "[" * 100_000 + "]" * 100_000,
    "{ a = " * 100_000 + "1" + " }" * 100_000,
    "[{ a = " * 50_000 + "1" + " }]" * 50_000,
])
def test_nesting_100000_deep_is_refused_before_tomllib_recurses(value: str) -> None:
    text = _net(rest=f'[task.t]\nactions = ["a"]\nparams.deep = {value}\n')
    with pytest.raises(NetFileError, match=f"nesting deeper than {MAX_DEPTH} levels") as info:
        loads_net(text, "deep.toml")
    assert info.value.line == text.splitlines().index(f"params.deep = {value}") + 1


def test_nesting_that_opens_on_one_line_and_deepens_over_many_is_refused_at_the_line_that_crosses_the_limit() -> None:
    text = "x = [\n" + "[\n" * 200 + "]\n" * 200 + "]\n"
    with pytest.raises(NetFileError, match="nesting deeper") as info:
        loads_net(text)
    assert info.value.line == MAX_DEPTH  # the key x is level 1, the array of line k level k + 1


def test_a_dotted_key_or_table_header_of_100000_parts_is_refused() -> None:
    # tomllib takes time quadratic in the parts of a key even to refuse it: the scan refuses first,
    # also when no '=' follows and inside an inline table
    for text in ("a" + ".a" * 100_000 + " = 1\n", "[" + "a." * 100_000 + "a]\n", "a." * 100_000 + "[\n",
                 "x = { " + "a . " * 100_000 + "a = 1 }\n"):
        with pytest.raises(NetFileError, match="nesting deeper") as info:
            loads_net(text)
        assert info.value.line == 1


def test_nesting_at_the_limit_still_loads_as_a_parameter() -> None:
    depth = MAX_DEPTH - 4  # params.deep sits under task.t, itself 2 deep, plus the key
    value = "[" * depth + "1" + "]" * depth
    net = loads_net(_net(rest=f'[task.t]\nactions = ["a"]\nparams.deep = {value}\n'))
    assert net.tasks["t"].actions[0].params["deep"]


@pytest.mark.parametrize("number", ["9" * 5000, "0x" + "f" * 5000, "1" + "_0" * 3000])
def test_a_5000_digit_integer_is_refused_with_its_line_not_a_bare_value_error(number: str) -> None:
    text = _net(f'[[place]]\nid = "p"\ntokens = {number}\n')
    with pytest.raises(NetFileError, match="a bare value of more than") as info:
        loads_net(text)
    assert info.value.line == 6


def test_an_integer_beyond_64_bits_is_refused_wherever_it_is() -> None:
    with pytest.raises(NetFileError, match="out of range: TOML integers are 64-bit") as info:
        loads_net(_net(rest='[task.t]\nactions = ["a"]\nparams = { n = 99999999999999999999 }\n'))
    assert info.value.line == 10


def test_a_file_over_the_size_cap_is_refused_before_it_is_read(tmp_path: Path) -> None:
    for name in ("big.toml", "big.pnml"):
        path = tmp_path / name
        with open(path, "wb") as fh:
            fh.truncate(MAX_FILE_BYTES + 1)  # sparse: nothing of it is on disk
        with pytest.raises(NetFileError, match="net file too large: 16777217 bytes") as info:
            load_any(path)
        assert info.value.path == str(path)
    with pytest.raises(NetFileError, match="too large"):
        loads_net(" " * (MAX_FILE_BYTES + 1))


def test_analyze_reads_a_pnml_file_over_16_mib_and_refuses_one_over_its_own_cap(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = tmp_path / "big.pnml"
    with open(path, "wb") as fh:
        fh.truncate(MAX_FILE_BYTES + 1)  # sparse: nothing of it is on disk
    with pytest.raises(NetFileError, match="not UTF-8 text: NUL bytes throughout"):
        load_any(path, max_pnml_bytes=32 * 2**20)  # read (then refused for what it holds, not its size)
    assert petrobot(["analyze", str(path), "--max-file-size", "16M"]) == 2
    assert "net file too large: 16777217 bytes (the limit is 16 MiB)" in capsys.readouterr().err


def test_a_fifo_a_device_or_a_directory_is_refused_without_reading(tmp_path: Path) -> None:
    fifo = tmp_path / "net.toml"
    os.mkfifo(fifo)  # opening it for reading would block until a writer comes
    with pytest.raises(NetFileError, match="not a regular file"):
        load_net(fifo)
    with pytest.raises(NetFileError, match="not a regular file"):
        load_pnml("/dev/zero")
    with pytest.raises(NetFileError, match="a directory"):
        load_net(tmp_path)
    with pytest.raises(LocationError, match="not a regular file"):
        load_location(fifo)


# ----------------------------------------------------------------------------------- names, numbers
@pytest.mark.parametrize(("edit", "words"), [
    (("id = \"p\"", "id = \"p\\u0007\""), "bad place id"),
    (("id = \"p\"", f"id = \"{'p' * (MAX_NAME + 1)}\""), f"the limit is {MAX_NAME}"),
    (('name = "n"', 'name = "two\\nlines"'), "name of [net] holds the control character '\\n'"),
    (('name = "n"', f'name = "{"n" * (MAX_NAME + 1)}"'), f"the limit is {MAX_NAME}"),
    (("tokens = 1", 'tokens = 1\nlabel = "a\\u001bb"'), "label of place 'p' holds the control character"),
    (("tokens = 1", f"tokens = {MAX_COUNT + 1}"), f"the limit is {MAX_COUNT}"),
    (("tokens = 1", f"tokens = 1\ncapacity = {MAX_COUNT + 1}"), "capacity of place 'p'"),
    (('name = "n"', f'name = "n"\nhome = {{ p = {MAX_COUNT + 1} }}'), "home of [net]: token count"),
])
def test_names_with_control_characters_or_absurd_lengths_and_counts_beyond_2_31_are_refused(
        edit: tuple[str, str], words: str) -> None:
    text = _net().replace(*edit)
    with pytest.raises(NetError) as info:
        loads_net(text, "n.toml")
    assert words in info.value.problem
    assert info.value.line is not None


@pytest.mark.parametrize(("key", "words"), [
    ("weight = nan", "weight of transition 't' is nan; it must be a finite number"),
    ("weight = inf", "it must be a finite number"),
    ('kind = "exponential"\nrate = inf', "rate of transition 't' is inf"),
    (f"priority = {2**31}", "priorities lie in"),
    (f"servers = {2**31}", "servers of transition 't'"),
    (f"inputs = {{ p = {2**31} }}", "weight of input arc p -> t"),
    ('events = ["ext:tick\\n"]', "bad event name"),
])
def test_transition_numbers_must_be_finite_and_within_32_bits(key: str, words: str) -> None:
    with pytest.raises(NetError) as info:
        loads_net(_net(rest=f'[[transition]]\nid = "t"\n{key}\n'))
    assert words in info.value.problem and info.value.line is not None


@pytest.mark.parametrize(("entry", "words"), [
    ('actions = [{ name = "a", cost = inf }]', "must be a finite number >= 0"),
    ('actions = [{ name = "a", cost = nan }]', "must be a finite number >= 0"),
    ('actions = ["a"]\ndeadline_s = inf', "deadline_s of [task.t] is inf"),
    ('actions = ["a\\nb"]', "bad action of [task.t] id"),
])
def test_task_numbers_must_be_finite_and_action_names_whole_ids(entry: str, words: str) -> None:
    with pytest.raises(NetError) as info:
        loads_net(_net(rest=f"[task.t]\n{entry}\n"))
    assert words in info.value.problem and info.value.line is not None


# ----------------------------------------------------------------------------------- PNML
def _pnml(body: str, net_children: str = "") -> str:
    return (f'<pnml><net id="n" type="{PTNET}">{net_children}'
            f'<page id="top"><place id="p"/>{body}</page></net></pnml>')


def test_pnml_with_5000_nested_pages_is_refused_with_a_line() -> None:
    text = _pnml("\n".join(f'<page id="g{i}">' for i in range(5000)) + "</page>" * 5000)
    with pytest.raises(NetFileError, match=f"elements nested deeper than {MAX_XML_DEPTH} levels") as info:
        loads_pnml(text, "pages.pnml")
    assert info.value.line == MAX_XML_DEPTH - 2  # pnml, net, page "top" open on line 1


def test_pnml_with_200_nested_pages_loads_every_node() -> None:
    opening = "".join(f'<page id="g{i}"><place id="q{i}"/>' for i in range(200))
    net = loads_pnml(_pnml(opening + "</page>" * 200))
    assert len(net.places) == 201


def test_pnml_tool_specific_params_nested_5000_deep_are_refused_at_their_element() -> None:
    deep = "{ a = " * 5000 + "1" + " }" * 5000
    tool = (f'<toolspecific tool="petrobot" version="1"><tasks><task name="t">\n'
            f'<action name="a"><params>{deep}</params></action></task></tasks></toolspecific>')
    with pytest.raises(NetError, match="<params> does not hold a TOML inline table: nesting deeper") as info:
        loads_pnml(_pnml("", tool))
    assert info.value.line == 2


def test_pnml_tool_specific_params_cannot_smuggle_other_toml_keys() -> None:
    tool = ('<toolspecific tool="petrobot" version="1"><tasks><task name="t">'
            '<action name="a"><params>{ a = 1 }\nextra = 2</params></action></task></tasks></toolspecific>')
    with pytest.raises(NetError, match="does not hold a TOML inline table"):
        loads_pnml(_pnml("", tool))


def test_pnml_billion_laughs_is_refused_without_expanding_an_entity() -> None:
    with pytest.raises(NetFileError, match="not allowed in PNML: entities are not expanded") as info:
        load_pnml(HOSTILE / "billion_laughs.pnml")
    assert "haha" not in str(info.value)


def test_pnml_external_entity_is_refused_without_reading_the_file(tmp_path: Path) -> None:
    secret = tmp_path / "secret.txt"
    secret.write_text("the-secret-content")
    text = (f'<?xml version="1.0"?>\n<!DOCTYPE pnml [<!ENTITY s SYSTEM "file://{secret}">]>\n'
            f'<pnml><net id="n" type="{PTNET}"><name><text>&s;</text></name>'
            '<page id="g"><place id="p"/></page></net></pnml>')
    with pytest.raises(NetFileError, match="document type declaration") as info:
        loads_pnml(text)
    assert "the-secret-content" not in str(info.value)


@pytest.mark.parametrize(("fragment", "words"), [
    ('<place id="big"><initialMarking><text>2147483648</text></initialMarking></place>', "the limit is"),
    ('<place id="big"><initialMarking><text>' + "9" * 5000 + "</text></initialMarking></place>",
     "is not an integer"),
    ('<place id="lbl"><name><text>' + "x" * 2000 + "</text></name></place>", "the limit is 1024"),
    ('<transition id="t"><toolspecific tool="petrobot" version="1" weight="inf"/></transition>',
     "it must be a finite number"),
    ('<transition id="t"><toolspecific tool="petrobot" version="1" priority="9999999999"/></transition>',
     "the limit is"),
    (('<transition id="t"><toolspecific tool="petrobot" version="1"><event name="ext:a b"/>'
      "</toolspecific></transition>"), "bad event name"),
    ('<place id="p&#10;"/>', "bad place id"),
])
def test_pnml_values_obey_the_same_limits_as_toml(fragment: str, words: str) -> None:
    with pytest.raises(NetError) as info:
        loads_pnml(_pnml(fragment), "x.pnml")
    assert words in info.value.problem and info.value.line == 1


def test_pnml_declaring_an_unknown_or_other_encoding_is_read_as_the_utf8_it_was_checked_to_be() -> None:
    for encoding in ("ttf-8", "ISO-8859-1", "UTF-16"):
        text = f'<?xml version="1.0" encoding="{encoding}"?>\n' + _pnml('<place id="c"><name><text>café</text></name></place>')
        net = loads_pnml(text.encode(), "e.pnml")
        assert net.places[1].label == "café"


def test_pnml_text_with_a_nul_or_a_lone_surrogate_is_refused() -> None:
    for text in (_pnml("\0"), _pnml("\ud800")):
        with pytest.raises(NetFileError, match="NUL|surrogate"):
            loads_pnml(text)


def test_pnml_interpretation_problems_name_the_line_of_the_element() -> None:
    text = ('<pnml><net id="n" type="' + PTNET + '">\n'
            '<toolspecific tool="petrobot" version="1"><tasks><task name="t"><action name="a"/></task></tasks>'
            '</toolspecific>\n<page id="g">\n'
            '<place id="w"><toolspecific tool="petrobot" version="1" kind="primitive_task" task="t"/></place>\n'
            "</page></net></pnml>")
    with pytest.raises(NetError, match="has no normal exit") as info:
        loads_pnml(text, "i.pnml", interpreted=True)
    assert info.value.line == 4


# ----------------------------------------------------------------------------------- the TOML scanner
def test_toml_lines_index_arrays_of_tables_and_follow_dotted_keys() -> None:
    text = '[[a]]\nx = 1\n[[a]]\ny.z = 2\n[[a.b]]\nk = "[not a bracket"\n[c]\n"q.d" = [\n 1,\n]\nafter = 3\n'
    lines = TomlLines.scan(text)
    assert lines.exact(("a", 0, "x")) == 2
    assert lines.exact(("a", 1, "y", "z")) == 4
    assert lines.exact(("a", 1, "b", 0, "k")) == 6
    assert lines.exact(("c", "q.d")) == 8 and lines.exact(("c", "after")) == 11
    assert lines.line("a", 1, "nowhere") == 3


def test_the_net_loader_and_the_location_file_share_one_toml_line_map() -> None:
    from coordinator.netfile import source_map
    from services import location

    assert source_map.TomlLines is TomlLines and location.parse_toml is parse_toml


# ----------------------------------------------------------------------------------- services.toml
GOOD_SERVICES = """\
[nodes.alpha]
host = "127.0.0.1"
port = 7101

[actions.echo]
node = "alpha"
impl = "services.actions.demo:echo"
"""


@pytest.mark.parametrize(("edit", "line", "words"), [
    (("port = 7101", "port = 0"), 3, "port must be an integer in 1..65535"),
    (('host = "127.0.0.1"', 'host = "300.1.2.3"'), 2, "is not a valid IP address"),
    (('host = "127.0.0.1"', 'host = "bad host!"'), 2, "neither an IP address nor a host name"),
    (('node = "alpha"', 'node = "beta"'), 6, "unknown node 'beta'"),
    (('impl = "services.actions.demo:echo"', 'impl = "echo"'), 7, "impl must be an importable"),
    (("[actions.echo]", '[actions."echo\\n"]'), 5, "bad name"),
    (("[actions.echo]", "[actions.echo]\nspeed = 1"), 6, "unknown key(s) speed"),
    (("[actions.echo]", "[actions.echo]\ndeadline_s = nan"), 6, "deadline_s must be a positive finite number"),
    (('node = "alpha"', 'node = "al\\u0000pha"'), 6, "NUL character"),
    (("port = 7101", "port = [" + "[" * 1000 + "]" * 1001), 3, "nesting deeper"),
    (("port = 7101", "port = 7101 ]"), 3, "not valid TOML"),
])
def test_every_location_file_error_carries_its_line(edit: tuple[str, str], line: int, words: str) -> None:
    with pytest.raises(LocationError) as info:
        parse_location(GOOD_SERVICES.replace(*edit), path="s.toml")
    assert str(info.value).startswith(f"s.toml:{line}: ") and words in str(info.value)


def test_a_location_file_in_utf16_or_with_a_nul_byte_is_refused_with_its_line(tmp_path: Path) -> None:
    path = tmp_path / "services.toml"
    path.write_bytes(GOOD_SERVICES.encode("utf-16"))
    with pytest.raises(LocationError, match=f"^{path}:1: not UTF-8 text"):
        load_location(path)
    path.write_bytes(GOOD_SERVICES.replace("port = 7101", "port = 7101 # \0").encode())
    with pytest.raises(LocationError, match=f"^{path}:3: NUL character"):
        load_location(path)


def _no_dns(monkeypatch: pytest.MonkeyPatch) -> list[str]:
    asked: list[str] = []

    def getaddrinfo(host: str, *args: object, **kwargs: object) -> list[object]:
        asked.append(host)
        if host == "localhost":
            return []
        raise socket.gaierror(socket.EAI_NONAME, "Name or service not known")

    monkeypatch.setattr(socket, "getaddrinfo", getaddrinfo)
    return asked


def test_check_finds_missing_modules_non_callable_impls_bad_drivers_and_unresolvable_hosts(
        monkeypatch: pytest.MonkeyPatch) -> None:
    asked = _no_dns(monkeypatch)
    path = HOSTILE / "services_broken_impls.toml"
    location, problems = check_location_file(path)
    assert location is not None and asked == ["no-such-host.invalid"]
    found = [(str(p).split(":")[1], str(p).split(": ", 2)[1]) for p in problems]
    assert found == [("7", "[nodes.beta]"), ("12", "[actions.missing_module]"), ("16", "[actions.missing_attr]"),
                     ("20", "[actions.not_callable]"), ("24", "[actions.sync_function]"),
                     ("32", "[drivers.not_a_driver]")]
    text = "\n".join(map(str, problems))
    assert "does not resolve" in text and "No module named 'services.actions.no_such_module'" in text
    assert "has no attribute 'no_such_action'" in text and "is a list, neither a PrimitiveAction" in text
    assert "is a function, neither" in text and "is a class that is not a Driver" in text


def test_check_of_a_net_imports_only_the_impls_the_net_uses(monkeypatch: pytest.MonkeyPatch) -> None:
    _no_dns(monkeypatch)
    path = HOSTILE / "services_broken_impls.toml"
    location, problems = check_location_file(path, {"missing_attr"})
    assert location is not None
    found = [str(p).split(": ", 2)[1] for p in problems]
    assert found == ["[nodes.beta]", "[actions.missing_attr]", "[drivers.not_a_driver]"]  # its node: alpha
    _, none_used = check_location_file(path, set())
    assert [str(p).split(": ", 2)[1] for p in none_used] == ["[nodes.beta]"]


def test_check_accepts_the_project_location_files(monkeypatch: pytest.MonkeyPatch) -> None:
    _no_dns(monkeypatch)
    for path in (ROOT / "services.toml", SERVICES):
        location, problems = check_location_file(path)
        assert location is not None and problems == []


def test_check_services_only_prints_each_problem_at_its_line_and_exits_2(
        monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]) -> None:
    _no_dns(monkeypatch)
    path = HOSTILE / "services_broken_impls.toml"
    assert check_cmd.run(_args(check_cmd, ["check", "--services-only", "--services", str(path)])) == 2
    out = capsys.readouterr().out.splitlines()
    assert len(out) == 6 and all(line.startswith(f"{path}:") for line in out)
    assert check_cmd.run(_args(check_cmd, ["check", "--services-only", "--services", str(SERVICES)])) == 0
    assert capsys.readouterr().out.startswith(f"OK {SERVICES}: 2 nodes")


def test_check_of_a_net_also_checks_the_location_file_it_reads(
        monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]) -> None:
    _no_dns(monkeypatch)
    path = HOSTILE / "services_bad_host.toml"
    assert check_cmd.run(_args(check_cmd, ["check", str(DEMO), "--services", str(path)])) == 2
    assert capsys.readouterr().out.splitlines() == [
        f"{path}:2: [nodes.alpha]: host '300.1.2.3' is not a valid IP address"]


# ----------------------------------------------------------------------------------- nothing written
def test_a_failing_export_writes_no_output_file(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    target = tmp_path / "out.pnml"
    for sample in ("22_tokens_negative.toml", "utf16_bom.toml", "billion_laughs.pnml"):
        argv = ["export", str(HOSTILE / sample), "--to", "pnml", "-o", str(target)]
        assert export_cmd.run(_args(export_cmd, argv)) == 2
        assert f"{HOSTILE / sample}:" in capsys.readouterr().err
    assert list(tmp_path.iterdir()) == []


def test_an_export_that_cannot_write_leaves_the_old_file_and_no_temporary(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    target = tmp_path / "out.toml"
    target.write_text("old")

    def full_disk(*args: object) -> None:
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(os, "replace", full_disk)
    assert export_cmd.run(_args(export_cmd, ["export", str(DEMO), "--to", "toml", "-o", str(target)])) == 2
    assert target.read_text() == "old" and [p.name for p in tmp_path.iterdir()] == ["out.toml"]


@pytest.mark.parametrize("argv", [
    ["check"], ["export", "--to", "dot"], ["analyze"], ["gspn"], ["perf", "--journal", "{tmp}/j.db"],
    ["learn", "--journal", "{tmp}/j.db"], ["run", "--journal", "{tmp}/run.db", "--no-input"],
])
def test_every_command_that_loads_a_net_prints_file_line_and_writes_nothing(
        argv: list[str], tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    work = tmp_path / "work"
    work.mkdir()
    for sample in ("22_tokens_negative.toml", "utf16_no_bom.toml", "external_entity.pnml"):
        args = [a.replace("{tmp}", str(work)) for a in argv]
        code = petrobot([args[0], str(HOSTILE / sample), *args[1:]])
        captured = capsys.readouterr()
        assert code in (1, 2), captured  # check, export, learn and run exit 2; see the report on the others
        assert f"{HOSTILE / sample}:" in captured.out + captured.err
        assert "Traceback" not in captured.out + captured.err
    assert list(work.iterdir()) == []
