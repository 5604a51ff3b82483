"""What the fusion node admits, and in which order it hands it to the core.

Pure core (no rclpy): the node turns messages into plain values (:class:`Item`) and offers them to an
:class:`InputAdmission`, which rejects and counts, re-orders and releases them to a callback;
:func:`admit_jammer_state` and :class:`DuplicateFilter` are its pieces.

Order. Inputs pass through a re-ordering buffer (:class:`.reorder_buffer.ReorderBuffer`): a message is
processed once a message stamped the window later has arrived, so measurements that arrive up to that
much out of order are applied in stamp order (the outputs lag by the window). At equal stamps a
/gnss/integrity verdict or a /rfi/jammer_state goes before the measurements: gnss_integrity's verdict
of an epoch carries the epoch's stamp and is computed from it, so it arrives after it, and within the
window it still decides whether that epoch is fused (bags/spoofed: the epoch of the first detection is
excluded, not fused and then excluded). Later arrivals are rejected and counted
(``late_beyond_reorder_window``). Stamps pass :class:`rfi_node_common.input_checks.StampGate` first: a
stamp more than ``max_stamp_jump_s`` away from the latest accepted one is rejected (``stamp_far_future``
/ ``stamp_far_past``) unless ``stamp_jump_confirmations`` messages in a row agree on the jump (a clock or
bag restart): then the pending messages are processed and the filter restarts (``time_jump_restarts``).
Stamps <= 0 are rejected (``stamp_not_positive``: an unset header). Exact duplicates are rejected
(``duplicate_gnss_epoch``: the stamp of an epoch already accepted; ``duplicate_uwb_range``: the stamp
and anchor id of a range already accepted).

Re-ordering window: latency against late rejections. The window starts at ``reorder_window_s`` (0.1 s:
a GNSS receiver delivers its epoch 50-100 ms after the measurement time) and every output lags the
newest input by it. On a loaded computer the inputs also arrive late relative to each other: the
executor takes one message per topic and turn, so a UWB backlog (60 ranges/s) falls behind the GNSS
epochs by about as long as the node was starved (566 ranges of one 1x replay through separate
processes came later than 0.1 s). So the window adapts: a late arrival is still rejected, but the
window grows to 1.5 times how late it was (``reorder_window_growths``), up to ``reorder_window_max_s``
(1 s of outputs lag at most; it never shrinks while the node runs; a message later than that maximum
leaves the window as it is: no window would have taken it). Measured with the node as its own process
fed 20 s of bags/default at 1x and stopped twice (SIGSTOP) to mimic a starved CPU: the ranges came up
to 0.9 times the stop late; stops of 0.6 s: a fixed 0.1 s window rejected 44 ranges, the adaptive one
10 (in the first stop only); stops of 1.5 s: 140 and 40 (window at its 1 s maximum). With in-order
input (a bag replayed in one process) nothing is late and the window stays where it started; the order
of processing never depends on the window, only the lag of the outputs does.
``reorder_window_max_s`` <= ``reorder_window_s`` keeps the window fixed.

End of input. What the buffer holds is processed (in stamp order, exactly as a newer message would
have released it) by :meth:`InputAdmission.flush` (the node calls it at a replay's end, when no input
has arrived for ``idle_flush_s`` of wall time, and when it is destroyed). This changes only when
buffered messages are processed, never their order or the results; a message that arrives afterwards
with a stamp older than the last one processed is rejected as late, as any late message.
"""

from __future__ import annotations

import heapq
import math
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from rfi_node_common.input_checks import STAMP_NOT_POSITIVE, StampGate

from .reorder_buffer import ReorderBuffer, widened_window_ns

_NS = 1_000_000_000
KINDS = ('gnss', 'uwb', 'jammer', 'integrity')
"""Input kinds, as used in the counter names (``<kind>_received`` ...)."""

COUNTERS = (tuple(f'{k}_{what}' for k in KINDS for what in ('received', 'rejected', 'processed'))
            + ('reorder_window_growths', 'idle_flushes', 'end_of_input_flushes', 'publish_exceptions',
               'satellites_used', 'satellites_rejected', 'uwb_used', 'uwb_rejected_by_filter', 'divergences',
               'nonfinite_estimates_suppressed', 'parameter_changes'))
