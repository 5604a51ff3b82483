"""The input nodes' wait for their subscribers (rfi_experiments.source_start), with stand-ins for rclpy."""

from __future__ import annotations

from rfi_experiments.source_start import POLL_S, wait_for_subscribers


class Publisher:
    def __init__(self, counts):
        self.counts = list(counts)  # successive answers of get_subscription_count; the last one repeats

    def get_subscription_count(self):
        return self.counts.pop(0) if len(self.counts) > 1 else self.counts[0]


class Stop:
    """An event that records its waits instead of sleeping (set after ``set_after`` waits)."""

    def __init__(self, set_after=None):
        self.waits = []
        self.set_after = set_after

    def is_set(self):
        return self.set_after is not None and len(self.waits) >= self.set_after

    def wait(self, timeout_s):
        self.waits.append(timeout_s)
        return self.is_set()


class Logger:
    def __init__(self):
        self.warnings = []

    def warn(self, text):
        self.warnings.append(text)


def test_waits_until_the_subscribers_have_matched_then_settles():
    stop, log = Stop(), Logger()
    wait_for_subscribers(Publisher([0, 0, 1, 2]), 2, 3600.0, stop, log, settle_s=0.5)
    assert stop.waits == [POLL_S, POLL_S, POLL_S, 0.5] and not log.warnings


def test_no_wait_without_subscribers_wanted_nor_settle_by_default():
    stop = Stop()
    wait_for_subscribers(Publisher([0]), 0, 3600.0, stop, Logger(), settle_s=0.5)
    wait_for_subscribers(Publisher([1]), 1, 3600.0, stop, Logger())
    assert stop.waits == []


def test_the_timeout_warns_and_starts_anyway():
    stop, log = Stop(), Logger()
    wait_for_subscribers(Publisher([1]), 3, 0.0, stop, log, settle_s=0.5)
    assert log.warnings == ['1 of 3 subscribers after 0.0 s: starting anyway'] and stop.waits == []


def test_stop_ends_the_wait():
    stop, log = Stop(set_after=2), Logger()
    wait_for_subscribers(Publisher([0]), 1, 3600.0, stop, log, settle_s=0.5)
    assert len(stop.waits) == 3 and stop.waits[:2] == [POLL_S, POLL_S] and not log.warnings
