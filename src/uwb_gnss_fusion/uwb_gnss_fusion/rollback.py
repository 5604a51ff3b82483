"""Going back to the filter of before a spoofing alarm (the fusion's answer to a detection).

Pure core (no rclpy). A spoofer drags the filter between its first effect and its detection
(gnss_integrity needs from 0.4 s, with anchors and a careful push, to tens of seconds). Excluding GNSS
at the detection leaves the dragged state, and with fewer than three anchors nothing can re-anchor
it: one range cannot fix a position, and the state keeps the spoofer's velocity.
:class:`RollbackHistory` keeps copies of the filter's state (:meth:`FusionFilter.snapshot`) every
``period_s`` of stamp time for ``keep_s``, and the UWB ranges applied since the oldest. At an
exclusion of all GNSS the node restores the newest copy from before the episode's first alarm
(minus a margin) and applies the ranges since then again, without GNSS: the state is then what the
anchors and the motion model say, as if GNSS had been excluded from the alarm on. Beyond the paper.
"""

from __future__ import annotations

from collections import deque
from typing import Any

NS_PER_S = 1_000_000_000


class RollbackHistory:
    """Snapshots of a filter and the UWB ranges applied since the oldest (module docstring).

    Args:
        period_s: a snapshot at most this often, s of stamp time (> 0).
        keep_s: snapshots this old are dropped, s (>= period_s).
    """

    def __init__(self, period_s: float, keep_s: float) -> None:
        if not (period_s > 0.0 and keep_s >= period_s):
            raise ValueError(f"RollbackHistory: need 0 < period_s <= keep_s, got {period_s}, {keep_s}")
        self.period_ns = int(round(period_s * NS_PER_S))
        self.keep_ns = int(round(keep_s * NS_PER_S))
        self._snapshots: deque[tuple[int, dict[str, Any], int]] = deque()  # stamp, state, ranges before it
        self._ranges: deque[Any] = deque()
        self._dropped = 0  # ranges forgotten from the front
        self.restores = 0

    def clear(self) -> None:
        """Forget everything (a restart of the input, or after a roll-back)."""
        self._snapshots.clear()
        self._ranges.clear()
        self._dropped = 0

    def add_range(self, meas: Any) -> None:
        """A UWB range the filter has just applied (or rejected: it is applied again just the same)."""
        self._ranges.append(meas)

    def note(self, stamp_ns: int, filt: Any) -> None:
        """After the filter processed a message stamped ``stamp_ns``: a snapshot if one is due."""
        if self._snapshots and stamp_ns - self._snapshots[-1][0] < self.period_ns:
            return
        if not getattr(filt, "initialized", True):
            return
        self._snapshots.append((int(stamp_ns), filt.snapshot(), self._dropped + len(self._ranges)))
        while len(self._snapshots) > 1 and stamp_ns - self._snapshots[1][0] >= self.keep_ns:
            self._snapshots.popleft()
        # the ranges older than the oldest snapshot are never applied again
        oldest = self._snapshots[0][2]
        while self._dropped < oldest and self._ranges:
            self._ranges.popleft()
            self._dropped += 1

    def roll_back(self, filt: Any, before_ns: int) -> list[Any] | None:
        """Restore ``filt`` to the newest snapshot stamped at or before ``before_ns``; returns the
        ranges applied after it (to apply again, in order), or None (no snapshot that old: ``filt``
        unchanged). The history is cleared: the restored past is replaced."""
        older = [snap for snap in self._snapshots if snap[0] <= before_ns]
        if not older:
            return None
        _, state, logged = older[-1]
        filt.restore(state)
        replay = list(self._ranges)[logged - self._dropped:]
        self.clear()
        self.restores += 1
        return replay
