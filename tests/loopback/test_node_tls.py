"""TLS on node connections (docs/protocol.md §3, "TLS"): psk mode and certificate mode on loopback.

Certificates are made for the test with the ``openssl`` command line (tests that need them are
skipped where it is not installed).
"""

from __future__ import annotations

import asyncio
import shutil
import subprocess
from collections.abc import AsyncIterator
from pathlib import Path

import pytest
from node_rig import ACTIONS, KEY, free_port, running_node

from services.client import NodeLink, ServiceClient
from services.location import TlsSettings
from services.node import Node
from services.wire import client_context, server_context

PSK = '[tls]\nmode = "psk"\n'


PSK_TLS = TlsSettings(mode="psk")


def psk_link(node: Node, key: bytes = KEY, tls: TlsSettings | None = PSK_TLS) -> NodeLink:
    return NodeLink("alpha", (node.host, node.port), key, connect_timeout_s=2.0, tls=tls)


async def test_psk_mode_serves_calls_to_a_client_with_the_key() -> None:
    async with running_node(header=PSK) as node:
        assert node.spec.tls.mode == "psk"
        async with ServiceClient(node.location, KEY) as client:
            res = await client.call("echo", {"over": "tls"})
            assert (res.status, res.value) == ("success", {"over": "tls"})
            link = client.link("alpha")
            wire = link._wire
            assert wire is not None and wire.transport is not None
            assert wire.transport.get_extra_info("ssl_object").version() == "TLSv1.2"


async def test_psk_mode_refuses_a_plain_client_and_a_client_with_another_key() -> None:
    async with running_node(header=PSK) as node:
        plain = psk_link(node, tls=None)
        res = await plain.call("echo")
        assert res.status == "error" and "unreachable" in (res.reason or "")
        wrong = psk_link(node, key=b"not the key of this node, 32 b!")
        res = await wrong.call("echo")
        assert res.status == "error" and "auth" in (res.reason or "")
        for c in (plain, wrong):
            await c.close()


async def test_psk_mode_defeats_a_relay_that_terminates_tls_on_both_sides() -> None:
    """A relay holding no key runs one TLS session with the client and one with the node and copies
    the bytes between them: without the channel binding in the MACs it would pass the handshake
    through and read everything; with it, neither side's MAC verifies."""
    async with running_node(header=PSK) as node:
        server_ctx = server_context(TlsSettings(mode="psk"))
        client_ctx = client_context(TlsSettings(mode="psk"))

        async def pipe(reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
            try:
                while data := await reader.read(65536):
                    writer.write(data)
                    await writer.drain()
            except (ConnectionError, OSError):
                pass
            finally:
                writer.close()

        async def relay(c_reader: asyncio.StreamReader, c_writer: asyncio.StreamWriter) -> None:
            n_reader, n_writer = await asyncio.open_connection(node.host, node.port, ssl=client_ctx)
            await asyncio.gather(pipe(c_reader, n_writer), pipe(n_reader, c_writer))

        port = free_port()
        server = await asyncio.start_server(relay, "127.0.0.1", port, ssl=server_ctx)
        try:
            victim = NodeLink("alpha", ("127.0.0.1", port), KEY, connect_timeout_s=2.0, tls=TlsSettings(mode="psk"))
            res = await victim.call("echo", {"secret": 1})
            assert res.status == "error" and "auth" in (res.reason or ""), res
            await victim.close()
        finally:
            server.close()


# --------------------------------------------------------------------------- certificates


def openssl(*args: str, cwd: Path) -> None:
    subprocess.run(["openssl", *args], cwd=cwd, check=True, capture_output=True, timeout=60)


def make_ca(where: Path, name: str) -> None:
    openssl("req", "-x509", "-newkey", "ec", "-pkeyopt", "ec_paramgen_curve:prime256v1", "-nodes",
            "-keyout", f"{name}.key", "-out", f"{name}.pem", "-days", "2", "-subj", f"/CN={name}", cwd=where)


def make_host(where: Path, ca: str, name: str) -> None:
    (where / f"{name}.ext").write_text("subjectAltName=IP:127.0.0.1,DNS:alpha.lab\n"
                                       "extendedKeyUsage=serverAuth,clientAuth\n")
    openssl("req", "-newkey", "ec", "-pkeyopt", "ec_paramgen_curve:prime256v1", "-nodes",
            "-keyout", f"{name}.key", "-out", f"{name}.csr", "-subj", f"/CN={name}", cwd=where)
    openssl("x509", "-req", "-in", f"{name}.csr", "-CA", f"{ca}.pem", "-CAkey", f"{ca}.key",
            "-CAcreateserial", "-out", f"{name}.pem", "-days", "2", "-extfile", f"{name}.ext", cwd=where)


@pytest.fixture(scope="module")
def certs(tmp_path_factory: pytest.TempPathFactory) -> Path:
    if shutil.which("openssl") is None:
        pytest.skip("the openssl command makes the test certificates and is not installed")
    where = tmp_path_factory.mktemp("certs")
    make_ca(where, "ca")
    make_host(where, "ca", "host")
    make_ca(where, "rogue_ca")
    make_host(where, "rogue_ca", "rogue")
    return where


@pytest.fixture
async def cert_node(certs: Path) -> AsyncIterator[Node]:
    header = f'[tls]\nmode = "certificate"\nca = "{certs}/ca.pem"\ncert = "{certs}/host.pem"\nkey = "{certs}/host.key"\n'
    async with running_node(ACTIONS, header=header) as node:
        yield node


async def test_certificate_mode_serves_a_client_whose_certificate_the_ca_signed(cert_node: Node) -> None:
    async with ServiceClient(cert_node.location, KEY) as client:
        res = await client.call("echo", {"cert": True})
        assert (res.status, res.value) == ("success", {"cert": True})


async def test_certificate_mode_refuses_a_client_certificate_from_another_ca(cert_node: Node, certs: Path) -> None:
    rogue = TlsSettings(mode="certificate", ca=str(certs / "ca.pem"), cert=str(certs / "rogue.pem"),
                        key=str(certs / "rogue.key"))
    link = NodeLink("alpha", (cert_node.host, cert_node.port), KEY, connect_timeout_s=2.0, tls=rogue)
    res = await link.call("echo")
    assert res.status == "error" and "unreachable" in (res.reason or "")
    await link.close()


async def test_certificate_mode_checks_the_name_in_the_node_certificate(cert_node: Node, certs: Path) -> None:
    wrong_name = TlsSettings(mode="certificate", ca=str(certs / "ca.pem"), cert=str(certs / "host.pem"),
                             key=str(certs / "host.key"), server_name="beta.lab")
    link = NodeLink("alpha", (cert_node.host, cert_node.port), KEY, connect_timeout_s=2.0, tls=wrong_name)
    res = await link.call("echo")
    assert res.status == "error" and "unreachable" in (res.reason or "")
    await link.close()
    right_name = TlsSettings(mode="certificate", ca=str(certs / "ca.pem"), cert=str(certs / "host.pem"),
                             key=str(certs / "host.key"), server_name="alpha.lab")
    link = NodeLink("alpha", (cert_node.host, cert_node.port), KEY, connect_timeout_s=2.0, tls=right_name)
    assert (await link.call("echo")).status == "success"
    await link.close()
