"""Spoofing evidence from elsewhere: the receiver's own spoofing flag, and an SDR's power rise.

Pure (no rclpy). Two tests of category EXTERNAL:

- ``receiver_spoofing_flag``: the receiver's spoofing indicator (u-blox UBX-SEC-SIG
  ``spoofingState``: 1 none, 2 indicated, 3 affirmed; 0 unknown or detection disabled), as
  bridged on /gnss/receiver_interference. Indicated is SUSPECT, affirmed is ALARM; the statistic is
  the state (the receiver's false-alarm rate is its own: the outcome says NaN). A report older
  than ``max_report_age_s`` at the epoch is UNKNOWN.
- ``sdr_power_rise``: a spoofer adds power in band (a few dB for an aggressive one): the SDR
  monitor (/rfi/jammer_state) sees a rise of in-band power without a jammer signature (type
  WIDEBAND or UNKNOWN, J/N below ``max_spoofer_jn_db``), while the receiver's C/N0 does not drop
  (a jammer of that power would lower it). The statistic is the SDR's J/N in dB when that holds,
  0 when the SDR reports NONE; SUSPECT at ``min_rise_db``, never ALARM on its own (a power rise is
  weak evidence; with a second category it makes a detection). UNKNOWN without a fresh SDR state.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from gnss_common.constants import NS_PER_S
from rfi_node_common.params import check_positive_finite

from .outcome import (
    CATEGORY_EXTERNAL,
    DECISION_ALARM,
    DECISION_PASS,
    DECISION_SUSPECT,
    SCOPE_ALL,
    TestOutcome,
    decide,
    unknown,
)

SPOOFING_UNKNOWN = 0
SPOOFING_NONE = 1
SPOOFING_INDICATED = 2
SPOOFING_AFFIRMED = 3
"""rfi_msgs/ReceiverInterference SPOOFING_* (u-blox SEC-SIG spoofingState)."""

JAMMER_NONE, JAMMER_CW, JAMMER_CHIRP, JAMMER_WIDEBAND, JAMMER_UNKNOWN = 0, 1, 2, 3, 4
"""rfi_msgs/JammerState type constants."""


@dataclass(frozen=True)
class ExternalEvidenceParams:
    """Parameters of the external-evidence tests.

    Attributes:
        max_report_age_s: a receiver or SDR report older than this at the GNSS epoch is not used, s.
        min_rise_db: SDR J/N (power rise over the learned floor) at which ``sdr_power_rise`` is SUSPECT, dB.
        max_spoofer_jn_db: a rise above this is a jammer, not a spoofer, dB.
        max_cn0_drop_db: the C/N0 drop (against the clean model) below which the rise is not jamming, dB.
    """

    max_report_age_s: float = 5.0
    min_rise_db: float = 1.0
    max_spoofer_jn_db: float = 10.0
    max_cn0_drop_db: float = 1.0

    def __post_init__(self) -> None:
        check_positive_finite(self, ("max_report_age_s", "min_rise_db", "max_spoofer_jn_db", "max_cn0_drop_db"))
        if self.max_spoofer_jn_db <= self.min_rise_db:
            raise ValueError("ExternalEvidenceParams.max_spoofer_jn_db must exceed min_rise_db")


class ExternalEvidence:
    """Keeps the newest receiver spoofing flag and SDR state; judged at each GNSS epoch."""

    def __init__(self, params: ExternalEvidenceParams | None = None) -> None:
        self.params = params if params is not None else ExternalEvidenceParams()
        self._flag: tuple[int, int] | None = None  # (stamp ns, SPOOFING_*)
        self._sdr: tuple[int, int, float] | None = None  # (stamp ns, type, J/N dB)

    def add_receiver_flag(self, stamp_ns: int, spoofing_state: int, detection_enabled: bool) -> None:
        """A receiver report: its spoofing state (ignored when its detection is disabled, or older than the
        report kept: the newest by stamp counts, whatever the order of arrival)."""
        if self._flag is not None and stamp_ns < self._flag[0]:
            return
        if detection_enabled and spoofing_state in (SPOOFING_NONE, SPOOFING_INDICATED, SPOOFING_AFFIRMED):
            self._flag = (stamp_ns, spoofing_state)

    def add_sdr_state(self, stamp_ns: int, jammer_type: int, jammer_to_noise_db: float) -> None:
        """An SDR monitor's /rfi/jammer_state (one older than the state kept is ignored: the newest by stamp)."""
        if self._sdr is None or stamp_ns >= self._sdr[0]:
            self._sdr = (stamp_ns, jammer_type, jammer_to_noise_db)

    def _fresh(self, stamp_ns: int, report_ns: int) -> bool:
        return abs(stamp_ns - report_ns) <= self.params.max_report_age_s * NS_PER_S

    def update(self, stamp_ns: int, cn0_drop_db: float) -> tuple[TestOutcome, TestOutcome]:
        """(``receiver_spoofing_flag``, ``sdr_power_rise``) at a GNSS epoch.

        Args:
            stamp_ns: the epoch's stamp, ns.
            cn0_drop_db: the epoch's common C/N0 drop against the clean model, dB (NaN: unknown).
        """
        p = self.params
        if self._flag is None or not self._fresh(stamp_ns, self._flag[0]):
            flag = unknown("receiver_spoofing_flag", CATEGORY_EXTERNAL, SPOOFING_INDICATED, SPOOFING_AFFIRMED)
        else:
            state = self._flag[1]
            decision = {SPOOFING_NONE: DECISION_PASS, SPOOFING_INDICATED: DECISION_SUSPECT,
                        SPOOFING_AFFIRMED: DECISION_ALARM}[state]
            flag = TestOutcome("receiver_spoofing_flag", CATEGORY_EXTERNAL, decision, float(state),
                               SPOOFING_INDICATED, SPOOFING_AFFIRMED, math.nan, "1", SCOPE_ALL)
        if self._sdr is None or not self._fresh(stamp_ns, self._sdr[0]):
            rise = unknown("sdr_power_rise", CATEGORY_EXTERNAL, p.min_rise_db, math.inf, unit="dB")
        else:
            _, kind, jn = self._sdr
            if kind == JAMMER_NONE:
                stat = 0.0
            elif (kind in (JAMMER_WIDEBAND, JAMMER_UNKNOWN) and math.isfinite(jn) and jn <= p.max_spoofer_jn_db
                  and math.isfinite(cn0_drop_db) and cn0_drop_db < p.max_cn0_drop_db):
                stat = float(jn)
            else:
                stat = 0.0  # a jammer signature, or a drop of C/N0: jamming evidence, not spoofing
            rise = TestOutcome("sdr_power_rise", CATEGORY_EXTERNAL, decide(stat, p.min_rise_db, math.inf), stat,
                               p.min_rise_db, math.inf, math.nan, "dB", SCOPE_ALL)
        return flag, rise
