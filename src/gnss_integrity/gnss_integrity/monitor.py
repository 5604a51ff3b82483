"""The integrity monitor: every test on every GNSS epoch, one vendor-neutral report.

Pure core (no rclpy): :class:`IntegrityMonitor` takes plain inputs (time from their stamps, never the
wall clock) and returns an :class:`IntegrityReport` per GNSS epoch, field for field the
rfi_msgs/GnssIntegrity message. Per epoch:

1. the multi-constellation snapshot (``gnss_common.multi_gnss_fix``): position, one clock per
   constellation, velocity and drift, residuals, elevations;
2. jamming: the C/N0 drop against the clean model learned on the fly
   (:mod:`.cn0_model`, :mod:`.cn0_jamming`), the receiver's AGC and flags (:mod:`.receiver_agc`),
   its spectrum (:mod:`.receiver_spectrum`) and an SDR monitor's state; the J/S in the form of
   Cao et al. eq. 4 from the SDR when fresh, else from C/N0;
3. spoofing: C/N0 (:mod:`.cn0_spoofing`), clock (:mod:`.clock_test`), kinematics against UWB and
   Doppler (:mod:`.kinematics_test`), the Doppler velocity against the UWB ranges' rates
   (:mod:`.uwb_range_rate`), consistency (:mod:`.consistency`), external evidence
   (:mod:`.external_evidence`), combined by :mod:`.integrity_state`;
4. the C/N0 model learns only from epochs that every other evidence calls clean.

A missing input leaves its tests UNKNOWN: never NONE.

Side inputs are taken in stamp order, not in order of arrival: ``add_uwb``, ``add_receiver_report``,
``add_sdr_state`` and ``add_spectrum`` only hold what they are given, and :meth:`IntegrityMonitor.process_epoch`
first applies every held input stamped at or before the epoch, sorted by (stamp, kind, arrival), and keeps the
later ones for a later epoch. An epoch's verdict is therefore a function of the epochs before it and the side
inputs stamped at or before it that were given before it, whatever order they came in: a range stamped after the
epoch is never used for it even if it came first (a GNSS receiver's epochs often reach a node after the UWB
ranges of the same instant), and a range stamped before the epoch that comes after it is used from the next
epoch on (as if it had come just before that one). The node gives the monitor every side input that has reached
it before each epoch (gnss_integrity_node). At most ``max_held_inputs`` are held: beyond that the oldest is
applied at once (counted, ``inputs_applied_before_an_epoch``; during a GNSS outage of minutes).
"""

from __future__ import annotations

import heapq
import itertools
import math
from collections.abc import Callable
from dataclasses import dataclass, field, replace

import numpy as np

from gnss_common.constants import NS_PER_S
from gnss_common.multi_gnss_fix import MultiGnssFix, MultiGnssFixParams, solve_multi_gnss
from gnss_common.observations import GPS, GnssEpoch, UwbRangeMeasurement

from .clock_test import ClockTest, ClockTestParams
from .cn0_jamming import Cn0JammingDetector, Cn0JammingParams
from .cn0_model import Cn0Epoch, Cn0ModelParams, Cn0Models
from .cn0_spoofing import Cn0SpoofingParams, Cn0SpoofingTests
from .consistency import ConsistencyParams, ConsistencyTests
from .external_evidence import ExternalEvidence, ExternalEvidenceParams
from .integrity_state import SpoofingState, StateParams
from .kinematics_test import AnchorRange, KinematicsTest, KinematicsTestParams
from .outcome import (
    CATEGORY_CN0,
    CATEGORY_JAMMING,
    DECISION_ALARM,
    DECISION_SUSPECT,
    DECISION_UNKNOWN,
    EVIDENCE_RECEIVER_AGC,
    EVIDENCE_RECEIVER_FLAG,
    EVIDENCE_RECEIVER_SPECTRUM,
    EVIDENCE_SDR_MONITOR,
    SCOPE_SATELLITES,
    STATE_DETECTED,
    STATE_NONE,
    STATE_SUSPECTED,
    STATE_UNKNOWN,
    TestOutcome,
)
from .receiver_agc import ReceiverAgcMonitor, ReceiverAgcParams, ReceiverInterferenceReport
from .receiver_spectrum import ReceiverSpectrumMonitor, SpectrumDetection, SpectrumInput, SpectrumParams
from .uwb_range_rate import UwbRangeRateParams, UwbRangeRateTest

