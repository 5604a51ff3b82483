"""Which analysis an IF block gets: full, light or none (shed). Pure: no rclpy, no clock read here.

Issue 26 item 1: replays are analysed in full, always; shedding and the light analysis are a safety net for
live streams only.

Live (the definition the node and the docs use): a *time line* of blocks (from the node's start, or from a stamp
restart the StampGate confirmed) is live when its first block's stamp lies within ``live_bound_s``
(:data:`LIVE_BOUND_S`, 1 s) of the receive clock, either side. The receive clock is the middleware's reception
time of the message (rmw ``received_timestamp``, the system clock), or the system clock when the block is judged
if the middleware does not report it. Every block of a live time line is a live block; every block of any other
time line is not.

* A front end stamped with the clock (if_source ``pace: real_time``, an SDR driver) is live.
* A bag (``if_to_bag`` output, a scenario bag, a recording), whatever the replay speed (``play --max``,
  ``--rate 10``, ``--rate 1``), carries the stamps it was recorded with, seconds to years in the past: not live.

A block that is not live gets the full analysis, whatever the CPU it costs: nothing is shed, nothing is light.
The wall clock then decides nothing at all, so a replay at any speed gives the same answers, block for block, as
a replay at 1x (time comes from the stamps).

A live block (the safety net; the node's module docstring, "Load shedding"):

1. ``max_block_age_s`` > 0 and stamped more than that behind the clock when it is handled (the receive clock plus
   the time it waited in the node's input queue): SHED (``shed_stale``). Judged at handling, not at reception: a
   block that arrived on time but then waited behind a slow analysis would be answered late whatever it gets;
2. ``max_cpu_load`` 0: FULL;
3. every block earns ``max_cpu_load`` times the stream time it covers (its duration, or the time since the last
   block when longer); the node charges the CPU time it spends (:meth:`LoadPolicy.spend`). In credit: FULL,
   unless (light analysis allowed) the block waited more than :data:`LIGHT_QUEUE_S` in the input queue or is
   stamped more than :data:`LIGHT_LAG_FRACTION` of ``max_block_age_s`` behind the clock at handling: LIGHT.
   In debt: LIGHT while the debt is at most ``light_analysis_debt_s`` (light analysis allowed), else SHED. Credit
   and debt are capped at :data:`SHED_CREDIT_CAP_S`.

Every decision is counted (:attr:`LoadPolicy.counts`: ``full``, ``light``, ``shed``, ``shed_stale`` of them,
and ``not_live`` for the blocks judged not live), and the node puts the counts on /diagnostics.
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass

FULL, LIGHT, SHED = 'full', 'light', 'shed'
"""What the load decision gives a block: the full analysis, the light one, none."""

NS_PER_S = 1_000_000_000

LIVE_BOUND_S = 1.0
"""A time line is live when its first block is stamped within this many seconds of the receive clock, either side,
s (module docstring). A replay's stamps lie further in the past; a live front end's lag (driver buffering, DDS, the
input queue) is milliseconds."""
LIGHT_QUEUE_S = 0.01
"""A live block that waited longer than this in the input queue (from its reception by the middleware to its
callback), s, gets the light analysis even when the CPU budget allows the full one: the budget counts the node
thread's CPU time, not what the machine leaves it, so the queue is what shows that the node does not get the core it
is budgeted. Never a replay's block (replays queue up by design)."""
LIGHT_LAG_FRACTION = 0.2
"""... and so does a live block stamped more than this share of ``max_block_age_s`` behind the clock at handling (the
same for a middleware that does not report reception times)."""
SHED_CREDIT_CAP_S = 0.1
"""CPU credit saved while idle, and CPU debt, are capped at this much (credit: times max_cpu_load), s: a burst of
slow blocks after a quiet spell is absorbed, a lasting overload is not, and a one-off cost sheds at most this much
of a live stream."""


@dataclass(frozen=True)
class LoadPolicyParams:
    """Settings of :class:`LoadPolicy` (the node's parameters of the same names).

    Attributes:
        max_cpu_load: share of one core a live stream's analysis may use over the stream time its blocks cover;
            0: every live block in full (only the age limit sheds).
        light_analysis_debt_s: CPU debt, s, up to which an over-budget live block gets the light analysis
            instead of being shed; 0: no light analysis.
        max_block_age_s: a live block stamped more than this behind the clock when handled is shed, s; 0: off.
        light_allowed: the estimator has a light analysis (stft).
        live_bound_s: :data:`LIVE_BOUND_S`.
    """

    max_cpu_load: float = 0.9
    light_analysis_debt_s: float = 0.02
    max_block_age_s: float = 0.05
    light_allowed: bool = True
    live_bound_s: float = LIVE_BOUND_S

    def __post_init__(self) -> None:
        for name in ('max_cpu_load', 'light_analysis_debt_s', 'max_block_age_s', 'live_bound_s'):
            v = getattr(self, name)
            if not v >= 0.0:                 # False for NaN
                raise ValueError(f'{name} must be >= 0, got {v}')


