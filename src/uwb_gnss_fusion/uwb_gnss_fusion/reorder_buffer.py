"""Re-ordering of time-stamped inputs that arrive late, and the policy that widens its window.

Pure core (no rclpy): the node puts every input through a :class:`ReorderBuffer` before the filter,
which rejects anything older than its own time.
"""

from __future__ import annotations

import heapq
import math

REORDER_WINDOW_GROWTH = 1.5
"""A message late by d widens the re-ordering window to this times d (up to the maximum)."""


class ReorderBuffer:
    """Re-orders time-stamped messages that arrive late by up to a fixed window.

    ``push`` stores a message; ``pop_ready(now_ns)`` returns, in stamp order, the messages with
    ``stamp_ns <= now_ns - window_ns``. Messages with equal stamps leave in arrival order, except that
    those pushed with ``context=True`` leave before the others: a verdict or a J/S that describes the
    instant of a measurement applies to that measurement, even when it was computed from it and so
    arrives after it. Messages older than the last released stamp are returned
    by ``push`` as late (the caller counts them) instead of being released out of order.

    Args:
        window_ns: re-ordering window, ns, >= 0 (the latency it adds).
    """

    def __init__(self, window_ns: int) -> None:
        if window_ns < 0:
            raise ValueError("window_ns must be >= 0")
        self.window_ns = int(window_ns)
        self._heap: list[tuple[int, int, int, object]] = []
        self._seq = 0
        self._released_ns: int | None = None
        self.late = 0

    def push(self, msg, context: bool = False) -> bool:
        """Store ``msg`` (anything with an int ``stamp_ns``); ``context``: it leaves before the messages
        of the same stamp that are not. Returns False if it is already too late."""
        if self._released_ns is not None and msg.stamp_ns < self._released_ns:
            self.late += 1
            return False
        heapq.heappush(self._heap, (int(msg.stamp_ns), 0 if context else 1, self._seq, msg))
        self._seq += 1
        return True

    def pop_ready(self, now_ns: int) -> list:
        """Messages with stamp <= now_ns - window_ns, oldest first."""
        out = []
        limit = now_ns - self.window_ns
        while self._heap and self._heap[0][0] <= limit:
            stamp, _, _, msg = heapq.heappop(self._heap)
            self._released_ns = stamp
            out.append(msg)
        return out

    def flush(self) -> list:
        """All stored messages, oldest first."""
        out = []
        while self._heap:
            stamp, _, _, msg = heapq.heappop(self._heap)
            self._released_ns = stamp
            out.append(msg)
        return out


def widened_window_ns(window_ns: int, late_ns: int, window_max_ns: int) -> int | None:
    """The re-ordering window after a message arrived ``late_ns`` later than a newer one.

    Args:
        window_ns: the window now, ns.
        late_ns: how late the message was (stamp of the newest message minus its stamp), ns.
        window_max_ns: the largest window allowed, ns.

    Returns:
        The widened window, ns (``REORDER_WINDOW_GROWTH`` times the lateness, at most
        ``window_max_ns``), or None when it does not grow: the lateness is within the window
        already, or beyond the maximum (no window allowed would have held the message).
    """
    wanted_ns = min(window_max_ns, int(math.ceil(REORDER_WINDOW_GROWTH * late_ns)))
    if wanted_ns > window_ns and late_ns <= window_max_ns:
        return wanted_ns
    return None