JAMMER_NONE = 0
JAMMER_UNKNOWN = 4
_KIND_UWB, _KIND_RECEIVER, _KIND_SPECTRUM, _KIND_SDR = range(4)
"""Order of held side inputs of one stamp (they touch independent state; a fixed order keeps it exact)."""


@dataclass(frozen=True)
class MonitorParams:
    """Every part's parameters (each validated by its own dataclass).

    Attributes:
        sdr_max_age_s: an SDR /rfi/jammer_state older than this at the epoch is not used, s.
        spectrum_max_age_s: a receiver spectrum analysis older than this at the epoch is not used, s.
        max_held_inputs: side inputs (UWB ranges, receiver reports, spectra, SDR states) held for the
            epoch they precede (module docstring); beyond this the oldest is applied at once. 20,000 is
            minutes of four anchors at 20 Hz with the receiver's reports.
    """

    fix: MultiGnssFixParams = field(default_factory=MultiGnssFixParams)
    cn0_model: Cn0ModelParams = field(default_factory=Cn0ModelParams)
    cn0_jamming: Cn0JammingParams = field(default_factory=Cn0JammingParams)
    cn0_spoofing: Cn0SpoofingParams = field(default_factory=Cn0SpoofingParams)
    receiver: ReceiverAgcParams = field(default_factory=ReceiverAgcParams)
    spectrum: SpectrumParams = field(default_factory=SpectrumParams)
    clock: ClockTestParams = field(default_factory=ClockTestParams)
    kinematics: KinematicsTestParams = field(default_factory=KinematicsTestParams)
    range_rate: UwbRangeRateParams = field(default_factory=UwbRangeRateParams)
    consistency: ConsistencyParams = field(default_factory=ConsistencyParams)
    external: ExternalEvidenceParams = field(default_factory=ExternalEvidenceParams)
    state: StateParams = field(default_factory=StateParams)
    sdr_max_age_s: float = 2.0
    spectrum_max_age_s: float = 5.0
    max_held_inputs: int = 20_000

    def __post_init__(self) -> None:
        if int(self.max_held_inputs) < 0:
            raise ValueError(f"max_held_inputs must be >= 0, got {self.max_held_inputs}")


@dataclass(frozen=True)
class IntegrityReport:
    """One epoch's verdict: the fields of rfi_msgs/GnssIntegrity (see its comments)."""

    stamp_ns: int
    jamming_state: int
    jammer_to_signal_db: float
    jammer_to_signal_std_db: float
    jammer_to_signal_is_lower_bound: bool
    jamming_evidence: int
    cn0_elevation_model_in_use: bool
    cn0_drop_db: float
    satellites_with_cn0: int
    jammer_type: int
    jammer_frequency_hz: float
    jammer_bandwidth_hz: float
    spoofing_state: int
    spoofing_scope: int
    affected_constellations: tuple[int, ...]
    affected_satellites: tuple[tuple[int, int], ...]
    first_alarm_ns: int
    first_detection_ns: int
    tests: tuple[TestOutcome, ...]
    position_ecef_m: np.ndarray  # the snapshot (NaN: none); not in the message, for diagnostics


def _jamming_state(outcomes: list[TestOutcome]) -> int:
    decided = [o for o in outcomes if o.decision != DECISION_UNKNOWN]
    if not decided:
        return STATE_UNKNOWN
    if any(o.decision == DECISION_ALARM for o in decided):
        return STATE_DETECTED
    if any(o.decision == DECISION_SUSPECT for o in decided):
        return STATE_SUSPECTED
    return STATE_NONE