"""The node's counters that exist from the start (at zero, so that every report lists them); others
appear when first counted."""

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


def jammer_rejection_text(reason: str, jammer_type: int, jammer_to_signal_db: float) -> str:
    """What the node logs when :func:`admit_jammer_state` rejects a JammerState for ``reason``."""
    if reason == 'jammer_state_unknown_type':
        return f'JammerState type {jammer_type} is not a JammerState constant: ignored'
    if reason == 'jammer_state_nan':
        return 'JammerState with a jammer type but a NaN J/S ignored'
    return f'JammerState J/S {jammer_to_signal_db} dB ignored'


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


@dataclass(frozen=True)
class Item:
    """One input on its way to the core: ``kind`` one of :data:`KINDS`, ``payload`` the converted message
    (``GnssEpoch``, ``UwbRangeMeasurement``, a J/S in dB or an ``IntegrityVerdict``);
    ``dropped_satellites``: satellites of an epoch the node's checks dropped."""

    stamp_ns: int
    kind: str
    payload: Any
    dropped_satellites: int = 0


Log = Callable[[str, str], None]
"""``log(text, level)``: a warning for the node's logger, ``level`` ``'warn'`` or ``'warn_throttled'`` (at
most one per ``warning_throttle_s``)."""


class InputAdmission:
    """The admission and re-ordering state machine of the fusion node (module docstring).

    Args:
        reorder_window_s: the initial re-ordering window, s (>= 0).
        reorder_window_max_s: the largest it may grow to, s.
        max_stamp_jump_s, stamp_jump_confirmations: the stamp gate's (:class:`StampGate`).
        process: called with each released :class:`Item`, in stamp order.
        restart: called after a confirmed stamp jump, once the pending items are processed: the
            caller starts a fresh filter.
        log: warnings (:data:`Log`).
        before_release: called before any item is released (the node applies parameter changes there).

    Attributes:
        counts: the node's counters (``<kind>_received`` / ``_rejected`` / ``_processed`` ...; the node
            and the core add their own).
        reasons: rejections by reason.
    """

    def __init__(self, reorder_window_s: float, reorder_window_max_s: float, max_stamp_jump_s: float,
                 stamp_jump_confirmations: int, process: Callable[[Item], None],
                 restart: Callable[[], None], log: Log, before_release: Callable[[], None]) -> None:
        self.counts: Counter[str] = Counter(dict.fromkeys(COUNTERS, 0))
        self.reasons: Counter[str] = Counter()
        self._buffer = ReorderBuffer(round(reorder_window_s * _NS))
        self._window_max_ns = round(reorder_window_max_s * _NS)
        self._buffered: Counter[str] = Counter()
        self._gate = StampGate(max_stamp_jump_s, stamp_jump_confirmations, strictly_increasing=False)
        self._released_ns: int | None = None  # stamp of the last message released to the core
        self._seen = DuplicateFilter()  # exact duplicates: keys kept while a copy could still be buffered
        self._process = process
        self._restart_core = restart
        self._log = log
        self._before_release = before_release

    @property
    def latest_ns(self) -> int | None:
        """The latest accepted stamp, ns (None before the first)."""
        return self._gate.latest_ns

    @property
    def buffered(self) -> dict[str, int]:
        """Messages waiting in the re-ordering buffer, per kind."""
        return {kind: self._buffered[kind] for kind in KINDS}

    @property
    def reorder_window_s(self) -> float:
        """The re-ordering window now, s (``reorder_window_s`` at start, widened by late arrivals)."""
        return self._buffer.window_ns / _NS

    def seen(self, key: Key) -> bool:
        """Whether a message with this key was accepted (and may still be buffered)."""
        return key in self._seen

    def reject(self, kind: str, reason: str, text: str) -> None:
        """Count a ``kind`` message rejected for ``reason`` and log ``text`` (throttled)."""
        self.counts[f'{kind}_rejected'] += 1
        self.reasons[reason] += 1
        self._log(f'{text} ({reason})', 'warn_throttled')

    def offer(self, item: Item, key: Key | None = None) -> bool:
        """Admit the item (duplicate, stamp, lateness), buffer it and process everything the buffer
        releases. ``key``: what makes it an exact duplicate (kind, stamp, anchor id). Returns whether
        it was buffered."""
        stamp_ns = item.stamp_ns
        if key is not None and key in self._seen:
            self.reject(item.kind, f'duplicate_{"gnss_epoch" if item.kind == "gnss" else "uwb_range"}',
                        f'{item.kind} message stamped {stamp_ns} ns{f" from anchor {key[2]!r}" if key[2] else ""} '
                        'was already accepted')
            return False
        previous_ns = self._gate.latest_ns
        decision = self._gate.admit(stamp_ns)
        if not decision.accepted:
            reason = str(decision.reason)
            if reason == STAMP_NOT_POSITIVE:
                text = f'{item.kind} message with stamp {stamp_ns} ns'
            else:
                text = (f'{item.kind} stamp {stamp_ns} ns is {(stamp_ns - (previous_ns or 0)) / _NS:+.3f} s from the '
                        f'latest {previous_ns} ns')
            self.reject(item.kind, reason, text)
            return False
        if decision.restart:
            self._restart(stamp_ns, previous_ns)
        # a verdict or a J/S of an instant applies to the measurements of that instant
        if not self._buffer.push(item, context=item.kind in ('integrity', 'jammer')):
            self._late(item)
            return False
        if key is not None:
            self._seen.add(key, stamp_ns)
        self._buffered[item.kind] += 1
        latest_ns = self._gate.latest_ns
        assert latest_ns is not None  # the stamp just accepted
        self._release(self._buffer.pop_ready(latest_ns))
        return True

    def flush(self, counter: str) -> int:
        """Process every buffered message now, in stamp order; ``counter`` counts the flushes that
        processed any. Returns how many were processed."""
        items = self._buffer.flush()
        if items:
            self.counts[counter] += 1
            self._release(items)
        return len(items)

    def _late(self, item: Item) -> None:
        """Reject a message older than one already processed, and widen the window to cover such lateness."""
        late_ns = (self._gate.latest_ns or item.stamp_ns) - item.stamp_ns
        window_ns = self._buffer.window_ns
        self.reject(item.kind, 'late_beyond_reorder_window',
                    f'{item.kind} stamp {item.stamp_ns} ns arrived {late_ns / _NS:.3f} s after a newer message, '
                    f'later than the re-ordering window {window_ns / _NS:.3f} s')
        wanted_ns = widened_window_ns(window_ns, late_ns, self._window_max_ns)
        if wanted_ns is not None:
            self._buffer.window_ns = wanted_ns
            self.counts['reorder_window_growths'] += 1
            self._log(f're-ordering window widened to {wanted_ns / _NS:.3f} s (inputs arrive late; '
                      f'maximum reorder_window_max_s {self._window_max_ns / _NS:g} s)', 'warn')

    def _release(self, items: list) -> None:
        self._before_release()
        for ready in items:
            self._buffered[ready.kind] -= 1
            self._released_ns = ready.stamp_ns
            self._process(ready)
        if items:
            self._forget_released()

    def _forget_released(self) -> None:
        """Drop the duplicate keys stamped more than the largest window before the last released
        message: a copy that late is rejected as late (and would not widen the window); a copy
        less late is recognised as a duplicate (and does not widen it either)."""
        if self._released_ns is not None:
            self._seen.forget_older_than(self._released_ns - max(self._window_max_ns, self._buffer.window_ns))

    def _restart(self, stamp_ns: int, previous_ns: int | None) -> None:
        """A confirmed stamp jump: finish the pending messages, then start a fresh filter."""
        self._release(self._buffer.flush())
        self.counts['time_jump_restarts'] += 1
        self._log(f'stamps jumped to {stamp_ns} ns (from {previous_ns} ns): filter restarted', 'warn')
        self._restart_core()
        self._buffer = ReorderBuffer(self._buffer.window_ns)
        self._released_ns = None
        self._seen.clear()
