"""Connection caps, the handshake deadline and login throttling (services.node.guard), as pure logic."""

from __future__ import annotations

import pytest

from services.node.guard import AuthThrottle, Caps, ConnectionGuard, budget_caps


def guard(**caps: float) -> ConnectionGuard[str]:
    caps.setdefault("reserved_pending", 0)  # no slots kept for known addresses unless a test asks
    return ConnectionGuard(Caps(**caps))  # type: ignore[arg-type]


def test_the_oldest_pending_connection_of_an_address_makes_room_for_a_new_one() -> None:
    g = guard(max_pending_per_host=2, max_pending=100)
    assert g.accept("a1", "10.0.0.9", 0.0) == []
    assert g.accept("a2", "10.0.0.9", 1.0) == []
    assert g.accept("a3", "10.0.0.9", 2.0) == ["a1"]
    assert g.accept("b1", "10.0.0.7", 3.0) == []  # another address is not affected
    assert g.pending == 3


def test_at_the_total_cap_the_address_holding_most_pending_connections_makes_room() -> None:
    g = guard(max_pending=4, max_pending_per_host=4)
    g.accept("legit", "10.0.0.1", 0.0)  # the oldest, but alone on its address
    for i in range(3):
        g.accept(f"flood{i}", "10.0.0.66", 1.0 + i)
    assert g.accept("flood3", "10.0.0.66", 5.0) == ["flood0"]
    assert g.accept("other", "10.0.0.77", 6.0) == ["flood1"]
    assert g.oldest_pending() == "legit"


def test_among_addresses_holding_as_many_the_first_listed_makes_room() -> None:
    g = guard(max_pending=3, max_pending_per_host=3)
    for i, host in enumerate(["h1", "h2", "h3"]):
        g.accept(f"c{i}", host, float(i))
    assert g.accept("c3", "h4", 3.0) == ["c0"]
    assert g.oldest_pending() == "c1"


def test_a_real_client_that_finishes_its_handshake_is_never_pushed_out() -> None:
    g = guard(max_pending=2, max_pending_per_host=2)
    g.accept("legit", "h", 0.0)
    assert g.authenticate("legit")
    assert g.accept("x1", "h", 1.0) == [] and g.accept("x2", "h", 1.0) == []
    assert g.accept("x3", "h", 1.0) == ["x1"]
    assert (g.open, g.pending) == (1, 2)


def test_open_connections_are_capped_in_total_and_per_address() -> None:
    g = guard(max_open=3, max_open_per_host=2)
    for c, h in [("a", "h1"), ("b", "h1"), ("c", "h1"), ("d", "h2"), ("e", "h3")]:
        g.accept(c, h, 0.0)
    assert [g.authenticate(c) for c in "abcde"] == [True, True, False, True, False]
    g.close("a")
    g.accept("f", "h1", 0.0)
    assert g.authenticate("f") and g.open == 3


def test_pending_connections_past_the_handshake_deadline_are_named_oldest_first() -> None:
    g = guard(handshake_timeout_s=2.0)
    g.accept("early", "h", 0.0)
    g.accept("late", "h", 1.5)
    g.accept("done", "h", 0.5)
    g.authenticate("done")
    assert list(g.overdue(1.9)) == []
    assert list(g.overdue(2.0)) == ["early"]
    assert list(g.overdue(10.0)) == ["early", "late"]
    g.close("early")
    g.close("never seen")  # harmless
    assert list(g.overdue(10.0)) == ["late"]


def test_closing_forgets_a_connection_in_either_state() -> None:
    g = guard()
    g.accept("p", "h", 0.0)
    g.accept("o", "h", 0.0)
    g.authenticate("o")
    g.close("p")
    g.close("o")
    assert (g.open, g.pending, g.oldest_pending()) == (0, 0, None)
    assert not g.authenticate("p")  # closed before its handshake ended


def test_caps_shrink_to_fit_under_the_file_descriptor_limit() -> None:
    want = Caps()
    assert budget_caps(want, fd_limit=20000, fds_in_use=10) == want
    small = budget_caps(want, fd_limit=1024, fds_in_use=10)
    assert small == want  # 256 + 128 fit under 1024 - 10 - 64
    tiny = budget_caps(want, fd_limit=256, fds_in_use=20)
    assert tiny.max_open + tiny.max_pending <= 256 - 20 - 64
    assert tiny.max_pending == (256 - 20 - 64) // 4 and tiny.max_pending_per_host <= tiny.max_pending
    assert budget_caps(want, fd_limit=10, fds_in_use=50).max_open >= 1


