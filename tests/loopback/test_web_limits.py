"""What a page without the console's token may cost the run it shows (issue 22, section 6): a cap on
read-only pages, drawings of at most 512 KiB from them, their work rate-limited and done in the
console's worker process (never on the run's event loop), wrong tokens rate-limited per address
without locking out the token's holder. A real console on 127.0.0.1 with a live run (the
fixture of test_web_server.py); the worker is a real child process."""

from __future__ import annotations

import asyncio
import json

import aiohttp
import pytest

from coordinator.web.limits import ConsoleGuard, ConsoleLimits
from coordinator.web.worker import Worker, WorkFailed
from tests.loopback.test_web_server import Console, closed_with, console, hello, request  # noqa: F401 - fixture

__all__: list[str] = []


def big_draft(places: int) -> dict[str, object]:
    """A drawing of ``places`` places and as many transitions in one ring."""
    return {"net": {"name": f"big{places}"},
            "places": [{"id": f"p{i}", "tokens": 1 if i == 0 else 0, "pos": [i * 10.0, 0.0]} for i in range(places)],
            "transitions": [{"id": f"t{i}", "pos": [i * 10.0 + 5, 40.0]} for i in range(places)],
            "arcs": [a for i in range(places) for a in ({"from": f"p{i}", "to": f"t{i}"},
                                                         {"from": f"t{i}", "to": f"p{(i + 1) % places}"})]}


async def test_read_only_pages_beyond_the_cap_are_refused_and_the_token_still_gets_in(console: Console):
    console.server.guard.limits = ConsoleLimits(max_viewers=3)
    async with aiohttp.ClientSession() as http:
        viewers = [await http.ws_connect(console.ws_url()) for _ in range(3)]
        for ws in viewers:
            assert (await hello(ws, None))["control"] is False
        async with http.ws_connect(console.ws_url()) as extra:
            await extra.send_str(json.dumps({"type": "hello", "v": 1}))
            code, reason = await closed_with(extra)
            assert code == 1013 and "3 read-only pages already" in reason
        async with http.ws_connect(console.ws_url()) as operator:
            assert (await hello(operator, console.server.token))["control"] is True
        await viewers[0].close()
        for _ in range(2000):  # until the server has seen the page go (bounded: 20 s)
            if console.server.guard.viewers < 3:
                break
            await asyncio.sleep(0.01)
        async with http.ws_connect(console.ws_url()) as again:  # a place came free
            assert (await hello(again, None))["control"] is False
        for ws in viewers[1:]:
            await ws.close()


async def test_a_read_only_pages_large_drawing_is_closed_unread_and_a_medium_one_is_checked_in_the_worker(
        console: Console):
    async with aiohttp.ClientSession() as http:
        async with http.ws_connect(console.ws_url(), max_msg_size=0) as ws:
            await hello(ws, None)
            reply = await request(ws, 1, type="validate", draft=big_draft(400))  # ~60 KiB
            assert reply["ok"] is True and reply["validation"]["ok"] is True
            assert console.server.worker.jobs == 1  # not in a thread of the run's process
            await ws.send_str(json.dumps({"type": "validate", "id": 2, "draft": big_draft(6000)}))  # > 512 KiB
            code, reason = await closed_with(ws)
            assert code == 1009 and "read-only page" in reason


async def test_read_only_pages_work_is_rate_limited_together(console: Console):
    console.server.guard = ConsoleGuard(ConsoleLimits(viewer_jobs_per_s=0.2, viewer_job_burst=2))
    async with aiohttp.ClientSession() as http:
        pages = [await http.ws_connect(console.ws_url()) for _ in range(2)]
        for ws in pages:
            await hello(ws, None)
        replies = [await request(pages[i % 2], i, type="validate", draft=big_draft(50)) for i in range(5)]
        assert [r["ok"] for r in replies] == [True, True, False, False, False]
        assert "busy with read-only pages' work" in replies[2]["reason"]
        async with http.ws_connect(console.ws_url()) as operator:  # the token's holder is not counted
            await hello(operator, console.server.token)
            assert (await request(operator, 9, type="validate", draft=big_draft(50)))["ok"] is True
        for ws in pages:
            await ws.close()


async def test_wrong_tokens_are_rate_limited_per_address_and_the_right_token_still_gets_in(console: Console):
    async with aiohttp.ClientSession() as http:
        answered = refused = 0
        for i in range(20):
            async with http.ws_connect(console.ws_url()) as ws:
                await ws.send_str(json.dumps({"type": "hello", "v": 1, "token": f"guess-{i}"}))
                msg = await ws.receive()
                if msg.type == aiohttp.WSMsgType.TEXT and json.loads(msg.data)["type"] == "welcome":
                    answered += 1
                else:
                    refused += 1
                    assert ws.close_code == 1008
        assert answered <= 11 and refused >= 9  # 10 in a row, then one every 2 s
        async with http.ws_connect(console.ws_url()) as operator:
            assert (await hello(operator, console.server.token))["control"] is True
        statuses = []
        for i in range(15):
            async with http.get(console.base + "/api/nets", headers={"X-Petrobot-Token": f"guess-{i}"}) as res:
                statuses.append(res.status)
        assert 429 in statuses
        async with http.get(console.base + "/api/nets", headers={"X-Petrobot-Token": console.server.token}) as res:
            assert res.status == 200


