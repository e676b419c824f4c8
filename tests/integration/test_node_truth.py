"""The node tells the truth about what ran: real node processes frozen, killed and restarted mid-call.

* A call whose caller gave up (the node was frozen: the client's heartbeat declared it dead) is
  cancelled on the node with reason ``caller_gone`` once it resumes and nobody asks for the call,
  and a later ``query`` says so; an ``unattended`` action finishes instead and ``query`` says that.
* A node killed during a call answers the repeated id with ``node_restarted`` after its restart,
  and never runs it twice.
* A repeated id gets its first result after 10,000 other calls and after a restart.
"""

from __future__ import annotations

import asyncio
import signal

import pytest
from tests.integration.cluster import Cluster
from waiting import log_says

pytestmark = pytest.mark.integration

SERVICES = """
[nodes.alpha]
host = "127.0.0.1"
port = {port[alpha]}
max_in_flight = 64

[actions.echo]
node = "alpha"
impl = "services.actions.demo:echo"

[actions.wait]
node = "alpha"
impl = "services.actions.demo:wait"

[actions.move]
node = "alpha"
impl = "services.actions.demo:wait"
unattended = true
"""


async def freeze_during(cluster: Cluster, action: str, call_id: str) -> None:
    """Call ``action`` (10 s), freeze the node until the client has given up, then let it go on."""
    async with cluster.client() as client:
        task = asyncio.create_task(client.call(action, {"seconds": 10, "step": 0.1}, call_id=call_id))
        await log_says(cluster, "alpha", f"call {call_id} {action} from")
        cluster.kill("alpha", signal.SIGSTOP)
        try:
            res = await asyncio.wait_for(task, 30)
        finally:
            cluster.kill("alpha", signal.SIGCONT)
        assert res.status == "error" and "heartbeat" in (res.reason or ""), res


async def test_a_call_given_up_on_while_the_node_was_frozen_is_cancelled_and_a_query_tells_so(
        cluster: Cluster) -> None:
    cluster.write_services(SERVICES)
    cluster.start("alpha")
    await freeze_during(cluster, "wait", "frozen-1")
    await log_says(cluster, "alpha", "result frozen-1 wait: error (caller_gone)")
    async with cluster.client() as client:
        truth = await client.query("wait", "frozen-1")
    assert truth is not None and (truth.status, truth.reason) == ("error", "caller_gone")
    assert "result frozen-1 wait: success" not in cluster.log("alpha")


async def test_an_unattended_action_finishes_after_its_caller_gave_up_and_a_query_tells_so(
        cluster: Cluster) -> None:
    cluster.write_services(SERVICES)
    cluster.start("alpha")
    await freeze_during(cluster, "move", "frozen-2")
    await log_says(cluster, "alpha", "call frozen-2 move lost its last caller: it may finish unattended")
    async with cluster.client() as client:
        truth = await client.query("move", "frozen-2")  # joins the running call and waits for its end
    assert truth is not None and truth.status == "success" and truth.value["waited_s"] >= 10


async def test_a_query_with_cancel_ends_a_call_given_up_on_before_the_grace_period(cluster: Cluster) -> None:
    cluster.write_services(SERVICES)
    cluster.start("alpha")
    await freeze_during(cluster, "move", "frozen-3")
    async with cluster.client() as client:
        truth = await client.query("move", "frozen-3", cancel=True)
    assert truth is not None and (truth.status, truth.reason) == ("error", "cancelled")


async def test_a_call_running_when_its_node_died_is_answered_node_restarted_and_never_run_twice(
        cluster: Cluster) -> None:
    cluster.write_services(SERVICES)
    cluster.start("alpha")
    async with cluster.client() as client:
        task = asyncio.create_task(client.call("wait", {"seconds": 10}, call_id="crash-1"))
        await log_says(cluster, "alpha", "call crash-1 wait from")
        cluster.kill("alpha")  # SIGKILL: no clean shutdown
        lost = await asyncio.wait_for(task, 10)
        assert lost.status == "error"
        cluster.start("alpha")
        again = await client.call("wait", {"seconds": 10}, call_id="crash-1")
        asked = await client.query("wait", "crash-1")
    assert (again.status, again.reason) == ("error", "node_restarted")
    assert asked == again
    assert cluster.log("alpha").count("call crash-1 wait from") == 1  # both runs of the node, one log


async def test_a_repeated_id_gets_its_first_result_after_ten_thousand_other_calls_and_after_a_restart(
        cluster: Cluster) -> None:
    cluster.write_services(SERVICES)
    cluster.start("alpha")
    async with cluster.client() as client:
        first = await client.call("echo", {"first": True}, call_id="keep-me")
        sem = asyncio.Semaphore(64)

        async def other(i: int) -> str:
            async with sem:
                return (await client.call("echo", {"i": i})).status

        statuses = await asyncio.gather(*(other(i) for i in range(10_050)))
        assert statuses.count("success") == 10_050
        after_load = await client.call("echo", {"first": False}, call_id="keep-me")
    assert after_load == first
    cluster.kill("alpha")
    cluster.start("alpha")
    async with cluster.client() as client:
        after_restart = await client.call("echo", {"first": False}, call_id="keep-me")
    assert after_restart == first
    assert after_restart.value == {"first": True} and after_restart.wall_s == first.wall_s
