"""What the fusion does with /gnss/integrity: exclude spoofed GNSS, readmit it after a clean period,
and take a jamming J/S from the receiver's C/N0 where no SDR monitor gives one.

Pure core (no rclpy). The node converts each rfi_msgs/GnssIntegrity into an :class:`IntegrityVerdict`
and passes it here in stamp order (through its re-ordering buffer, like every input); every GNSS
epoch then goes through :meth:`GnssExclusion.filter_epoch` before the filter sees it.

Exclusion (issue 25, item 4):

- a DETECTED spoofing state adds what it implicates to the exclusion: all GNSS (``SCOPE_ALL``),
  every satellite of the listed constellations, or the listed satellites; the filter then keeps
  positioning on UWB and its motion model (an excluded epoch still advances nothing: it is
  counted and dropped, never applied);
- SUSPECTED does not exclude (a watch state), and does not count as clean either;
- UNKNOWN freezes the clean timer (no evidence is not clean evidence);
- the exclusion ends only after ``readmit_clean_s`` of NONE without a break (hysteresis), and the
  end is reported (``readmissions``), never silent.

Jamming: a jamming state DETECTED with a finite J/S becomes the filter's J/S (Cao et al., eq. 4
weighting), NONE makes it "no jammer" (NaN); an SDR monitor's /rfi/jammer_state received within
``sdr_precedence_s`` takes precedence (it measures the jammer directly).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

from gnss_common.integrity_codes import (
    SCOPE_ALL,
    SCOPE_CONSTELLATIONS,
    SCOPE_NONE,
    SCOPE_SATELLITES,
    STATE_DETECTED,
    STATE_NONE,
    STATE_SUSPECTED,
    STATE_UNKNOWN,
)
from gnss_common.observations import GnssEpoch

NS_PER_S = 1_000_000_000



@dataclass(frozen=True)
class IntegrityVerdict:
    """The fields of one rfi_msgs/GnssIntegrity the fusion uses.

    Attributes:
        stamp_ns: the message's stamp, ns.
        spoofing_state, spoofing_scope: ``STATE_*``, ``SCOPE_*``.
        constellations: implicated constellations.
        satellites: implicated ``(constellation, svid)``.
        jamming_state: ``STATE_*``.
        jammer_to_signal_db: J/S estimate, dB (NaN: none).
    """

    stamp_ns: int
    spoofing_state: int
    spoofing_scope: int
    constellations: tuple[int, ...] = ()
    satellites: tuple[tuple[int, int], ...] = ()
    jamming_state: int = STATE_UNKNOWN
    jammer_to_signal_db: float = math.nan


@dataclass
class GnssExclusion:
    """The exclusion state machine (module docstring).

    Args:
        readmit_clean_s: NONE this long without a break readmits the excluded GNSS, s.
        act_on_spoofing: False: verdicts are counted but nothing is excluded.
    """

    readmit_clean_s: float = 30.0
    act_on_spoofing: bool = True
    counts: dict[str, int] = field(default_factory=lambda: {
        "exclusions": 0, "readmissions": 0, "epochs_excluded": 0, "satellites_excluded": 0})

    def __post_init__(self) -> None:
        if not (math.isfinite(self.readmit_clean_s) and self.readmit_clean_s >= 0.0):
            raise ValueError(f"readmit_clean_s must be a finite number >= 0, got {self.readmit_clean_s}")
        self.scope = SCOPE_NONE
        self.constellations: set[int] = set()
        self.satellites: set[tuple[int, int]] = set()
        self._clean_since_ns: int | None = None

    @property
    def active(self) -> bool:
        """Whether some GNSS is excluded now."""
        return self.scope != SCOPE_NONE

    def describe(self) -> str:
        """What is excluded, in words (for the status and the log)."""
        if self.scope == SCOPE_ALL:
            return "all GNSS"
        parts = []
        if self.constellations:
            parts.append("constellations " + ", ".join(map(str, sorted(self.constellations))))
        if self.satellites:
            parts.append("satellites " + ", ".join(f"{c}:{s}" for c, s in sorted(self.satellites)))
        return "; ".join(parts) if parts else "nothing"

    def update(self, verdict: IntegrityVerdict) -> str | None:
        """Apply one verdict; returns "excluded" or "readmitted" when the exclusion changed, else None."""
        if not self.act_on_spoofing:
            return None
        state = verdict.spoofing_state
        if state == STATE_DETECTED:
            self._clean_since_ns = None
            return self._exclude(verdict)
        if state == STATE_SUSPECTED:
            self._clean_since_ns = None
            return None
        if state != STATE_NONE or not self.active:
            return None  # UNKNOWN: the clean timer stands still
        if self._clean_since_ns is None:
            self._clean_since_ns = verdict.stamp_ns
        if verdict.stamp_ns - self._clean_since_ns >= self.readmit_clean_s * NS_PER_S:
            self.scope = SCOPE_NONE
            self.constellations.clear()
            self.satellites.clear()
            self._clean_since_ns = None
            self.counts["readmissions"] += 1
            return "readmitted"
        return None

    def _exclude(self, verdict: IntegrityVerdict) -> str | None:
        before = (self.scope, frozenset(self.constellations), frozenset(self.satellites))
        scope = verdict.spoofing_scope
        if scope == SCOPE_ALL or (scope == SCOPE_NONE):
            self.scope = SCOPE_ALL  # DETECTED without a scope: exclude everything, the safe side
        elif self.scope != SCOPE_ALL:
            if scope == SCOPE_CONSTELLATIONS and verdict.constellations:
                self.constellations.update(int(c) for c in verdict.constellations)
            elif verdict.satellites:
                self.satellites.update((int(c), int(s)) for c, s in verdict.satellites)
            elif verdict.constellations:
                self.constellations.update(int(c) for c in verdict.constellations)
            else:
                self.scope = SCOPE_ALL
            if self.scope != SCOPE_ALL:
                self.scope = SCOPE_CONSTELLATIONS if self.constellations else SCOPE_SATELLITES
        if (self.scope, frozenset(self.constellations), frozenset(self.satellites)) != before:
            self.counts["exclusions"] += 1
            return "excluded"
        return None

    def filter_epoch(self, epoch: GnssEpoch) -> tuple[GnssEpoch | None, int]:
        """The epoch without its excluded satellites, and how many were removed.

        Returns:
            ``(None, n)`` when all GNSS is excluded (the epoch is not applied), else the epoch with
            the remaining satellites (the same object when nothing is excluded).
        """
        if self.scope == SCOPE_NONE:
            return epoch, 0
        n = len(epoch.observations)
        if self.scope == SCOPE_ALL:
            self.counts["epochs_excluded"] += 1
            self.counts["satellites_excluded"] += n
            return None, n
        kept = tuple(o for o in epoch.observations
                     if o.constellation not in self.constellations
                     and (o.constellation, o.svid) not in self.satellites)
        removed = n - len(kept)
        self.counts["satellites_excluded"] += removed
        return (replace(epoch, observations=kept) if removed else epoch), removed


def integrity_jammer_to_signal(verdict: IntegrityVerdict) -> float | None:
    """The J/S the filter should use from a verdict: a finite J/S when jamming is DETECTED, NaN
    ("no jammer") when NONE, None (leave the filter's J/S alone) otherwise."""
    if verdict.jamming_state == STATE_DETECTED and math.isfinite(verdict.jammer_to_signal_db):
        return float(verdict.jammer_to_signal_db)
    if verdict.jamming_state == STATE_NONE:
        return math.nan
    return None


JSR_LIMITS_DB = (-100.0, 150.0)
"""A J/S outside this range is not physical: the verdict is rejected (``integrity_js_nonphysical``)."""


def verdict_of(msg) -> tuple[IntegrityVerdict | None, str | None]:
    """An rfi_msgs/GnssIntegrity (any object with its fields) as a verdict, or why it is rejected.

    Returns:
        ``(verdict, None)`` or ``(None, reason)`` with reason ``integrity_unknown_state`` (a state or
        scope that is none of the message's constants), ``integrity_malformed_satellites``
        (``affected_satellite_constellations`` and ``affected_svids`` of different lengths) or
        ``integrity_js_nonphysical`` (an infinite J/S or one outside :data:`JSR_LIMITS_DB`).
    """
    states = (STATE_UNKNOWN, STATE_NONE, STATE_SUSPECTED, STATE_DETECTED)
    scopes = (SCOPE_NONE, SCOPE_SATELLITES, SCOPE_CONSTELLATIONS, SCOPE_ALL)
    if msg.spoofing_state not in states or msg.jamming_state not in states or msg.spoofing_scope not in scopes:
        return None, "integrity_unknown_state"
    if len(msg.affected_satellite_constellations) != len(msg.affected_svids):
        return None, "integrity_malformed_satellites"
    js = float(msg.jammer_to_signal_db)
    if not math.isnan(js) and not (math.isfinite(js) and JSR_LIMITS_DB[0] <= js <= JSR_LIMITS_DB[1]):
        return None, "integrity_js_nonphysical"
    stamp_ns = int(msg.header.stamp.sec) * NS_PER_S + int(msg.header.stamp.nanosec)
    satellites = tuple(zip((int(c) for c in msg.affected_satellite_constellations),
                           (int(s) for s in msg.affected_svids), strict=True))
    return IntegrityVerdict(stamp_ns, int(msg.spoofing_state), int(msg.spoofing_scope),
                            tuple(int(c) for c in msg.affected_constellations), satellites,
                            int(msg.jamming_state), js), None
