"""The sequence numbers a set-point stream takes (services/sequence.py)."""

from __future__ import annotations

import pytest

from services.sequence import SequenceGate, Verdict


def test_a_stream_takes_newer_numbers_within_the_step_and_drops_older_ones():
    gate = SequenceGate(restart_after_s=0.25, max_step=10)
    assert gate.judge(5, now=0.0) is Verdict.START
    assert gate.judge(6, now=0.01) is Verdict.NEXT
    assert gate.judge(16, now=0.02) is Verdict.NEXT
    assert gate.judge(16, now=0.03) is Verdict.OLD and gate.judge(3, now=0.03) is Verdict.OLD
    assert gate.judge(27, now=0.04) is Verdict.JUMP
    assert gate.latest == 16


def test_a_jump_is_refused_while_live_and_restarts_the_stream_after_a_silence_up_or_down():
    gate = SequenceGate(restart_after_s=0.25, max_step=10)
    gate.judge(100, now=0.0)
    assert gate.judge(2**62, now=0.1) is Verdict.JUMP
    assert gate.judge(2**62, now=0.3) is Verdict.RESTART and gate.latest == 2**62
    assert gate.judge(101, now=0.35) is Verdict.OLD  # a forged number holds the stream ...
    assert gate.judge(102, now=0.6) is Verdict.RESTART and gate.latest == 102  # ... for restart_after_s at most
    assert gate.judge(110, now=5.0) is Verdict.NEXT  # in step after a pause: no restart to report
    assert not Verdict.JUMP.taken and not Verdict.OLD.taken and Verdict.RESTART.taken


def test_reset_starts_the_stream_again_and_bad_bounds_are_refused():
    gate = SequenceGate(restart_after_s=1.0)
    gate.judge(50, now=0.0)
    gate.reset()
    assert gate.judge(1, now=0.1) is Verdict.START
    with pytest.raises(ValueError):
        SequenceGate(restart_after_s=0.0)
    with pytest.raises(ValueError):
        SequenceGate(restart_after_s=1.0, max_step=0)
