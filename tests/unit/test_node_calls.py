"""The node's call table (services.node.calls), driven as pure logic: no sockets, no event loop."""

from __future__ import annotations

import pytest

from services.node.calls import (
    ENTRY_OVERHEAD,
    Answer,
    CallTable,
    Join,
    KeptResult,
    MemoryResultCache,
    Reject,
    RejectReason,
    Start,
)
from services.protocol import Call, Result, encode_frame
from services.results import ActionResult


def table(max_in_flight: int = 2, cache: MemoryResultCache | None = None) -> CallTable[str]:
    """A table hosting ``echo``, ``wait`` and the local-only ``private``; waiters are peer names."""
    return CallTable(["echo", "wait", "private"], local_only=["private"], max_in_flight=max_in_flight, cache=cache)


def call(cid: str, action: str = "echo") -> Call:
    return Call(id=cid, action=action)


def result(cid: str, value: object = None) -> Result:
    return Result(id=cid, result=ActionResult.success(value))


def finish(t: CallTable[str], cid: str, now: float = 0.0, value: object = None) -> list[str]:
    res = result(cid, value)
    return list(t.finish(res, size=len(encode_frame(res)), now=now).waiters)


def test_a_new_call_starts_and_its_caller_waits_for_it() -> None:
    t = table()
    verdict = t.admit(call("c1"), "p1", local=True)
    assert isinstance(verdict, Start)
    assert verdict.running.call == call("c1") and list(verdict.running.waiters) == ["p1"]
    assert t.in_flight == 1 and t.running("c1") is verdict.running


def test_an_action_not_hosted_here_is_rejected_unknown_action() -> None:
    assert table().admit(call("c1", "fly"), "p1", local=True) == Reject(RejectReason.UNKNOWN_ACTION)


def test_a_local_only_action_is_served_to_a_local_peer_only() -> None:
    t = table()
    assert t.admit(call("c1", "private"), "far", local=False) == Reject(RejectReason.LOCAL_ONLY)
    assert isinstance(t.admit(call("c2", "private"), "near", local=True), Start)
    assert isinstance(t.admit(call("c3", "echo"), "far", local=False), Start)


def test_a_repeat_of_a_running_id_joins_it_and_both_callers_get_the_result() -> None:
    t = table()
    first = t.admit(call("c1"), "p1", local=True)
    again = t.admit(call("c1"), "p2", local=True)
    assert isinstance(first, Start) and isinstance(again, Join)
    assert again.running is first.running and t.in_flight == 1
    assert finish(t, "c1") == ["p1", "p2"]


def test_a_repeat_of_a_finished_id_is_answered_with_the_kept_result_without_running_again() -> None:
    t = table()
    t.admit(call("c1"), "p1", local=True)
    finish(t, "c1", now=5.0, value={"x": 1})
    verdict = t.admit(call("c1"), "p2", local=True)
    assert isinstance(verdict, Answer)
    assert verdict.kept.result == result("c1", {"x": 1})
    assert (verdict.kept.action, verdict.kept.stored_at) == ("echo", 5.0)
    assert t.in_flight == 0


def test_the_same_id_for_another_action_is_a_duplicate_id_while_running_and_once_kept() -> None:
    t = table()
    t.admit(call("c1", "wait"), "p1", local=True)
    assert t.admit(call("c1", "echo"), "p2", local=True) == Reject(RejectReason.DUPLICATE_ID)
    finish(t, "c1")
    assert t.admit(call("c1", "echo"), "p2", local=True) == Reject(RejectReason.DUPLICATE_ID)


def test_calls_beyond_max_in_flight_are_rejected_busy_until_one_ends() -> None:
    t = table(max_in_flight=2)
    t.admit(call("c1"), "p", local=True)
    t.admit(call("c2"), "p", local=True)
    assert t.admit(call("c3"), "p", local=True) == Reject(RejectReason.BUSY)
    finish(t, "c1")
    assert isinstance(t.admit(call("c3"), "p", local=True), Start)


def test_a_stopping_table_rejects_new_calls_shutdown_but_answers_repeats() -> None:
    t = table()
    t.admit(call("done"), "p", local=True)
    finish(t, "done")
    t.admit(call("busy"), "p", local=True)
    still_running = t.stop()
    assert [r.call.id for r in still_running] == ["busy"]
    assert t.admit(call("new"), "p", local=True) == Reject(RejectReason.SHUTDOWN)
    assert isinstance(t.admit(call("done"), "p", local=True), Answer)
    assert isinstance(t.admit(call("busy"), "q", local=True), Join)


def test_a_repeat_is_answered_even_when_the_table_is_full() -> None:
    t = table(max_in_flight=1)
    t.admit(call("c1"), "p", local=True)
    finish(t, "c1")
    t.admit(call("c2"), "p", local=True)
    assert isinstance(t.admit(call("c1"), "p", local=True), Answer)
    assert isinstance(t.admit(call("c2"), "q", local=True), Join)


