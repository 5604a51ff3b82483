"""What the two input nodes (``if_source``, ``ubx_source``) share before they read: the wait for subscribers.

A file replayed into a node started at the same moment would lose its first messages to discovery; each
source can hold its input until ``wait_for_subscribers`` subscribers of its main topic have matched, for at
most ``wait_timeout_s`` (the node's parameters; the timeout's definition is :class:`SubscriberWaitParams`).
No rclpy import: the publisher, the stop event and the logger are passed in.
"""

from __future__ import annotations

import threading
import time
from dataclasses import dataclass
from typing import Any

from rfi_node_common.params import parameter

POLL_S = 0.02
"""How often the subscriber count is read while waiting, s (wall clock)."""


@dataclass(frozen=True)
class SubscriberWaitParams:
    """The wait's timeout, defined once; each source adds its own ``wait_for_subscribers`` (it names its topic)."""

    wait_timeout_s: float = parameter(
        30.0, 'Longest wait for wait_for_subscribers, s; then reading starts anyway (with a warning).',
        minimum=0.0, maximum=86400.0)


def wait_for_subscribers(publisher: Any, want: int, timeout_s: float, stop: threading.Event, logger: Any,
                         settle_s: float = 0.0) -> None:
    """Return once ``publisher`` has ``want`` subscribers (then ``settle_s`` later), ``stop`` is set, or
    ``timeout_s`` has passed (wall clock: start-up plumbing, not stamp time), with a warning then.

    Args:
        publisher: the rclpy publisher whose subscriptions are counted.
        want: subscribers to wait for; 0: return at once.
        timeout_s: longest wait, s.
        stop: set when the node is being destroyed (the wait ends at once).
        logger: the node's logger (``warn``).
        settle_s: after the subscribers have matched, wait this much longer, s (their side of discovery
            completes a little later).
    """
    if not want:
        return
    deadline = time.monotonic() + timeout_s
    while publisher.get_subscription_count() < want and not stop.is_set():
        if time.monotonic() >= deadline:
            logger.warn(f'{publisher.get_subscription_count()} of {want} subscribers after {timeout_s} s: '
                        'starting anyway')
            return
        stop.wait(POLL_S)
    if settle_s > 0.0:
        stop.wait(settle_s)
