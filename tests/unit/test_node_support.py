"""The node's small helpers: rate-limited log lines, locality of peers, the watched services.toml,
and the services.toml keys a node reads (unattended actions, state directory, TLS)."""

from __future__ import annotations

import logging
from pathlib import Path

import pytest

from services.errors import LocationError
from services.location import TlsSettings, parse_location
from services.node.locality import Locality
from services.node.logs import LogLimiter
from services.node.watch import LocationWatch, digest_of


class Clock:
    def __init__(self) -> None:
        self.t = 0.0

    def __call__(self) -> float:
        return self.t


def test_repeated_log_lines_are_held_back_and_counted(caplog: pytest.LogCaptureFixture) -> None:
    clock = Clock()
    limiter = LogLimiter(logging.getLogger("test.limiter"), burst=3, interval_s=10.0, clock=clock)
    caplog.set_level(logging.INFO, "test.limiter")
    written = [limiter.log(logging.WARNING, ("auth", "10.0.0.9"), "refused %s", i) for i in range(1000)]
    assert written.count(True) == 3
    limiter.log(logging.WARNING, ("auth", "10.0.0.7"), "refused other")  # another key has its own lines
    clock.t = 10.0
    limiter.log(logging.WARNING, ("auth", "10.0.0.9"), "refused again")
    lines = [r.getMessage() for r in caplog.records]
    assert lines == ["refused 0", "refused 1", "refused 2", "refused other",
                     "997 similar line(s) suppressed in 10 s (auth)", "refused again"]


def test_peers_from_a_thousand_addresses_write_at_most_the_total_and_one_summary_per_interval(
        caplog: pytest.LogCaptureFixture) -> None:
    """Issue 22: the limit per address let a fuzz from 1,000 addresses grow a node's log to 26.7 MB."""
    clock = Clock()
    limiter = LogLimiter(logging.getLogger("test.limiter.total"), burst=5, interval_s=10.0, total=50, clock=clock)
    caplog.set_level(logging.INFO, "test.limiter.total")
    for second in range(30):  # 30 s of 1,000 addresses, each failing a login and sending a bad frame
        clock.t = float(second)
        for host in range(1000):
            limiter.log(logging.WARNING, ("auth", f"10.0.{host // 250}.{host % 250}"), "refused %s", host)
            limiter.log(logging.WARNING, ("bad frame", f"10.0.{host // 250}.{host % 250}"), "bad frame %s", host)
    clock.t = 30.0
    limiter.flush()
    lines = [r.getMessage() for r in caplog.records]
    summaries = [line for line in lines if line.startswith("log limit:")]
    assert len(lines) <= 3 * (50 + 1) and len(summaries) == 3, len(lines)
    assert "auth" in summaries[0] and "from 1000 sources" in summaries[0] and "bad frame" in summaries[0]
    dropped = sum(int(line.split()[2]) for line in summaries)
    assert dropped == 2 * 1000 * 30 - (len(lines) - len(summaries))  # every line is written or counted


def test_the_limiter_remembers_a_bounded_number_of_keys() -> None:
    limiter = LogLimiter(logging.getLogger("test.limiter.keys"), max_keys=10)
    logging.getLogger("test.limiter.keys").setLevel(logging.INFO)
    for i in range(1000):
        limiter.log(logging.INFO, ("k", i), "x")
    assert len(limiter._keys) == 10


def test_loopback_and_the_accepting_address_are_local_and_others_are_asked_of_the_host() -> None:
    asked: list[str] = []

    def own(ip: str) -> bool:
        asked.append(ip)
        return ip == "192.168.7.20"

    loc = Locality(own)
    assert loc.is_local("127.0.0.1", "127.0.0.5")  # a loopback alias: same host
    assert loc.is_local("::1", "::1")
    assert loc.is_local("10.1.2.3", "10.1.2.3")
    assert loc.is_local("192.168.7.20", "10.1.2.3")  # another address of this host
    assert not loc.is_local("192.0.2.44", "10.1.2.3")  # another host
    assert not loc.is_local("192.0.2.44", "10.1.2.3")
    assert not loc.is_local("not an address", "10.1.2.3")
    assert asked == ["192.168.7.20", "192.0.2.44"]  # each asked once, then cached


def test_the_watch_says_when_the_file_on_disk_differs_from_what_was_loaded(tmp_path: Path) -> None:
    path = tmp_path / "services.toml"
    path.write_bytes(b"[nodes.a]\n")
    watch = LocationWatch(str(path), digest_of(b"[nodes.a]\n"))
    assert not watch.changed()
    path.write_bytes(b"[nodes.b]\n")
    assert watch.changed() and watch.changed()
    path.write_bytes(b"[nodes.a]\n")  # put back as it was
    assert not watch.changed()
    path.unlink()
    assert watch.changed()
    assert not LocationWatch("<string>", "x").changed() and not LocationWatch(None, None).changed()


NODE = '[nodes.alpha]\nhost = "127.0.0.1"\nport = 7101\n'


def test_an_action_may_be_unattended_and_a_node_may_name_its_state_directory(tmp_path: Path) -> None:
    loc = parse_location(NODE + 'state_dir = "state"\n[actions.move]\nnode = "alpha"\nimpl = "m:f"\n'
                         'unattended = true\n[actions.look]\nnode = "alpha"\nimpl = "m:f"\n',
                         path=str(tmp_path / "services.toml"))
    assert loc.actions["move"].unattended and not loc.actions["look"].unattended
    assert loc.nodes["alpha"].state_dir == str(tmp_path / "state")
    with pytest.raises(LocationError, match="unattended must be true or false"):
        parse_location(NODE + '[actions.m]\nnode = "alpha"\nimpl = "m:f"\nunattended = 1\n')


def test_tls_settings_default_to_off_and_a_node_table_overrides_the_global_one(tmp_path: Path) -> None:
    assert parse_location(NODE).nodes["alpha"].tls == TlsSettings(mode="off")
    text = ('[tls]\nmode = "certificate"\nca = "ca.pem"\ncert = "host.pem"\nkey = "/etc/host.key"\n'
            + NODE + '[nodes.alpha.tls]\nserver_name = "alpha.lab"\n'
            '[nodes.beta]\nhost = "127.0.0.1"\nport = 7102\n[nodes.beta.tls]\nmode = "psk"\n')
    loc = parse_location(text, path=str(tmp_path / "services.toml"))
    assert loc.nodes["alpha"].tls == TlsSettings(mode="certificate", ca=str(tmp_path / "ca.pem"),
                                                 cert=str(tmp_path / "host.pem"), key="/etc/host.key",
                                                 server_name="alpha.lab")
    assert loc.nodes["beta"].tls.mode == "psk"


@pytest.mark.parametrize(("tls", "match"), [
    ('mode = "tls13"', "mode must be one of off, certificate, psk"),
    ('mode = "certificate"\nca = "ca.pem"', "certificate mode needs ca, cert and key"),
    ('mode = "psk"\nciphers = "ALL"', "unknown key"),
    ("mode = 1", "mode must be a non-empty string"),
])
def test_bad_tls_settings_are_named(tls: str, match: str) -> None:
    with pytest.raises(LocationError, match=match):
        parse_location("[tls]\n" + tls + "\n" + NODE)