def test_cancel_marks_a_running_call_and_ignores_an_unknown_id() -> None:
    t = table()
    t.admit(call("c1"), "p", local=True)
    running = t.cancel("c1")
    assert running is not None and running.cancel_requested
    assert t.cancel("nope") is None


def test_finishing_an_id_that_is_not_running_is_a_key_error() -> None:
    with pytest.raises(KeyError):
        finish(table(), "never")


def test_rejection_reasons_are_the_wire_strings() -> None:
    assert [r.value for r in RejectReason] == [
        "unknown_action", "local_only", "duplicate_id", "busy", "shutdown", "unknown_call"]


def test_a_local_only_action_that_is_not_hosted_is_a_value_error() -> None:
    with pytest.raises(ValueError):
        CallTable(["echo"], local_only=["private"])
    with pytest.raises(ValueError):
        CallTable(["echo"], max_in_flight=0)


# --------------------------------------------------------------------------- the result cache


def kept(cid: str, size: int, at: float) -> KeptResult:
    """A kept result whose frame is ``size`` bytes (the cache charges what it holds: the frame)."""
    return KeptResult(cid, "echo", result(cid), size, at, bytes(size))


def test_kept_results_older_than_the_age_cap_expire_oldest_first() -> None:
    cache = MemoryResultCache(max_age_s=600.0)
    t = table(cache=cache)
    for i, at in enumerate([0.0, 100.0, 700.0]):
        t.admit(call(f"c{i}"), "p", local=True)
        finish(t, f"c{i}", now=at)
    assert t.expire(650.0) == 1
    assert "c0" not in cache and "c1" in cache
    assert t.expire(699.0) == 0
    assert t.expire(701.0) == 1 and len(cache) == 1 and "c2" in cache
    assert isinstance(t.admit(call("c0"), "p", local=True), Start)  # forgotten: runs again


def test_each_kept_result_is_charged_its_frame_length_plus_the_overhead() -> None:
    cache = MemoryResultCache()
    t = table(cache=cache)
    t.admit(call("c1"), "p", local=True)
    finish(t, "c1", value="x" * 1000)
    frame = len(encode_frame(result("c1", "x" * 1000)))
    assert cache.nbytes == frame + ENTRY_OVERHEAD
    got = cache.get("c1")
    assert got is not None and got.size == frame


def test_the_byte_cap_drops_the_oldest_results_first() -> None:
    cache = MemoryResultCache(max_bytes=3 * (100 + 512), entry_overhead=512)
    for i in range(5):
        cache.put(kept(f"c{i}", 100, float(i)))
    assert len(cache) == 3 and "c1" not in cache and "c2" in cache and "c4" in cache
    assert cache.nbytes == 3 * 612
    cache.put(kept("big", 600, 9.0))  # 1112 bytes: two of the three older ones make room
    assert [c for c in ("c2", "c3", "c4", "big") if c in cache] == ["c4", "big"]
    assert cache.nbytes == 612 + 1112


def test_the_newest_result_is_kept_even_when_it_alone_exceeds_the_byte_cap() -> None:
    cache = MemoryResultCache(max_bytes=1000, entry_overhead=0)
    cache.put(kept("small", 10, 0.0))
    cache.put(kept("huge", 5000, 1.0))
    assert "huge" in cache and "small" not in cache and cache.nbytes == 5000


def test_putting_an_id_again_replaces_its_result_and_its_charge() -> None:
    cache = MemoryResultCache(entry_overhead=0)
    cache.put(kept("c1", 10, 0.0))
    cache.put(kept("c1", 30, 1.0))
    assert len(cache) == 1 and cache.nbytes == 30


def test_the_memory_cache_holds_the_frame_only_and_charges_what_it_holds() -> None:
    """Issue 22: results were charged their payload bytes while kept as Python objects, many times
    larger for a value of many small items (the node's RSS grew 30 -> 147 MiB under a 64 MiB cap)."""
    import sys

    cache = MemoryResultCache()
    value = list(range(100_000, 300_000))  # 200,000 ints: ~1 MB as a frame, ~7 MB as Python objects
    res = result("c1", value)
    frame = encode_frame(res)
    cache.put(KeptResult("c1", "echo", res, len(frame), 0.0))  # no frame given: encoded by the cache
    stored = cache._kept["c1"]
    assert cache.nbytes == len(frame) + ENTRY_OVERHEAD and stored.frame == frame
    assert sys.getsizeof(stored.frame) < len(frame) + 64 and not hasattr(stored, "result")
    got = cache.get("c1")
    assert got is not None and got.result == res and got.frame == frame


def test_the_cache_bounds_must_be_positive() -> None:
    with pytest.raises(ValueError):
        MemoryResultCache(max_bytes=0)
    with pytest.raises(ValueError):
        MemoryResultCache(max_age_s=0.0)


