"""From test outcomes to one spoofing state, its scope and its episode (first alarm, first detection).

Pure (no rclpy). The rule, per epoch:

- UNKNOWN: no spoofing test decided (all UNKNOWN): never NONE without a test that ran;
- DETECTED: a test at ALARM, or SUSPECT in at least ``min_categories_for_detection`` independent
  categories (C/N0, clock, kinematics, consistency, external) at once, or a test SUSPECT for
  ``persistence_s`` without a break (a slow attack that stays just above the suspect line);
- SUSPECTED: a test at SUSPECT;
- NONE: otherwise.

Scope (what a consumer excludes): ALL if a DETECTED-making test implicates the whole receiver;
else the constellations it implicates; else its satellites. An episode starts at the first
SUSPECTED or DETECTED epoch and ends after ``clean_period_s`` of NONE; the first-alarm and
first-detection stamps belong to the episode.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass, field

from gnss_common.constants import NS_PER_S
from rfi_node_common.params import check_positive_finite, parameter

from .outcome import (
    DECISION_ALARM,
    DECISION_SUSPECT,
    DECISION_UNKNOWN,
    SCOPE_ALL,
    SCOPE_CONSTELLATIONS,
    SCOPE_NONE,
    SCOPE_SATELLITES,
    STATE_DETECTED,
    STATE_NONE,
    STATE_SUSPECTED,
    STATE_UNKNOWN,
    TestOutcome,
)


@dataclass(frozen=True)
class StateParams:
    """Parameters of the state rule (``persistence_s`` and ``clean_period_s`` are also parameters of
    gnss_integrity_node, ``detection_persistence_s`` and ``clean_period_s``, written here once).

    Attributes:
        min_categories_for_detection: SUSPECT tests in this many categories at once make DETECTED.
    """

    min_categories_for_detection: int = 2
    persistence_s: float = parameter(
        10.0, "A test SUSPECT this long without a break makes the spoofing state DETECTED, s.",
        minimum=0.1, maximum=3600.0)
    clean_period_s: float = parameter(
        30.0, "NONE for this long ends an alarm episode (first_alarm_stamp and first_detection_stamp reset), s.",
        minimum=0.1, maximum=3600.0)

    def __post_init__(self) -> None:
        if int(self.min_categories_for_detection) < 2:
            raise ValueError("StateParams.min_categories_for_detection must be >= 2")
        check_positive_finite(self, ("persistence_s", "clean_period_s"))


@dataclass(frozen=True)
class SpoofingVerdict:
    """The state of one epoch (see rfi_msgs/GnssIntegrity).

    Attributes:
        state: ``STATE_*``.
        scope: ``SCOPE_*`` (SCOPE_NONE unless DETECTED).
        constellations: implicated constellations, ascending.
        satellites: implicated ``(constellation, svid)``, ascending.
        first_alarm_ns: first SUSPECTED/DETECTED stamp of the episode (0: none).
        first_detection_ns: first DETECTED stamp of the episode (0: none).
        deciding: names of the tests that made the state.
    """

    state: int
    scope: int
    constellations: tuple[int, ...]
    satellites: tuple[tuple[int, int], ...]
    first_alarm_ns: int
    first_detection_ns: int
    deciding: tuple[str, ...]


@dataclass
class SpoofingState:
    """Turns each epoch's spoofing outcomes into a :class:`SpoofingVerdict` (module docstring)."""

    params: StateParams = field(default_factory=StateParams)

    def __post_init__(self) -> None:
        self._suspect_since: dict[tuple, int] = {}  # (test, satellites it names) -> first SUSPECT stamp
        self._first_alarm_ns = 0
        self._first_detection_ns = 0
        self._clean_since: int | None = None

    def reset(self) -> None:
        """End any episode and forget persistence."""
        self.__post_init__()

    def update(self, stamp_ns: int, outcomes: Iterable[TestOutcome]) -> SpoofingVerdict:
        """The verdict of one epoch from its spoofing tests (jamming tests excluded by the caller)."""
        p = self.params
        outs = list(outcomes)
        decided = [o for o in outs if o.decision != DECISION_UNKNOWN]
        suspects = [o for o in decided if o.decision >= DECISION_SUSPECT]
        # persistence is per test and per set of satellites it names: outlier bursts that move from
        # satellite to satellite (a weak jammer, multipath) are faults, not one held finding
        keys = {(o.name, o.satellites) for o in suspects}
        for key in keys:
            self._suspect_since.setdefault(key, stamp_ns)
        for key in list(self._suspect_since):
            if key not in keys:
                del self._suspect_since[key]
        alarms = [o for o in suspects if o.decision == DECISION_ALARM]
        persistent = [o for o in suspects
                      if stamp_ns - self._suspect_since[(o.name, o.satellites)] >= p.persistence_s * NS_PER_S]
        categories = {o.category for o in suspects}
        if not decided:
            state = STATE_UNKNOWN
        elif alarms or persistent or len(categories) >= p.min_categories_for_detection:
            state = STATE_DETECTED
        elif suspects:
            state = STATE_SUSPECTED
        else:
            state = STATE_NONE
        deciding = alarms + persistent if (alarms or persistent) else suspects
        self._episode(stamp_ns, state)
        scope = SCOPE_NONE
        constellations: tuple[int, ...] = ()
        satellites: tuple[tuple[int, int], ...] = ()
        if state == STATE_DETECTED:
            scope, constellations, satellites = _scope(deciding)
        elif state == STATE_SUSPECTED:
            _, constellations, satellites = _scope(deciding)
        return SpoofingVerdict(state, scope, constellations, satellites, self._first_alarm_ns,
                               self._first_detection_ns, tuple(sorted({o.name for o in deciding})))

    def _episode(self, stamp_ns: int, state: int) -> None:
        if state in (STATE_SUSPECTED, STATE_DETECTED):
            self._clean_since = None
            if self._first_alarm_ns == 0:
                self._first_alarm_ns = stamp_ns
            if state == STATE_DETECTED and self._first_detection_ns == 0:
                self._first_detection_ns = stamp_ns
            return
        if state == STATE_NONE:
            if self._clean_since is None:
                self._clean_since = stamp_ns
            if stamp_ns - self._clean_since >= self.params.clean_period_s * NS_PER_S:
                self._first_alarm_ns = self._first_detection_ns = 0


def _scope(deciding: list[TestOutcome]) -> tuple[int, tuple[int, ...], tuple[tuple[int, int], ...]]:
    constellations = sorted({c for o in deciding for c in o.constellations})
    satellites = sorted({s for o in deciding for s in o.satellites})
    if any(o.scope == SCOPE_ALL for o in deciding) or not (constellations or satellites):
        return SCOPE_ALL, tuple(constellations), tuple(satellites)
    if constellations:
        return SCOPE_CONSTELLATIONS, tuple(constellations), tuple(satellites)
    return SCOPE_SATELLITES, (), tuple(satellites)
