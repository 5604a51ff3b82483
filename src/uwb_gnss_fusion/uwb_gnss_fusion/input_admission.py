"""What the fusion node admits before its re-ordering buffer: jammer states and exact duplicates.

Pure core (no rclpy): the node turns messages into plain values and asks these; the texts it logs
and the counters it keeps stay in the node.
"""

from __future__ import annotations

import heapq
import math

Key = tuple[str, int, str]
"""What makes a message an exact duplicate: (kind, stamp ns, anchor id or '')."""

JSR_VALID_RANGE_DB = (-100.0, 150.0)
"""J/S accepted from /rfi/jammer_state, dB."""


def admit_jammer_state(
    jammer_type: int, jammer_to_signal_db: float, none_type: int, known_types: frozenset[int]
) -> tuple[float | None, str | None]:
    """The J/S a JammerState gives the filter, or why it is rejected.

    Args:
        jammer_type: the message's ``type``.
        jammer_to_signal_db: the message's J/S, dB.
        none_type: the ``type`` meaning no jammer (JammerState.NONE).
        known_types: every valid ``type`` constant.

    Returns:
        ``(js_db, None)`` with NaN for "no jammer", or ``(None, reason)`` with reason one of
        ``jammer_state_unknown_type``, ``jammer_state_nan`` (a jammer without J/S),
        ``jammer_state_nonphysical`` (outside :data:`JSR_VALID_RANGE_DB`).
    """
    if jammer_type not in known_types:
        return None, 'jammer_state_unknown_type'
    if jammer_type == none_type:
        return math.nan, None
    js = float(jammer_to_signal_db)
    if math.isnan(js):
        return None, 'jammer_state_nan'
    if not (math.isfinite(js) and JSR_VALID_RANGE_DB[0] <= js <= JSR_VALID_RANGE_DB[1]):
        return None, 'jammer_state_nonphysical'
    return js, None


class DuplicateFilter:
    """Keys of accepted messages (:data:`Key`), kept while a copy could still
    arrive in time to be buffered; :meth:`forget_older_than` prunes them by stamp."""

    def __init__(self) -> None:
        self._seen: set[Key] = set()
        self._order: list[tuple[int, Key]] = []  # heap by stamp, for pruning

    def __contains__(self, key: Key) -> bool:
        return key in self._seen

    def __len__(self) -> int:
        return len(self._seen)

    def add(self, key: Key, stamp_ns: int) -> None:
        """Remember an accepted message's key."""
        self._seen.add(key)
        heapq.heappush(self._order, (stamp_ns, key))

    def forget_older_than(self, oldest_ns: int) -> None:
        """Drop the keys stamped before ``oldest_ns``."""
        order = self._order
        while order and order[0][0] < oldest_ns:
            self._seen.discard(heapq.heappop(order)[1])

    def clear(self) -> None:
        """Forget every key."""
        self._seen.clear()
        self._order.clear()