def test_any_store_with_get_put_and_expire_can_keep_the_results() -> None:
    class DictStore:
        """A stand-in for a store that outlives the node (as an SQLite one would)."""

        def __init__(self) -> None:
            self.rows: dict[str, KeptResult] = {}
            self.expired_at: list[float] = []

        def get(self, call_id: str) -> KeptResult | None:
            return self.rows.get(call_id)

        def put(self, kept: KeptResult) -> None:
            self.rows[kept.call_id] = kept

        def expire(self, now: float) -> int:
            self.expired_at.append(now)
            return 0

        def begin(self, call_id: str, action: str, now: float) -> None:
            pass

        def flush(self) -> None:
            pass

    store = DictStore()
    before_restart = CallTable[str](["echo"], cache=store)
    before_restart.admit(call("c1"), "p", local=True)
    before_restart.finish(result("c1", 7), size=40, now=1.0)
    after_restart = CallTable[str](["echo"], cache=store)  # a new node process, the same store
    verdict = after_restart.admit(call("c1"), "p", local=True)
    assert isinstance(verdict, Answer) and verdict.kept.result.result.value == 7
    after_restart.expire(2.0)
    assert store.expired_at == [2.0]


# --------------------------------------------------------------------------- queries and orphaned calls


def test_a_query_answers_a_kept_result_joins_a_running_call_and_never_starts_anything() -> None:
    t = table()
    t.admit(call("done"), "p1", local=True)
    finish(t, "done", value=3)
    t.admit(call("busy", "wait"), "p1", local=True)
    kept = t.query("done", "q")
    assert isinstance(kept, Answer) and kept.kept.result == result("done", 3)
    joined = t.query("busy", "q")
    assert isinstance(joined, Join) and list(joined.running.waiters) == ["p1", "q"]
    assert t.query("never", "q") == Reject(RejectReason.UNKNOWN_CALL)
    assert t.in_flight == 1 and t.running("never") is None


def test_a_caller_waits_once_however_often_it_repeats_or_queries_an_id() -> None:
    t = table()
    t.admit(call("c1"), "p1", local=True)
    for _ in range(1000):
        t.admit(call("c1"), "p1", local=True)
        t.query("c1", "p1")
    assert finish(t, "c1") == ["p1"]


def test_a_call_whose_last_caller_left_is_cancelled_after_the_grace_period() -> None:
    t = table()
    t.admit(call("c1", "wait"), "p1", local=True)
    t.admit(call("c1", "wait"), "p2", local=True)
    assert t.detach("p1", now=10.0) == []  # p2 still waits
    orphaned = t.detach("p2", now=11.0)
    assert [r.call.id for r in orphaned] == ["c1"] and orphaned[0].orphaned_since == 11.0
    assert t.orphans(now=12.9, grace_s=2.0) == []
    due = t.orphans(now=13.0, grace_s=2.0)
    assert [r.call.id for r in due] == ["c1"] and due[0].cancel_reason == "caller_gone"
    assert t.orphans(now=20.0, grace_s=2.0) == []  # named once


def test_asking_for_an_orphan_again_adopts_it() -> None:
    t = table()
    t.admit(call("c1", "wait"), "p1", local=True)
    t.admit(call("c2", "wait"), "p1", local=True)
    t.detach("p1", now=0.0)
    assert isinstance(t.query("c1", "p2"), Join)
    assert isinstance(t.admit(call("c2", "wait"), "p3", local=True), Join)
    assert t.orphans(now=100.0, grace_s=2.0) == []


def test_an_unattended_action_runs_on_without_its_caller_and_keeps_its_result() -> None:
    t = CallTable[str](["wait", "move"], unattended=["move"])
    t.admit(call("m1", "move"), "p1", local=True)
    t.admit(call("w1", "wait"), "p1", local=True)
    t.detach("p1", now=0.0)
    assert [r.call.id for r in t.orphans(now=100.0, grace_s=2.0)] == ["w1"]
    assert finish(t, "m1", value="moved") == []  # nobody to tell, but the result is kept
    kept = t.query("m1", "later")
    assert isinstance(kept, Answer) and kept.kept.result.result.value == "moved"


def test_a_cancel_keeps_its_first_reason() -> None:
    t = table()
    t.admit(call("c1"), "p", local=True)
    t.cancel("c1", "caller_gone")
    running = t.cancel("c1")
    assert running is not None and running.cancel_reason == "caller_gone" and running.cancel_requested


def test_starts_are_noted_in_the_cache() -> None:
    begun: list[tuple[str, str, float]] = []

    class Recorder(MemoryResultCache):
        def begin(self, call_id: str, action: str, now: float) -> None:
            begun.append((call_id, action, now))

    t = CallTable[str](["echo"], cache=Recorder())
    t.admit(call("c1"), "p", local=True, now=5.0)
    t.admit(call("c1"), "q", local=True, now=6.0)  # a join starts nothing
    assert begun == [("c1", "echo", 5.0)]


def test_unattended_names_must_be_hosted() -> None:
    with pytest.raises(ValueError, match="unattended"):
        CallTable(["echo"], unattended=["move"])