class IntegrityMonitor:
    """Jamming and spoofing tests of one receiver (module docstring)."""

    def __init__(self, params: MonitorParams | None = None) -> None:
        self.params = params if params is not None else MonitorParams()
        p = self.params
        self.cn0_models = Cn0Models(p.cn0_model)
        self.cn0_jamming = Cn0JammingDetector(p.cn0_jamming)
        self.cn0_spoofing = Cn0SpoofingTests(p.cn0_spoofing)
        self.receiver = ReceiverAgcMonitor(p.receiver)
        self.spectrum = ReceiverSpectrumMonitor(p.spectrum)
        self.clock = ClockTest(p.clock)
        self.kinematics = KinematicsTest(p.kinematics)
        self.range_rate = UwbRangeRateTest(p.range_rate)
        self.consistency = ConsistencyTests(p.consistency)
        self.external = ExternalEvidence(p.external)
        self.state = SpoofingState(p.state)
        self._last_position: np.ndarray | None = None
        self._sdr: tuple[int, int, float, float] | None = None  # stamp, type, J/S, J/N
        self._spectrum: tuple[int, SpectrumDetection] | None = None
        self._cn0_clean = True  # the last epoch's C/N0 verdict: the AGC baseline's learning gate
        # side inputs held until the epoch they precede: a heap of (stamp ns, kind, arrival, apply)
        self._held: list[tuple[int, int, int, Callable[[], None]]] = []
        self._arrivals = itertools.count()
        self.counts: dict[str, int] = {"epochs": 0, "epochs_without_fix": 0, "uwb_ranges": 0,
                                       "receiver_reports": 0, "sdr_states": 0, "spectra": 0,
                                       "epochs_degraded_by_jamming": 0, "epochs_with_exclusions": 0,
                                       "inputs_applied_before_an_epoch": 0}

    # ------------------------------------------------------------------ side inputs
    def add_uwb(self, meas: UwbRangeMeasurement) -> None:
        """A UWB range whose anchor is in ECEF (``frame_id`` "earth"; the node converts map anchors); held
        for the first epoch stamped at or after it (module docstring)."""
        self.counts["uwb_ranges"] += 1
        rng = AnchorRange(meas.stamp_ns, meas.anchor_id, np.asarray(meas.anchor_position_m, dtype=float),
                          float(meas.range_m), float(meas.range_std_m))
        self._hold(meas.stamp_ns, _KIND_UWB, lambda: self._apply_uwb(rng))

    def add_receiver_report(self, report: ReceiverInterferenceReport) -> None:
        """The receiver's interference report (AGC, jam indicator, jamming and spoofing flags); held."""
        self.counts["receiver_reports"] += 1
        self._hold(report.stamp_ns, _KIND_RECEIVER, lambda: self._apply_receiver_report(report))

    def add_sdr_state(self, stamp_ns: int, jammer_type: int, jammer_to_signal_db: float,
                      jammer_to_noise_db: float) -> None:
        """An SDR monitor's /rfi/jammer_state; held."""
        self.counts["sdr_states"] += 1
        state = (int(stamp_ns), int(jammer_type), float(jammer_to_signal_db), float(jammer_to_noise_db))
        self._hold(stamp_ns, _KIND_SDR, lambda: self._apply_sdr_state(state))

    def add_spectrum(self, stamp_ns: int, spectrum: SpectrumInput) -> None:
        """A receiver spectrum report (u-blox MON-SPAN, one RF block): checked at once, held, analysed when
        applied.

        Raises:
            ValueError: a spectrum whose bins or span do not fit (:meth:`ReceiverSpectrumMonitor.check`).
        """
        self.spectrum.check(spectrum)
        self.counts["spectra"] += 1
        self._hold(stamp_ns, _KIND_SPECTRUM, lambda: self._apply_spectrum(int(stamp_ns), spectrum))

    @property
    def held_inputs(self) -> int:
        """Side inputs held for a later epoch."""
        return len(self._held)

    def _hold(self, stamp_ns: int, kind: int, apply: Callable[[], None]) -> None:
        heapq.heappush(self._held, (int(stamp_ns), kind, next(self._arrivals), apply))
        while len(self._held) > self.params.max_held_inputs:
            self.counts["inputs_applied_before_an_epoch"] += 1
            heapq.heappop(self._held)[3]()

    def _release(self, stamp_ns: int) -> None:
        """Apply every held side input stamped at or before ``stamp_ns``, in (stamp, kind, arrival) order."""
        held = self._held
        while held and held[0][0] <= stamp_ns:
            heapq.heappop(held)[3]()

    def _apply_uwb(self, rng: AnchorRange) -> None:
        self.kinematics.add_range(rng)
        self.range_rate.add_range(rng)

    def _apply_receiver_report(self, report: ReceiverInterferenceReport) -> None:
        self.receiver.update(report, other_clean=self._cn0_clean)
        self.external.add_receiver_flag(report.stamp_ns, report.spoofing_state, report.spoofing_detection_enabled)

    def _apply_sdr_state(self, state: tuple[int, int, float, float]) -> None:
        if self._sdr is None or state[0] >= self._sdr[0]:  # the newest by stamp (a late one is older)
            self._sdr = state
        self.external.add_sdr_state(state[0], state[1], state[3])

    def _apply_spectrum(self, stamp_ns: int, spectrum: SpectrumInput) -> None:
        detection = self.spectrum.update(spectrum)
        if self._spectrum is None or detection.state >= self._spectrum[1].state or spectrum.rf_block_id == 0:
            self._spectrum = (stamp_ns, detection)

    # ------------------------------------------------------------------ the epoch
    def process_epoch(self, epoch: GnssEpoch) -> IntegrityReport:
        """Every test on one GNSS epoch (in stamp order), after the side inputs held for it (module docstring)."""
        self.counts["epochs"] += 1
        stamp = epoch.stamp_ns
        self._release(stamp)
        fix = solve_multi_gnss(epoch, self.params.fix, initial_position_ecef_m=self._last_position)
        if fix.valid:
            self._last_position = fix.position_ecef_m.copy()
        else:
            self.counts["epochs_without_fix"] += 1
        position = fix.position_ecef_m if fix.valid else np.full(3, math.nan)
        # ---- C/N0: jamming first, then spoofing from the same references
        cn0_epoch = Cn0Epoch.from_gnss_epoch(epoch, self._last_position)
        ref = self.cn0_models.reference(cn0_epoch)
        jam = self.cn0_jamming.evaluate(ref)
        cn0_spoof = self.cn0_spoofing.evaluate(ref, jam)
        receiver = self.receiver.judge(stamp)
        jam_tests, jamming = self._jamming(stamp, jam, receiver)
        # ---- spoofing tests; those of measurement quality only where no jammer degrades it
        degraded = not jam.epoch_clean or jamming[0] >= STATE_SUSPECTED
        quality = self._quality_tests(stamp, epoch, fix, position, degraded)
        ext = self.external.update(stamp, jam.common_drop_db)
        spoof_tests = [*cn0_spoof.outcomes, *quality, *ext]
        verdict = self.state.update(stamp, spoof_tests)
        self._learn(ref, jam, cn0_spoof, receiver, spoof_tests)
        jamming_state, js, js_std, js_bound, evidence, jammer_type, freq, bw = jamming
        return IntegrityReport(
            stamp, jamming_state, js, js_std, js_bound, evidence, ref.elevation_model_in_use, jam.common_drop_db,
            jam.satellites_used, jammer_type, freq, bw, verdict.state, verdict.scope, verdict.constellations,
            verdict.satellites, verdict.first_alarm_ns, verdict.first_detection_ns,
            tuple([*jam_tests, *spoof_tests]), position)

    def _quality_tests(self, stamp: int, epoch: GnssEpoch, fix: MultiGnssFix, position: np.ndarray,
                       degraded: bool) -> list[TestOutcome]:
        """Clock, kinematics and consistency: what a spoofer changes in the measurements.

        A jammer degrades the same measurements (tracking jitter, outlier bursts, lost lock), which
        these tests cannot tell from an attack: while this epoch's C/N0 drop is above its suspect
        threshold, or any jamming evidence says SUSPECTED or worse, they are UNKNOWN and their
        histories restart (so that no window mixes jammed and clean epochs). A spoofer that keeps a
        jammer on is then seen only by the C/N0-independent evidence (the receiver's flag): a blind
        spot (docs/gnss_integrity/README.md). A test that implicates single satellites
        (``SCOPE_SATELLITES``: RAIM, per-satellite code against Doppler) never exceeds SUSPECT: one
        epoch's failure of a few satellites is a fault (multipath, an outlier burst) as often as an
        attack; held for ``persistence_s`` it makes a detection. The clock and kinematic tests use
        the fix without the satellites ``raim_subset`` names.
        """
        cons = self.consistency.update(stamp, epoch, fix)
        clean_fix = self._without_faults(epoch, fix, cons[2])
        if clean_fix.valid:
            position = clean_fix.position_ecef_m
        clock = self._clock(stamp, clean_fix)
        velocity = clean_fix.velocity_ecef_mps if clean_fix.valid and clean_fix.velocity_valid else None
        kin = self.kinematics.update(stamp, position, velocity)
        rate = self.range_rate.update(stamp, position, velocity,
                                      clean_fix.velocity_covariance[:3, :3] if velocity is not None else None)
        outs = [*clock, *kin, rate, *cons]
        if degraded or not fix.valid:
            if degraded:
                self.counts["epochs_degraded_by_jamming"] += 1
                self.clock.reset()
                self.kinematics.reset()
                self.range_rate.reset()
                self.consistency.reset()
            return [_unknown_like(o) for o in outs]
        return [_capped(o) if o.scope == SCOPE_SATELLITES else o for o in outs]

    def _without_faults(self, epoch: GnssEpoch, fix: MultiGnssFix, raim: TestOutcome) -> MultiGnssFix:
        """The fix without the satellites ``raim_subset`` names (fault detection and exclusion), for
        the clock and kinematic tests: a satellite's outlier must not read as a clock step or a jump."""
        if not fix.valid or not raim.satellites:
            return fix
        bad = set(raim.satellites)
        use = np.array([(o.constellation, o.svid) not in bad for o in epoch.observations], dtype=bool)
        self.counts["epochs_with_exclusions"] += 1
        return solve_multi_gnss(epoch, self.params.fix, use=use, initial_position_ecef_m=fix.position_ecef_m)

    def _jamming(self, stamp: int, jam, receiver) -> tuple[list[TestOutcome], tuple]:
        """The jamming tests and (state, J/S, its std, whether it is a lower bound, evidence bits, jammer
        type, frequency, bandwidth)."""
        jam_tests = [jam.outcome, receiver.agc, receiver.jam_flag]
        spectrum = self._fresh_spectrum(stamp)
        if spectrum is not None:
            jam_tests.append(spectrum.outcome)
        sdr = self._fresh_sdr(stamp)
        jamming_state = _jamming_state(jam_tests)
        evidence = jam.evidence
        evidence |= EVIDENCE_RECEIVER_AGC if receiver.agc.decision >= DECISION_SUSPECT else 0
        evidence |= EVIDENCE_RECEIVER_FLAG if receiver.jam_flag.decision >= DECISION_SUSPECT else 0
        js, js_std, js_bound = jam.jammer_to_signal_db, jam.jammer_to_signal_std_db, jam.jammer_to_signal_is_lower_bound
        jammer_type, freq, bw = JAMMER_UNKNOWN if jamming_state >= STATE_SUSPECTED else JAMMER_NONE, math.nan, math.nan
        if spectrum is not None and spectrum.outcome.decision >= DECISION_SUSPECT:
            evidence |= EVIDENCE_RECEIVER_SPECTRUM
            jammer_type = spectrum.jammer_type
            freq, bw = spectrum.frequency_hz, spectrum.bandwidth_hz
        if sdr is not None:
            _, sdr_type, sdr_js, _ = sdr
            if sdr_type != JAMMER_NONE and math.isfinite(sdr_js):
                jamming_state = STATE_DETECTED
                evidence |= EVIDENCE_SDR_MONITOR
                js, js_std, js_bound, jammer_type = sdr_js, math.nan, False, sdr_type
            elif jamming_state == STATE_UNKNOWN:
                jamming_state = STATE_NONE  # the SDR tested the band and found nothing
        return jam_tests, (jamming_state, js, js_std, js_bound, evidence, jammer_type, freq, bw)

    def _clock(self, stamp: int, fix: MultiGnssFix) -> tuple[TestOutcome, TestOutcome]:
        if not (fix.valid and fix.velocity_valid and fix.clock_constellations):
            return self.clock.update(stamp, math.nan, math.nan, math.nan, math.nan, 0)
        ref = GPS if GPS in fix.clock_constellations else fix.clock_constellations[0]
        k = fix.clock_constellations.index(ref)
        bias_std = math.sqrt(max(float(fix.covariance[3 + k, 3 + k]), 0.0))
        drift_std = math.sqrt(max(float(fix.velocity_covariance[3, 3]), 0.0))
        return self.clock.update(stamp, float(fix.clock_biases_m[k]), bias_std, float(fix.clock_drift_mps),
                                 drift_std, ref)

    def _learn(self, ref, jam, cn0_spoof, receiver, spoof_tests: list[TestOutcome]) -> None:
        """The C/N0 model learns only from an epoch every other evidence calls clean.

        The C/N0 spoofing tests gate through ``cn0_spoof.epoch_clean``, which lets a C/N0 rise
        alone stop blocking after ``too_high_learning_block_s`` (a model learned under partial
        blockage must be able to rise in open sky, or it would alarm for ever); the other
        categories gate directly, and an SDR that sees a jammer blocks learning.
        """
        others = all(o.decision < DECISION_SUSPECT for o in spoof_tests if o.category != CATEGORY_CN0)
        clean = (jam.epoch_clean and cn0_spoof.epoch_clean and receiver.looks_clean and others
                 and self._fresh_sdr_type_clean(ref.epoch.stamp_ns))
        self._cn0_clean = bool(jam.epoch_clean) and self.cn0_models.ceiling_passed is not False
        self.cn0_models.learn(ref, clean)

    def _fresh_sdr(self, stamp: int) -> tuple[int, int, float, float] | None:
        if self._sdr is None or abs(stamp - self._sdr[0]) > self.params.sdr_max_age_s * NS_PER_S:
            return None
        return self._sdr

    def _fresh_sdr_type_clean(self, stamp: int) -> bool:
        sdr = self._fresh_sdr(stamp)
        return sdr is None or sdr[1] == JAMMER_NONE

    def _fresh_spectrum(self, stamp: int) -> SpectrumDetection | None:
        if self._spectrum is None or abs(stamp - self._spectrum[0]) > self.params.spectrum_max_age_s * NS_PER_S:
            return None
        return self._spectrum[1]


def _capped(o: TestOutcome) -> TestOutcome:
    """The outcome with an ALARM lowered to SUSPECT (the statistic and thresholds kept)."""
    return replace(o, decision=DECISION_SUSPECT) if o.decision == DECISION_ALARM else o


def _unknown_like(o: TestOutcome) -> TestOutcome:
    return TestOutcome(o.name, o.category, DECISION_UNKNOWN, math.nan, o.suspect_threshold, o.alarm_threshold,
                       o.false_alarm_probability, o.unit)


__all__ = ["CATEGORY_JAMMING", "IntegrityMonitor", "IntegrityReport", "MonitorParams"]
