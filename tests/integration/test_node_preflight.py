"""ServiceClient.preflight against real node processes: every way a net's actions can fail to be ready.

Each problem is reported in a sentence that names the action, the node and what to do; an empty
list means every action is placed and offered by a reachable node that loaded our services.toml.
"""

from __future__ import annotations

import pytest
from tests.integration.cluster import DEMO_SERVICES, Cluster

from services.client import ServiceClient
from services.location import parse_location

pytestmark = pytest.mark.integration


async def test_nothing_to_report_when_every_action_is_placed_offered_and_reachable(cluster: Cluster) -> None:
    cluster.start("alpha", "beta")
    async with cluster.client() as client:
        assert await client.preflight(["echo", "wait", "compute_primes", "memory.get"]) == []
        link = client.link("alpha")
        assert link.offered_actions is not None and "echo" in link.offered_actions
        assert link.location_digest == client.location_digest and not link.location_changed


async def test_an_action_not_placed_is_named_with_the_file(cluster: Cluster) -> None:
    cluster.start("alpha")
    async with cluster.client() as client:
        problems = await client.preflight(["echo", "catch"])
    assert problems == [f"action 'catch' is not placed in {cluster.services_path} (add [actions.catch])"]


async def test_an_unreachable_node_is_named_with_its_address_and_the_error(cluster: Cluster) -> None:
    cluster.start("alpha")  # beta is not started
    host, port = cluster.location.address("beta")
    async with cluster.client(connect_timeout_s=0.3) as client:
        problems = await client.preflight(["echo", "compute_primes", "slow"])
    assert len(problems) == 1
    assert problems[0].startswith(f"node beta at {host}:{port} is unreachable: ")
    assert "refused" in problems[0].lower()


async def test_a_node_started_from_another_services_file_says_what_it_offers(cluster: Cluster) -> None:
    cluster.write_services()
    ours = cluster.location
    # the node runs from an older file where compute_primes was placed elsewhere
    cluster.write_services(DEMO_SERVICES.replace('[actions.compute_primes]\nnode = "beta"',
                                                 '[actions.compute_primes]\nnode = "alpha"'))
    cluster.start("beta")
    async with ServiceClient(ours, cluster.key, location_digest="0" * 64) as client:
        problems = await client.preflight(["compute_primes", "slow"])
    assert problems[0].startswith("node beta does not offer 'compute_primes' (it offers announce, remember, slow)")
    assert problems[0].endswith("its services.toml differs: restart it")
    assert problems[1].startswith("node beta loaded a services.toml that differs from ours")


async def test_a_node_whose_file_changed_on_disk_since_it_started_is_named(cluster: Cluster) -> None:
    cluster.start("alpha")
    async with cluster.client() as client:  # its digest is of the file the node loaded
        cluster.services_path.write_text(cluster.services_path.read_text() + "\n# edited after the node started\n")
        problems = await client.preflight(["echo"])
    assert problems == ["node alpha's services.toml changed on disk since it started: restart it"]


async def test_a_node_that_refuses_our_key_is_named(cluster: Cluster) -> None:
    cluster.start("alpha")
    async with ServiceClient(cluster.location, b"a key the node does not hold....") as client:
        problems = await client.preflight(["echo"])
    assert len(problems) == 1 and problems[0].startswith("node alpha at 127.0.0.1:") and "refused our key" in problems[0]


async def test_the_services_digest_is_that_of_the_bytes_the_node_loaded(cluster: Cluster) -> None:
    cluster.start("alpha")
    text = cluster.services_path.read_text()
    async with ServiceClient(parse_location(text), cluster.key) as client:  # no file: no digest of ours
        assert client.location_digest is None
        assert await client.preflight(["echo"]) == []
        import hashlib

        assert client.link("alpha").location_digest == hashlib.sha256(text.encode()).hexdigest()
