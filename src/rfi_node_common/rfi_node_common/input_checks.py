"""Pure checks on the input stream of a node: stamp admission and lost-message detection.

No rclpy here (unit-tested without a context); :mod:`rfi_node_common.inputs` wires them to
subscriptions.

* :class:`StampGate` decides whether a header stamp may enter a node's core: stamps <= 0 (an unset or
  negative header) are refused, a stamp further than ``max_jump_s`` from the latest accepted one is
  refused unless ``confirmations`` consecutive messages agree on the jump (a clock or bag restart,
  which the caller then handles as a restart), and, for nodes that need it, a stamp that does not
  increase is refused. One bad stamp therefore never stalls a node: a far-future stamp is refused
  without moving the reference, and the next good one is accepted.
* :class:`SequenceLossCounter` counts messages lost between a publisher and a subscription from the
  gaps in the publisher's sequence numbers (``MessageInfo['publication_sequence_number']``, filled by
  the middleware for every message, reliable or best effort).
"""

from __future__ import annotations

from dataclasses import dataclass

from gnss_common.constants import NS_PER_S

STAMP_NOT_POSITIVE = 'stamp_not_positive'
STAMP_NOT_INCREASING = 'stamp_not_increasing'
STAMP_FAR_FUTURE = 'stamp_far_future'
STAMP_FAR_PAST = 'stamp_far_past'
STAMP_REASONS = (STAMP_NOT_POSITIVE, STAMP_NOT_INCREASING, STAMP_FAR_FUTURE, STAMP_FAR_PAST)
"""Rejection reasons of :class:`StampGate`, as used in the nodes' ``rejected_<reason>`` counters."""


@dataclass(frozen=True)
class StampDecision:
    """What :meth:`StampGate.admit` decided.

    Attributes:
        reason: None if the stamp is accepted, else one of :data:`STAMP_REASONS`.
        restart: the stamp is accepted as the confirmed start of a new time line (a jump of more
            than ``max_jump_s`` seen on ``confirmations`` consecutive messages): the caller resets
            what depends on continuity.
    """

    reason: str | None
    restart: bool = False

    @property
    def accepted(self) -> bool:
        return self.reason is None


_ACCEPT = StampDecision(None)


class StampGate:
    """Admission of header stamps (integer ns) into a node's core.

    Args:
        max_jump_s: a stamp further than this from the latest accepted stamp is refused
            (``stamp_far_future`` / ``stamp_far_past``), s, > 0.
        confirmations: this many consecutive refused stamps, each increasing and within
            ``max_jump_s`` of the previous one, confirm the jump: the last of them is accepted with
            ``restart`` True, >= 1 (1: every jump is accepted as a restart at once).
        strictly_increasing: refuse a stamp <= the latest accepted one (``stamp_not_increasing``);
            False for a node with its own re-ordering buffer, which only needs the jump bound.

    Examples:
        >>> gate = StampGate(max_jump_s=10.0, confirmations=3)
        >>> gate.admit(5 * NS_PER_S).accepted, gate.admit(-1).reason
        (True, 'stamp_not_positive')
        >>> gate.admit(10**18).reason, gate.admit(6 * NS_PER_S).accepted
        ('stamp_far_future', True)
    """

    def __init__(self, max_jump_s: float, confirmations: int, *, strictly_increasing: bool = True) -> None:
        if not max_jump_s > 0:
            raise ValueError(f'max_jump_s must be > 0, got {max_jump_s}')
        if int(confirmations) < 1:
            raise ValueError(f'confirmations must be >= 1, got {confirmations}')
        self.max_jump_ns = int(round(max_jump_s * NS_PER_S))
        self.confirmations = int(confirmations)
        self.strictly_increasing = strictly_increasing
        self.latest_ns: int | None = None
        self._candidate_ns: int | None = None
        self._streak = 0

    def admit(self, stamp_ns: int) -> StampDecision:
        """Decide on ``stamp_ns`` and, if accepted, make it the latest accepted stamp."""
        stamp_ns = int(stamp_ns)
        if stamp_ns <= 0:
            return StampDecision(STAMP_NOT_POSITIVE)
        latest = self.latest_ns
        if latest is not None and abs(stamp_ns - latest) > self.max_jump_ns:
            candidate = self._candidate_ns
            if candidate is not None and candidate < stamp_ns <= candidate + self.max_jump_ns:
                self._streak += 1
            else:
                self._streak = 1
            self._candidate_ns = stamp_ns
            if self._streak < self.confirmations:
                return StampDecision(STAMP_FAR_FUTURE if stamp_ns > latest else STAMP_FAR_PAST)
            self._reset_streak()
            self.latest_ns = stamp_ns
            return StampDecision(None, restart=True)
        self._reset_streak()
        if self.strictly_increasing and latest is not None and stamp_ns <= latest:
            return StampDecision(STAMP_NOT_INCREASING)
        self.latest_ns = stamp_ns if latest is None else max(latest, stamp_ns)
        return _ACCEPT

    def _reset_streak(self) -> None:
        self._candidate_ns = None
        self._streak = 0


class SequenceLossCounter:
    """Messages lost on one subscription, from gaps in the publishers' sequence numbers.

    Every DDS writer numbers its samples 1, 2, 3, ...; a subscription that receives n, then n + k
    from the same writer has lost k - 1 of them (in the middleware's queues, to a full history, or
    on the wire). rclpy's MessageInfo carries the number but not the writer's id, so:

    * with one matched publisher (the usual case) the gaps are exact;
    * with several, a sample is assigned to the stream whose last number is the closest below it
      (their numbers interleave), and while fewer streams than matched publishers have been seen a
      forward jump starts a new stream instead of counting a loss (a publisher that joined with
      higher numbers). A number below every stream's last also starts a new stream (a new or
      restarted publisher).

    The first message of a stream is never a loss: a subscription that joins late did not lose
    what was sent before it existed. A sequence number of 0 (a middleware that does not fill it,
    or an in-process hand-over) is ignored.

    Args:
        max_streams: publishers tracked at once; the least recently seen is forgotten beyond this.
    """

    def __init__(self, max_streams: int = 16) -> None:
        self.max_streams = int(max_streams)
        self._last: list[int] = []  # last sequence number per stream, most recently seen last
        self.lost = 0

    def observe(self, sequence_number: int, publishers: int = 1) -> int:
        """Record one received sequence number; return how many messages this reveals as lost (>= 0).

        Args:
            sequence_number: ``publication_sequence_number`` of the message (0: unknown).
            publishers: publishers currently matched with the subscription (1 if unknown).
        """
        seq = int(sequence_number)
        if seq <= 0:
            return 0
        best = -1
        for i, last in enumerate(self._last):
            if last < seq and (best < 0 or last > self._last[best]):
                best = i
        gap = -1 if best < 0 else seq - self._last[best] - 1
        if best < 0 or (gap > 0 and len(self._last) < max(1, int(publishers))):
            self._last.append(seq)
            while len(self._last) > max(self.max_streams, 1):
                del self._last[0]
            return 0
        del self._last[best]
        self._last.append(seq)
        self.lost += gap
        return gap

    def forget_beyond(self, publishers: int) -> None:
        """Keep only the ``publishers`` most recently seen streams (after publishers left)."""
        keep = max(1, int(publishers))
        if len(self._last) > keep:
            del self._last[:len(self._last) - keep]
