"""Stamp admission and sequence-gap loss counting (pure, no rclpy)."""

from __future__ import annotations

import numpy as np
import pytest

from rfi_node_common.input_checks import NS_PER_S, SequenceLossCounter, StampGate

S = NS_PER_S


def test_gate_refuses_unset_and_negative_stamps_without_moving_the_reference():
    gate = StampGate(max_jump_s=10.0, confirmations=3)
    assert gate.admit(0).reason == 'stamp_not_positive'
    assert gate.admit(-5 * S).reason == 'stamp_not_positive'
    assert gate.latest_ns is None
    assert gate.admit(1 * S).accepted
    assert gate.admit(-1).reason == 'stamp_not_positive'
    assert gate.latest_ns == 1 * S


def test_one_far_future_stamp_does_not_stall_the_stream():
    """The fault seen by fuzzing: one stamp in 2200 stalled the monitor for good."""
    gate = StampGate(max_jump_s=120.0, confirmations=5)
    assert gate.admit(100 * S).accepted
    assert gate.admit(2**62).reason == 'stamp_far_future'
    assert gate.admit(101 * S).accepted
    assert gate.admit(1 * S).reason == 'stamp_not_increasing'
    assert gate.admit(102 * S).accepted


def test_far_past_is_refused_and_not_increasing_only_when_strict():
    strict = StampGate(max_jump_s=10.0, confirmations=3)
    loose = StampGate(max_jump_s=10.0, confirmations=3, strictly_increasing=False)
    for gate in (strict, loose):
        assert gate.admit(100 * S).accepted
        assert gate.admit(50 * S).reason == 'stamp_far_past'
    assert strict.admit(99 * S).reason == 'stamp_not_increasing'
    assert loose.admit(99 * S).accepted and loose.latest_ns == 100 * S


def test_a_confirmed_jump_restarts_the_time_line():
    gate = StampGate(max_jump_s=10.0, confirmations=3)
    assert gate.admit(100 * S).accepted
    assert gate.admit(1000 * S).reason == 'stamp_far_future'
    assert gate.admit(1001 * S).reason == 'stamp_far_future'
    decision = gate.admit(1002 * S)
    assert decision.accepted and decision.restart
    assert gate.admit(1003 * S).accepted and not gate.admit(1004 * S).restart


def test_scattered_far_stamps_never_confirm_a_jump():
    """Random far stamps (a fuzzer, a corrupt clock) disagree with each other: no restart."""
    rng = np.random.default_rng(7)
    gate = StampGate(max_jump_s=10.0, confirmations=3)
    assert gate.admit(100 * S).accepted
    for stamp in rng.integers(10**12, 2**62, size=1000):
        assert gate.admit(int(stamp)).reason in ('stamp_far_future', 'stamp_far_past')
    assert gate.latest_ns == 100 * S


def test_a_good_stamp_between_far_ones_breaks_the_streak():
    gate = StampGate(max_jump_s=10.0, confirmations=2)
    assert gate.admit(100 * S).accepted
    assert not gate.admit(1000 * S).accepted
    assert gate.admit(101 * S).accepted
    assert not gate.admit(1001 * S).accepted
    assert gate.admit(1002 * S).restart


def test_gate_arguments_are_checked():
    with pytest.raises(ValueError):
        StampGate(max_jump_s=0.0, confirmations=1)
    with pytest.raises(ValueError):
        StampGate(max_jump_s=1.0, confirmations=0)


def test_loss_counter_counts_gaps_of_one_publisher():
    c = SequenceLossCounter()
    assert [c.observe(s) for s in (5, 6, 9, 10, 20)] == [0, 0, 2, 0, 9]
    assert c.lost == 11


def test_loss_counter_ignores_unnumbered_messages_and_late_joins():
    c = SequenceLossCounter()
    assert c.observe(0) == 0 and c.observe(1000) == 0 and c.observe(0) == 0 and c.observe(1001) == 0
    assert c.lost == 0


def test_loss_counter_separates_interleaved_publishers():
    rng = np.random.default_rng(3)
    a, b = list(range(1, 501)), list(range(40, 540))
    dropped_a = set(rng.choice(a[1:], size=17, replace=False).tolist())
    dropped_b = set(rng.choice(b[1:], size=23, replace=False).tolist())
    stream = []
    for x, y in zip(a, b, strict=True):
        if x not in dropped_a:
            stream.append(x)
        if y not in dropped_b:
            stream.append(y)
    c = SequenceLossCounter()
    for s in stream:
        c.observe(s, publishers=2)
    assert c.lost == 17 + 23


def test_with_one_publisher_a_forward_jump_is_a_loss():
    c = SequenceLossCounter()
    c.observe(1)
    assert c.observe(40) == 38


def test_a_restarted_publisher_starts_a_new_stream():
    c = SequenceLossCounter()
    for s in range(1, 101):
        c.observe(s)
    assert [c.observe(s) for s in (1, 2, 4)] == [0, 0, 1]
    assert c.lost == 1
