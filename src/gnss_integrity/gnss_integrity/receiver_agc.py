"""The receiver's own interference indicators against a learned per-platform baseline.

Pure (no rclpy, no rfi_msgs): :class:`ReceiverInterferenceReport` mirrors
rfi_msgs/ReceiverInterference (u-blox UBX-MON-HW, one RF block of UBX-MON-RF, UBX-SEC-SIG).

* ``receiver_agc``: the AGC count (0..8191; an in-band jammer adds power, so the AGC lowers its
  gain and the count falls) and the CW jamming indicator (0..255; a CW tone raises it), each against
  its baseline per (source, RF block): a running mean and variance of reports from clean periods.
  Clean-data model: ``z_agc = (baseline - agc) / max(sigma, agc_min_std_counts)`` and
  ``z_cw = (cw - baseline) / max(sigma, cw_min_std)`` are standard normal; the statistic is the
  largest z over channels and blocks (unit "1"), thresholds the one-sided normal quantiles of the
  false-alarm probabilities. The floors stand for clean variation the running sigma may not have
  seen (temperature, satellites, antenna): with the defaults, suspect at 3.7 x 100 = 370 counts
  (4.5 % of the range), alarm at 520 counts. AGC counts differ between platforms (antenna gain,
  cable, front end), hence the learned baseline and no fixed level.
  Learning gates: a report is learned when the receiver's own flag is not WARNING / CRITICAL, the
  antenna is not SHORT / OPEN, the caller's other evidence says clean (C/N0 model, ceiling) and the
  report itself is within ``learn_max_z`` (2) of its baseline. The AGC baseline rises at once (more gain = less
  interference) and falls at most ``agc_max_fall_counts_per_s``; the CW baseline falls at once and
  rises at most ``cw_max_rise_per_s``: an interferer switched on while learning drags them slowly.
  A start that is already jammed is not visible to the AGC alone (the baseline is then the jammed
  level): the C/N0 ceiling of :mod:`gnss_integrity.cn0_model` gates it (pass ``other_clean``).
* ``receiver_jam_flag``: the receiver's own jamming state, statistic = the state (1 OK -> PASS,
  2 WARNING -> SUSPECT, 3 CRITICAL -> ALARM, 0 or monitor disabled -> UNKNOWN); its false-alarm
  probability is the receiver's own (NaN here).

Reports older than ``max_report_age_s`` at the epoch judged leave both tests UNKNOWN. Time comes from
the stamps (ns), never the wall clock.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from gnss_integrity.outcome import (
    CATEGORY_JAMMING,
    DECISION_SUSPECT,
    TestOutcome,
    decide,
    normal_threshold,
    unknown,
)
from rfi_node_common.params import check_positive_finite

from .outcome import check_false_alarm_probabilities

AGC_TEST = "receiver_agc"
FLAG_TEST = "receiver_jam_flag"

# rfi_msgs/ReceiverInterference constants
SOURCE_MON_HW = 1
SOURCE_MON_RF = 2
SOURCE_SEC_SIG = 3
JAMMING_UNKNOWN = 0
JAMMING_OK = 1
JAMMING_WARNING = 2
JAMMING_CRITICAL = 3
ANTENNA_SHORT = 3
ANTENNA_OPEN = 4
AGC_FULL_RANGE_COUNTS = 8191.0
CW_FULL_RANGE = 255.0


@dataclass(frozen=True)
class ReceiverInterferenceReport:
    """One receiver interference report (fields of rfi_msgs/ReceiverInterference; NaN / 0 unknown).

    Attributes:
        stamp_ns: header stamp, ns (ROS time of the receiver epoch it belongs to).
        source: ``SOURCE_*``.
        rf_block_id: MON-RF block (0 L1, 1 L2/L5); 0 otherwise.
        jamming_state: ``JAMMING_*``.
        jamming_detection_enabled: the receiver's jamming monitor is on.
        jam_indicator: CW jamming indicator, 0..255 (NaN: not reported).
        agc_count: AGC monitor count, 0..8191 (NaN: not reported).
        noise_per_ms: noise level, receiver units (NaN: not reported; not used).
        antenna_status: 0 INIT, 1 DONTKNOW, 2 OK, 3 SHORT, 4 OPEN.
        antenna_power: 0 OFF, 1 ON, 2 DONTKNOW.
        spoofing_state, spoofing_detection_enabled: SEC-SIG spoofing flag (not used here).
    """

    stamp_ns: int
    source: int = SOURCE_MON_HW
    rf_block_id: int = 0
    jamming_state: int = JAMMING_UNKNOWN
    jamming_detection_enabled: bool = False
    jam_indicator: float = math.nan
    agc_count: float = math.nan
    noise_per_ms: float = math.nan
    antenna_status: int = 0
    antenna_power: int = 0
    spoofing_state: int = 0
    spoofing_detection_enabled: bool = False


@dataclass(frozen=True)
class ReceiverAgcParams:
    """Parameters of :class:`ReceiverAgcMonitor` (clean-data model in the module docstring).

    Attributes:
        false_alarm_probability, alarm_false_alarm_probability: per report, of the suspect and alarm
            thresholds of ``receiver_agc`` on clean data.
        agc_min_std_counts: floor of the AGC count's clean 1-sigma, counts.
        cw_min_std: floor of the CW indicator's clean 1-sigma, indicator units.
        memory_reports: the running mean / variance become exponentially weighted after this many.
        min_reports: clean reports a baseline needs before it is used.
        agc_max_fall_counts_per_s: fastest fall of the AGC baseline, counts/s.
        cw_max_rise_per_s: fastest rise of the CW baseline, units/s.
        max_report_age_s: reports older than this at the epoch judged are not used, s.
        learn_max_z: a report is learned only while both its z are below this (a slowly ramping
            interferer stops being learned long before it reaches the suspect threshold).
    """

    false_alarm_probability: float = 1e-4
    alarm_false_alarm_probability: float = 1e-7
    agc_min_std_counts: float = 100.0
    cw_min_std: float = 10.0
    memory_reports: float = 300.0
    min_reports: int = 10
    agc_max_fall_counts_per_s: float = 2.0
    cw_max_rise_per_s: float = 0.05
    max_report_age_s: float = 5.0
    learn_max_z: float = 2.0

    def __post_init__(self) -> None:
        check_false_alarm_probabilities(self)
        check_positive_finite(self, ("agc_min_std_counts", "cw_min_std", "memory_reports", "max_report_age_s"))
        if not (self.min_reports >= 1 and self.agc_max_fall_counts_per_s >= 0 and self.cw_max_rise_per_s >= 0):
            raise ValueError("min_reports >= 1, agc_max_fall_counts_per_s and cw_max_rise_per_s >= 0")


@dataclass
class Baseline:
    """Running clean level of one indicator, published with a one-sided rate limit.

    Attributes:
        mean, var: running mean and variance of clean reports.
        count: clean reports learned (capped at the memory).
        published: the level the test uses (follows ``mean`` at once in the harmless direction).
        stamp_ns: stamp of the last learned report.
    """

    mean: float = math.nan
    var: float = 0.0
    count: float = 0.0
    published: float = math.nan
    stamp_ns: int | None = None

    def learn(self, x: float, stamp_ns: int, memory: float, max_step_per_s: float, harmful_sign: float) -> None:
        """Add a clean value; ``harmful_sign`` -1 for the AGC (falls under jamming), +1 for the CW."""
        self.count = min(self.count + 1.0, memory)
        if not math.isfinite(self.mean):
            self.mean, self.published = x, x
        else:
            d = x - self.mean
            self.mean += d / self.count
            self.var += (d * (x - self.mean) - self.var) / self.count
            dt = 0.0 if self.stamp_ns is None else max((stamp_ns - self.stamp_ns) * 1e-9, 0.0)
            limit = self.published + harmful_sign * max_step_per_s * dt
            toward_harm = (self.mean - self.published) * harmful_sign > 0
            self.published = (min(self.mean, limit) if harmful_sign > 0 else max(self.mean, limit)) \
                if toward_harm else self.mean
        self.stamp_ns = stamp_ns


@dataclass(frozen=True)
class ReceiverAgcResult:
    """Judgement of the receiver's indicators at one stamp.

    Attributes:
        agc: the ``receiver_agc`` outcome.
        jam_flag: the ``receiver_jam_flag`` outcome.
        looks_clean: no indicator at its suspect threshold, no WARNING / CRITICAL, the antenna not
            SHORT / OPEN (True also when nothing is reported: no evidence against): a learning gate
            for the C/N0 model.
        evidence_available: at least one fresh indicator was judged.
    """

    agc: TestOutcome
    jam_flag: TestOutcome
    looks_clean: bool
    evidence_available: bool


@dataclass
class _Block:
    report: ReceiverInterferenceReport
    agc: Baseline = field(default_factory=Baseline)
    cw: Baseline = field(default_factory=Baseline)


class ReceiverAgcMonitor:
    """``receiver_agc`` and ``receiver_jam_flag`` (module docstring).

    Per report: :meth:`update`; per GNSS epoch: :meth:`judge` at the epoch's stamp.
    """

    def __init__(self, params: ReceiverAgcParams | None = None) -> None:
        self.params = params or ReceiverAgcParams()
        self._z_suspect = normal_threshold(self.params.false_alarm_probability)
        self._z_alarm = normal_threshold(self.params.alarm_false_alarm_probability)
        self._blocks: dict[tuple[int, int], _Block] = {}

    def update(self, report: ReceiverInterferenceReport, other_clean: bool = True) -> ReceiverAgcResult:
        """Take one report; learn it when it and ``other_clean`` (the C/N0 evidence) say clean.

        Returns:
            the judgement at the report's stamp (before learning it).
        """
        p = self.params
        key = (int(report.source), int(report.rf_block_id))
        block = self._blocks.get(key)
        if block is None:
            block = self._blocks[key] = _Block(report)
        elif report.stamp_ns < block.report.stamp_ns:
            return self.judge(report.stamp_ns)  # out of order: judged, not stored, not learned
        block.report = report
        result = self.judge(report.stamp_ns)
        z_agc, z_cw = self._z(block)
        own_clean = (report.jamming_state not in (JAMMING_WARNING, JAMMING_CRITICAL)
                     and report.antenna_status not in (ANTENNA_SHORT, ANTENNA_OPEN))
        if other_clean and own_clean and not (z_agc >= p.learn_max_z or z_cw >= p.learn_max_z):
            if math.isfinite(report.agc_count) and 0 <= report.agc_count <= AGC_FULL_RANGE_COUNTS:
                block.agc.learn(report.agc_count, report.stamp_ns, p.memory_reports, p.agc_max_fall_counts_per_s, -1.0)
            if math.isfinite(report.jam_indicator) and 0 <= report.jam_indicator <= CW_FULL_RANGE:
                block.cw.learn(report.jam_indicator, report.stamp_ns, p.memory_reports, p.cw_max_rise_per_s, 1.0)
        return result

    def _z(self, block: _Block) -> tuple[float, float]:
        """z of the block's latest report against its baselines (NaN: baseline or value missing)."""
        p = self.params
        r = block.report
        z_agc = z_cw = math.nan
        if block.agc.count >= p.min_reports and math.isfinite(r.agc_count):
            z_agc = (block.agc.published - r.agc_count) / max(math.sqrt(block.agc.var), p.agc_min_std_counts)
        if block.cw.count >= p.min_reports and math.isfinite(r.jam_indicator):
            z_cw = (r.jam_indicator - block.cw.published) / max(math.sqrt(block.cw.var), p.cw_min_std)
        return z_agc, z_cw

    def judge(self, stamp_ns: int) -> ReceiverAgcResult:
        """Both outcomes from the reports fresh at ``stamp_ns`` (ns)."""
        p = self.params
        max_age = int(p.max_report_age_s * 1e9)
        fresh = [b for b in self._blocks.values() if 0 <= stamp_ns - b.report.stamp_ns <= max_age]
        zs = [z for b in fresh for z in self._z(b) if math.isfinite(z)]
        if zs:
            stat = max(zs)
            agc = TestOutcome(AGC_TEST, CATEGORY_JAMMING, decide(stat, self._z_suspect, self._z_alarm), stat,
                              self._z_suspect, self._z_alarm, p.false_alarm_probability, "1")
        else:
            agc = unknown(AGC_TEST, CATEGORY_JAMMING, self._z_suspect, self._z_alarm, p.false_alarm_probability)
        states = [b.report.jamming_state for b in fresh
                  if b.report.jamming_detection_enabled and b.report.jamming_state != JAMMING_UNKNOWN]
        if states:
            st = float(max(states))
            flag = TestOutcome(FLAG_TEST, CATEGORY_JAMMING, decide(st, float(JAMMING_WARNING),
                                                                   float(JAMMING_CRITICAL)),
                               st, float(JAMMING_WARNING), float(JAMMING_CRITICAL), math.nan, "1")
        else:
            flag = unknown(FLAG_TEST, CATEGORY_JAMMING, float(JAMMING_WARNING), float(JAMMING_CRITICAL))
        antenna_bad = any(b.report.antenna_status in (ANTENNA_SHORT, ANTENNA_OPEN) for b in fresh)
        clean = agc.decision < DECISION_SUSPECT and flag.decision < DECISION_SUSPECT and not antenna_bad
        return ReceiverAgcResult(agc, flag, clean, bool(zs or states))