async def test_a_read_only_export_goes_to_the_worker_and_a_large_one_is_refused_before_it_is_read(console: Console):
    async with aiohttp.ClientSession() as http:
        async with http.post(console.base + "/api/export?format=dot", json=big_draft(100)) as res:
            assert res.status == 200 and "digraph" in await res.text()
        assert console.server.worker.jobs >= 1
        async with http.post(console.base + "/api/export?format=dot", json=big_draft(6000)) as res:
            assert res.status == 413 and "at most 512 KiB" in (await res.json())["error"]


async def test_a_job_over_its_time_is_stopped_with_its_process_and_the_next_job_gets_a_new_one() -> None:
    worker = Worker(timeout_s=0.05)
    message = json.dumps({"type": "validate", "id": 1, "draft": big_draft(20000)})
    try:
        with pytest.raises(WorkFailed, match="took more than"):
            await worker.run("validate", message)
        worker.timeout_s = 60.0
        got = await worker.run("validate", json.dumps({"type": "validate", "id": 2, "draft": big_draft(10)}))
        assert got["id"] == 2 and got["validation"]["ok"] is True and worker.restarts == 1
        with pytest.raises(WorkFailed, match="draft"):
            await worker.run("validate", json.dumps({"type": "validate", "id": 3, "draft": "not a drawing"}))
    finally:
        await worker.close()


async def test_a_read_only_pages_medium_drawing_is_answered_from_the_worker_unread_and_a_spent_budget_closes_it(
        console: Console):
    console.server.guard = ConsoleGuard(ConsoleLimits(viewer_jobs_per_s=0.01, viewer_job_burst=1))
    async with aiohttp.ClientSession() as http:
        async with http.ws_connect(console.ws_url(), max_msg_size=0) as ws:
            await hello(ws, None)
            # ~150 KiB: over what the run's loop parses for a read-only page, under what it may send
            reply = await request(ws, 7, type="validate", draft=big_draft(1000), name="ring.toml")
            assert reply["to"] == "validate" and reply["ok"] is True and reply["validation"]["ok"] is True
            assert console.server.worker.jobs == 1
            await ws.send_str(json.dumps({"type": "validate", "id": 8, "draft": big_draft(1000)}))
            code, reason = await closed_with(ws)  # the budget is spent: no reply, since it was not read
            assert code == 1013 and "busy with read-only pages' work" in reason
        console.server.guard = ConsoleGuard()
        async with http.ws_connect(console.ws_url(), max_msg_size=0) as ws:
            await hello(ws, None)
            await ws.send_str(json.dumps({"type": "save", "id": 9, "draft": big_draft(1000), "path": "ring.json"}))
            code, reason = await closed_with(ws)  # a large message of a read-only page is a drawing to check or nothing
            assert code == 1008 and "save message larger than" in reason


async def test_an_address_whose_read_only_pages_keep_breaking_the_bounds_is_closed_at_hello_before_it_sends_more(
        console: Console):
    console.server.guard = ConsoleGuard(ConsoleLimits(closures=2, closure_refill_s=600.0))
    huge = json.dumps({"type": "validate", "id": 1, "draft": big_draft(6000)})  # > 512 KiB
    async with aiohttp.ClientSession() as http:
        for _ in range(2):
            async with http.ws_connect(console.ws_url(), max_msg_size=0) as ws:
                await hello(ws, None)
                await ws.send_str(huge)
                assert (await closed_with(ws))[0] == 1009
        async with http.ws_connect(console.ws_url()) as ws:
            await ws.send_str(json.dumps({"type": "hello", "v": 1}))
            code, reason = await closed_with(ws)
            assert code == 1013 and "broke the console's bounds too often" in reason
        async with http.ws_connect(console.ws_url()) as operator:  # the token's holder is not a viewer
            assert (await hello(operator, console.server.token))["control"] is True


async def test_a_replay_is_read_from_the_journal_in_the_worker_and_a_missing_run_is_a_clear_404(console: Console):
    await console.fired(3)
    async with aiohttp.ClientSession() as http:
        async with http.get(console.base + f"/api/replay?run={console.runtime.run_id}") as res:
            data = await res.json()
        assert console.server.worker.jobs == 1  # not in a thread of the run's process
        assert data["draft"]["net"]["name"] == "ticked" and [r for r in data["records"] if r[0] == "f"]
        async with http.get(console.base + "/api/replay?run=no-such-run") as res:
            assert res.status == 404 and "no-such-run" in (await res.json())["error"]