def is_live_stamp(stamp_ns: int, receive_ns: int, live_bound_s: float = LIVE_BOUND_S) -> bool:
    """Whether a block stamped ``stamp_ns`` and received at ``receive_ns`` (both ns of the same clock, the system
    clock's epoch) is stamped within ``live_bound_s`` of its reception, either side."""
    return abs(receive_ns - stamp_ns) <= live_bound_s * NS_PER_S


class LoadPolicy:
    """The load decision of one node input (module docstring). Holds the time line's liveness and the CPU
    balance; the caller passes the clock readings in.

    Example:
        >>> p = LoadPolicy(LoadPolicyParams(max_cpu_load=1e-6))
        >>> p.decide(stamp_ns=10**9, receive_ns=10**18, covered_s=1e-3)     # a replay: full, whatever the debt
        'full'
        >>> p.spend(1.0); p.decide(stamp_ns=2 * 10**9, receive_ns=10**18, covered_s=1e-3)
        'full'
        >>> p.counts['full'], p.counts['not_live'], p.live
        (2, 2, False)
    """

    def __init__(self, params: LoadPolicyParams) -> None:
        self.params = params
        self.live: bool | None = None
        """None until the first block of the current time line is judged."""
        self.counts: Counter[str] = Counter()
        self._debt_s = 0.0
        self._last_stamp_ns: int | None = None

    @property
    def debt_s(self) -> float:
        """CPU debt of the live stream, s (negative: credit)."""
        return self._debt_s

    def restart(self) -> None:
        """A new time line (a confirmed stamp jump): its liveness is judged again on its first block."""
        self.live = None
        self._last_stamp_ns = None
        self._debt_s = 0.0

    def spend(self, cpu_s: float) -> None:
        """Charge CPU time the node spent on its input (s; counted against live streams only)."""
        if self.live:
            self._debt_s = min(self._debt_s + cpu_s, SHED_CREDIT_CAP_S)

    def decide(self, stamp_ns: int, receive_ns: int, covered_s: float = 0.0, queued_s: float | None = None) -> str:
        """FULL, LIGHT or SHED for one block (module docstring), counted.

        Args:
            stamp_ns: the block's stamp (the StampGate accepted it), ns.
            receive_ns: the receive clock at the block (rmw reception time, or the system clock), ns.
            covered_s: the block's duration, s (0 when unknown: the time since the last block counts).
            queued_s: how long the block waited in the input queue, s (None: not reported).
        """
        if self.live is None:
            self.live = is_live_stamp(stamp_ns, receive_ns, self.params.live_bound_s)
        mode = self._decide_live(stamp_ns, receive_ns, covered_s, queued_s) if self.live else FULL
        if not self.live:
            self.counts['not_live'] += 1
        self.counts[mode] += 1
        return mode

    def _decide_live(self, stamp_ns: int, receive_ns: int, covered_s: float, queued_s: float | None) -> str:
        p = self.params
        if self._last_stamp_ns is not None and stamp_ns > self._last_stamp_ns:
            covered_s = max(covered_s, (stamp_ns - self._last_stamp_ns) / NS_PER_S)
        if self._last_stamp_ns is None or stamp_ns > self._last_stamp_ns:
            self._last_stamp_ns = stamp_ns
        behind_ns = receive_ns - stamp_ns + (round(queued_s * NS_PER_S) if queued_s is not None else 0)   # handled now
        age = p.max_block_age_s
        if age > 0 and behind_ns > age * NS_PER_S:
            self.counts['shed_stale'] += 1
            return SHED
        if not p.max_cpu_load > 0:
            return FULL
        light = p.light_analysis_debt_s > 0 and p.light_allowed
        lagging = light and ((queued_s is not None and queued_s > LIGHT_QUEUE_S)
                             or (age > 0 and behind_ns > LIGHT_LAG_FRACTION * age * NS_PER_S))
        self._debt_s = min(max(self._debt_s - p.max_cpu_load * covered_s, -p.max_cpu_load * SHED_CREDIT_CAP_S),
                           SHED_CREDIT_CAP_S)
        if not self._debt_s > 0.0:
            return LIGHT if lagging else FULL
        return LIGHT if light and self._debt_s <= p.light_analysis_debt_s else SHED
