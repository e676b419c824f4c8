"""``local_only`` across real hosts: two network namespaces joined by a veth pair (root only).

Host A runs the node on 10.77.x.1; host B (10.77.x.2) is another machine as far as the kernel
knows. A caller on B is refused a ``local_only`` action and served the others; a caller on A is
served from any of A's addresses, loopback included (docs/protocol.md §7). The namespaces and
their interfaces are made by the test and removed afterwards; nothing changes in the host's own
network but two short-lived names under /run/netns.
"""

from __future__ import annotations

import json
import os
import secrets
import shutil
import subprocess
import sys
from collections.abc import Iterator

import pytest
from tests.integration.cluster import ROOT, Cluster

pytestmark = [pytest.mark.integration, pytest.mark.netns]

SERVICES = """
[nodes.alpha]
host = "{host}"
port = 7101

[actions.echo]
node = "alpha"
impl = "services.actions.demo:echo"

[actions.private_echo]
node = "alpha"
impl = "services.actions.demo:echo"
local_only = true
"""

CLIENT = """
import asyncio, json, sys
from services.client import ServiceClient
from services.keys import load_key
from services.location import load_location

async def main():
    source = sys.argv[2] if len(sys.argv) > 2 else None
    async with ServiceClient(load_location(sys.argv[1]), load_key(), connect_timeout_s=10.0,
                             local_addr=(source, 0) if source else None) as client:
        out = {}
        for action in ("private_echo", "echo"):
            res = await client.call(action, {"a": 1})
            out[action] = [res.status, res.reason]
        print(json.dumps(out))

asyncio.run(main())
"""


def ip(*args: str) -> None:
    subprocess.run(["ip", *args], check=True, capture_output=True, timeout=30)


@pytest.fixture
def hosts() -> Iterator[tuple[str, str, str]]:
    """Two namespaces (A, B) joined by a veth pair; yields (A, B, subnet prefix)."""
    if os.geteuid() != 0 or shutil.which("ip") is None:
        pytest.skip("network namespaces need root and the ip command")
    tag = secrets.token_hex(3)
    a, b = f"pbA{tag}", f"pbB{tag}"
    net = f"10.77.{int(tag[:2], 16)}"
    try:
        ip("netns", "add", a)
    except subprocess.CalledProcessError:
        pytest.skip("cannot create network namespaces here")
    try:
        ip("netns", "add", b)
        ip("-n", a, "link", "add", f"va{tag}", "type", "veth", "peer", "name", f"vb{tag}", "netns", b)
        for ns, dev, addr in ((a, f"va{tag}", f"{net}.1"), (b, f"vb{tag}", f"{net}.2")):
            ip("-n", ns, "addr", "add", f"{addr}/24", "dev", dev)
            ip("-n", ns, "link", "set", dev, "up")
            ip("-n", ns, "link", "set", "lo", "up")
        yield a, b, net
    finally:
        for ns in (a, b):
            subprocess.run(["ip", "netns", "del", ns], capture_output=True, timeout=30, check=False)


def client_in(ns: str, cluster: Cluster, source: str | None = None) -> dict[str, list[str | None]]:
    args = ["ip", "netns", "exec", ns, sys.executable, "-c", CLIENT, str(cluster.services_path)]
    out = subprocess.run(args + ([source] if source else []), cwd=ROOT, env=cluster.env(),
                         capture_output=True, text=True, timeout=60, check=False)
    assert out.returncode == 0, out.stderr
    return json.loads(out.stdout)


def test_a_local_only_action_refuses_a_caller_on_another_host_and_serves_its_own_host(
        cluster: Cluster, hosts: tuple[str, str, str]) -> None:
    a, b, net = hosts
    cluster.write_services(SERVICES.format(host=f"{net}.1"))
    log = open(cluster.tmp / "alpha.log", "ab")  # noqa: SIM115 - closed below
    node = subprocess.Popen(["ip", "netns", "exec", a, sys.executable, "-m", "services.node", "alpha",
                             "--services", str(cluster.services_path), "--key-file", str(cluster.key_file)],
                            cwd=ROOT, env=cluster.env(), stdout=log, stderr=subprocess.STDOUT)
    try:
        from_b = client_in(b, cluster)
        from_a_loopback = client_in(a, cluster, source="127.0.0.1")
        from_a = client_in(a, cluster)
    finally:
        node.terminate()
        node.wait(timeout=10)
        log.close()
    assert from_b == {"private_echo": ["error", "local_only"], "echo": ["success", None]}
    assert from_a_loopback == {"private_echo": ["success", None], "echo": ["success", None]}
    assert from_a == {"private_echo": ["success", None], "echo": ["success", None]}