def test_caps_must_be_positive() -> None:
    with pytest.raises(ValueError):
        Caps(max_pending=0)
    with pytest.raises(ValueError):
        Caps(handshake_timeout_s=0)


def test_failed_logins_throttle_their_address_until_tokens_come_back() -> None:
    t = AuthThrottle(burst=3, per_s=2.0)
    for i in range(3):
        assert not t.throttled("10.0.0.9", 0.0)
        t.failed("10.0.0.9", 0.0)
    assert t.throttled("10.0.0.9", 0.1)
    assert not t.throttled("10.0.0.7", 0.1)  # other addresses are not affected
    assert not t.throttled("10.0.0.9", 0.5)  # one token back after 0.5 s
    t.failed("10.0.0.9", 0.5)
    assert t.throttled("10.0.0.9", 0.6)


def test_a_guessing_address_gets_about_per_s_answers_a_second() -> None:
    t = AuthThrottle(burst=20, per_s=5.0)
    answered = 0
    for step in range(10_000):  # 10 s of attempts every millisecond
        now = step / 1000
        if not t.throttled("h", now):
            t.failed("h", now)
            answered += 1
    assert answered <= 20 + 5 * 10 + 1


def test_the_throttle_remembers_a_bounded_number_of_addresses() -> None:
    t = AuthThrottle(burst=1, per_s=0.001, max_hosts=100)
    for i in range(1000):
        t.failed(f"10.0.{i // 256}.{i % 256}", 0.0)
    assert len(t._buckets) == 100
    assert t.throttled("10.0.3.231", 0.0) and not t.throttled("10.0.0.0", 0.0)


def test_new_connections_are_rate_limited_per_address() -> None:
    g = guard(accepts_per_s=10.0, accept_burst=5)
    assert [g.may_accept("h", 0.0) for _ in range(7)] == [True] * 5 + [False] * 2
    assert g.may_accept("other", 0.0)
    assert not g.may_accept("h", 0.05) and g.may_accept("h", 0.1)  # one earned back per 0.1 s
    accepted = sum(g.may_accept("h", 1.0 + i / 1000) for i in range(10_000))  # 10 s of a tight loop
    assert accepted <= 5 + 10 * 10 + 1


def test_a_flood_from_many_new_addresses_never_takes_the_slots_kept_for_known_ones() -> None:
    """Issue 22: 1,200 reconnecting peers from spread addresses kept a legitimate client out."""
    g = guard(max_pending=8, max_pending_per_host=8, reserved_pending=2)
    g.accept("before", "10.0.0.1", 0.0)
    assert g.authenticate("before")  # 10.0.0.1 is known from now on
    flood = [f"f{i}" for i in range(100)]
    evicted = [c for i, c in enumerate(flood) for c in g.accept(c, f"10.9.{i}.1", 1.0 + i / 100)]
    assert g.pending == 6  # unknown addresses hold 6 of 8 at most: 2 stay for known ones
    assert g.accept("legit", "10.0.0.1", 2.5) == [] and g.accept("legit2", "10.0.0.1", 2.6) == []
    assert g.accept("legit3", "10.0.0.1", 2.7) == ["f94"]  # the pending slots are full: the flood gives way
    assert len(evicted) == 94 and g.authenticate("legit") and g.authenticate("legit2")


def test_new_connections_from_unknown_addresses_are_rate_limited_in_total_and_known_ones_are_not() -> None:
    g = guard(new_per_s=10.0, new_burst=5)
    assert [g.within_total(f"10.9.0.{i}", 0.0) for i in range(7)] == [True] * 5 + [False] * 2
    assert g.within_total("10.9.1.1", 0.1)  # a token came back
    g.accept("c", "10.0.0.1", 0.0)
    g.authenticate("c")
    assert all(g.within_total("10.0.0.1", 0.1) for _ in range(100))
    assert g.known("10.0.0.1", 3000.0) and not g.known("10.0.0.1", 4000.0)  # trusted for trust_s (1 h)
