"""A jammer in the receiver's own spectrum (u-blox UBX-MON-SPAN, about 1 Hz, 256 bins per RF block).

Pure (numpy / scipy; no rclpy, no message types): :class:`ReceiverSpectrumMonitor` takes one
:class:`SpectrumInput` per report and RF block and returns a :class:`SpectrumDetection`: a CW line
or a band-limited (WIDEBAND) jammer with its absolute RF frequency and bandwidth, as the SDR
monitor would report it from IF, with the :class:`~gnss_integrity.outcome.TestOutcome` of the
test ``receiver_spectrum``.

A receiver's spectrum is not flat: the front-end filter makes a hump over the GNSS bands, and real
carriers outside them (mobile-satellite downlinks below 1559 MHz in a real F9 spectrum) and the
receiver's own spur at the centre sit in clean reports. So the monitor learns a clean reference
shape per RF block (per-bin median of the last ``reference_reports`` reports that passed, each
without its median level) and tests each report against it once it holds
``min_reference_reports`` (``REFERENCE_LEARNED``). Before that, with ``fallback_in_spectrum``, a
report is tested against a running median of itself (``REFERENCE_IN_SPECTRUM``: narrow lines
only, ``fallback_confidence``); without the fallback the state is UNKNOWN while learning. Only the
passband is tested: bins more than ``passband_db`` below the reference's maximum are stopband.

Findings: a line of at most ``max_line_bins`` -> CW at its parabolic peak; a contiguous band of
raised bins -> WIDEBAND with centre and bandwidth (edges where the rise falls below
``band_edge_fraction`` of its mean, dB); the whole band raised evenly, which the AGC hides by
lowering the PGA gain -> WIDEBAND over the span, from the input-referred level rise (median bin
level change minus PGA gain change, ``spectrum_after_pga``). A chirp sweeping faster than the
report period (~1 s) integrates into a raised band: it is reported as WIDEBAND over the swept band.

Notes
-----
Shape test: ``r_i`` = shape minus reference, re-centred by its median; ``sigma_i`` = the larger of
the per-bin and the global trimmed std of the out-of-sample differences of earlier clean reports,
at least ``noise_floor_db`` (trimmed std, not MAD: the bins are quantised to 0.25 dB and a MAD is
often 0). For each width ``w`` of ``window_bins`` and position, ``T = sum(r / sigma) / (sqrt(w) c_w)``,
``c_w >= 1`` the trimmed std of that sum over the clean differences (neighbouring bins correlate);
windows with a mean rise below ``min_line_rise_db`` (lines) or ``min_rise_db`` do not count. Each
``T`` is standard normal under the clean model; the strongest has the Bonferroni p-value
``n_windows Q(T_max)``. Level test: ``z = level_rise_db / sigma_L`` (trimmed std of clean level
changes, at least ``level_noise_floor_db``), counted from ``min_level_rise_db``. Statistic:
``-log10(2 min(p_shape, p_level))``, so that on clean data it reaches ``-log10(P)`` with
probability at most ``P`` per report; the thresholds are ``-log10`` of the false-alarm
probabilities. DETECTED also needs ``alarm_persistence`` reports in a row with the finding.

A jammed start: a report with a finding is never learned, and the fallback keeps a CW present from
power-on out of the reference; a band wider than about ``baseline_bins / 2`` present from power-on
is learned as shape (a blind spot until :meth:`ReceiverSpectrumMonitor.reset`).

Bin frequencies: ``f(i) = center + (i - center_bin) resolution``, ``center_bin`` 127 as in the
u-blox interface description (F9 HPG 1.32, UBX-MON-SPAN: ``center + span (i - 127) / 256``); the
receiver's centre spur is in bin 127 of the real F9 spectrum of pyubx2's sample log.
"""

from __future__ import annotations

import math
from collections import Counter
from dataclasses import dataclass, replace

import numpy as np
from numpy.lib.stride_tricks import sliding_window_view
from scipy.ndimage import median_filter
from scipy.special import log_ndtr

from gnss_integrity.outcome import (
    CATEGORY_JAMMING,
    DECISION_SUSPECT,
    STATE_DETECTED,
    STATE_NONE,
    STATE_SUSPECTED,
    STATE_UNKNOWN,
    TestOutcome,
    decide,
)
from gnss_integrity.receiver_spectrum_reference import BlockReference, trimmed_std, window_sums

TEST_NAME = "receiver_spectrum"
UNIT = "-log10 p"
JAMMER_NONE, JAMMER_CW, JAMMER_CHIRP, JAMMER_WIDEBAND, JAMMER_UNKNOWN = 0, 1, 2, 3, 4
"""rfi_msgs/JammerState type codes."""
REFERENCE_NONE, REFERENCE_IN_SPECTRUM, REFERENCE_LEARNED = 0, 1, 2
"""What a report was tested against: nothing (learning without fallback), a running median of
itself (narrow lines only), the learned clean shape of its RF block."""

LN10_OVER_10 = math.log(10.0) / 10.0


@dataclass(frozen=True)
class SpectrumParams:
    """Parameters of :class:`ReceiverSpectrumMonitor` (dB are power dB; defaults in brackets).

    Attributes:
        bins: bins per report [256, u-blox]; other counts are rejected.
        suspect_false_alarm_probability: per-report probability of SUSPECT on clean data [1e-3].
        alarm_false_alarm_probability: the same of ALARM [1e-7: one per 116 days at 1 Hz].
        alarm_persistence: DETECTED needs the alarm in this report and a finding in the same bins
            (within one) in the ``alarm_persistence - 1`` reports before [2]; else SUSPECTED.
        reference_reports: clean reports kept per RF block [60: a minute at 1 Hz].
        min_reference_reports: clean reports before the learned reference is used [10].
        fallback_in_spectrum: while learning, test against a running median of the report [True].
        fallback_confidence: confidence of a fallback result, 0..1 [0.5] (learned: 1).
        baseline_bins: running-median length of the fallback, bins, odd [15].
        local_scale_bins: window of the fallback's local noise estimate, bins, odd [31].
        window_bins: widths scanned, bins (the fallback scans the lines only).
        max_line_bins: a finding at most this wide is a CW line, bins [3].
        min_rise_db: a window wider than a line counts only from this mean rise, dB [1].
        min_line_rise_db: a line counts only from this mean rise, dB [3]: single bins stray more
            than bands; a CW that matters to a receiver stands 10 dB and more above its bin.
        noise_floor_db: smallest per-bin noise std, dB [0.25: u-blox quantises to 0.25 dB].
        passband_db: bins more than this below the reference's maximum are stopband, not tested,
            dB [15] (inf: every bin).
        band_edge_fraction: band edges where the rise falls below this share of its mean [0.5].
        level_noise_floor_db: smallest std of the input-referred level, dB [0.5; PGA steps 1 dB].
        min_level_rise_db: a whole-band rise counts only from this many dB [2].
        spectrum_after_pga: the bins are measured after the PGA (u-blox: "the PGA gain is not
            included in the spectrum data"), level = median bin - PGA [True]; False: input-referred.
        center_bin: bin index of the centre frequency [127, u-blox interface description].
        mask_center_spur: the fallback ignores the centre bin (the receiver's spur) [True].
        geometry_tolerance: largest relative mismatch of ``bins * resolution`` and span [0.01].
    """

    bins: int = 256
    suspect_false_alarm_probability: float = 1.0e-3
    alarm_false_alarm_probability: float = 1.0e-7
    alarm_persistence: int = 2
    reference_reports: int = 60
    min_reference_reports: int = 10
    fallback_in_spectrum: bool = True
    fallback_confidence: float = 0.5
    baseline_bins: int = 15
    local_scale_bins: int = 31
    window_bins: tuple[int, ...] = (1, 2, 3, 5, 8, 13, 21, 34, 55, 89)
    max_line_bins: int = 3
    min_rise_db: float = 1.0
    min_line_rise_db: float = 3.0
    noise_floor_db: float = 0.25
    passband_db: float = 15.0
    band_edge_fraction: float = 0.5
    level_noise_floor_db: float = 0.5
    min_level_rise_db: float = 2.0
    spectrum_after_pga: bool = True
    center_bin: float = 127.0
    mask_center_spur: bool = True
    geometry_tolerance: float = 0.01

    def __post_init__(self) -> None:
        s, a = self.suspect_false_alarm_probability, self.alarm_false_alarm_probability
        for ok, text in (
            (self.bins >= 16, f"bins must be >= 16, got {self.bins}"),
            (0.0 < a < s < 1.0, f"need 0 < alarm ({a}) < suspect ({s}) false-alarm probability < 1"),
            (self.alarm_persistence >= 1, "alarm_persistence must be >= 1"),
            (self.reference_reports >= self.min_reference_reports >= 4,
             "need reference_reports >= min_reference_reports >= 4"),
            (0.0 <= self.fallback_confidence <= 1.0, "fallback_confidence must be in [0, 1]"),
            (self.baseline_bins >= 3 and self.baseline_bins % 2 == 1, "baseline_bins must be odd and >= 3"),
            (self.local_scale_bins >= 3 and self.local_scale_bins % 2 == 1, "local_scale_bins must be odd and >= 3"),
            (len(self.window_bins) > 0 and all(1 <= w <= self.bins // 2 for w in self.window_bins),
             f"window_bins must be in [1, bins / 2], got {self.window_bins}"),
            (1 <= self.max_line_bins <= self.bins // 2, "max_line_bins must be in [1, bins / 2]"),
            (min(self.min_rise_db, self.min_line_rise_db, self.noise_floor_db, self.level_noise_floor_db,
                 self.min_level_rise_db, self.passband_db) > 0.0, "the dB thresholds and floors must be > 0"),
            (0.0 < self.band_edge_fraction < 1.0, "band_edge_fraction must be in (0, 1)"),
            (0.0 <= self.center_bin <= self.bins - 1, "center_bin must be a bin index"),
            (0.0 < self.geometry_tolerance < 0.5, "geometry_tolerance must be in (0, 0.5)"),
        ):
            if not ok:
                raise ValueError(text)

    def thresholds(self) -> tuple[float, float]:
        """(suspect, alarm) thresholds of the statistic: -log10 of the false-alarm probabilities."""
        return -math.log10(self.suspect_false_alarm_probability), -math.log10(self.alarm_false_alarm_probability)


@dataclass(frozen=True, eq=False)
class SpectrumInput:
    """One spectrum of one RF block (rfi_msgs/ReceiverSpectrum without the header).

    Attributes:
        power_db: power per bin, dB, receiver-relative, ascending frequency, (bins,).
        center_frequency_hz, span_hz, resolution_hz: RF centre, span, bin width, Hz (> 0).
        pga_gain_db: front-end PGA gain, dB (NaN: not reported).
        rf_block_id: RF block (each block learns its own reference).

    Raises:
        ValueError: not one spectrum of >= 16 bins, a non-finite bin, a frequency that is not
            finite and > 0, an infinite PGA gain.
    """

    power_db: np.ndarray
    center_frequency_hz: float
    span_hz: float
    resolution_hz: float
    pga_gain_db: float = math.nan
    rf_block_id: int = 0

    def __post_init__(self) -> None:
        try:
            power = np.array(self.power_db, dtype=float)
        except (TypeError, ValueError):
            raise ValueError("power_db must be numbers") from None
        if power.ndim != 1 or power.size < 16:
            raise ValueError(f"power_db must be one spectrum of at least 16 bins, got shape {power.shape}")
        bad = np.flatnonzero(~np.isfinite(power))
        if bad.size:
            raise ValueError(f"power_db has {bad.size} non-finite bins (first: bin {int(bad[0])})")
        for name in ("center_frequency_hz", "span_hz", "resolution_hz"):
            value = float(getattr(self, name))
            if not (math.isfinite(value) and value > 0.0):
                raise ValueError(f"{name} must be finite and > 0, got {value}")
        if math.isinf(float(self.pga_gain_db)):
            raise ValueError(f"pga_gain_db must be finite or NaN, got {self.pga_gain_db}")
        power.flags.writeable = False
        object.__setattr__(self, "power_db", power)


@dataclass(frozen=True)
class SpectrumDetection:
    """What one spectrum shows (NaN / -1: not applicable, e.g. state NONE).

    Attributes:
        state: ``STATE_*`` of :mod:`gnss_integrity.outcome` (UNKNOWN: learning without fallback).
        jammer_type: ``JAMMER_*``: NONE, CW, WIDEBAND, UNKNOWN (a fallback finding wider than a line).
        reference: ``REFERENCE_*`` the report was tested against.
        confidence: 1 (learned reference), ``fallback_confidence`` (in-spectrum), 0 (no test).
        frequency_hz: absolute RF frequency of the line or band centre, Hz; frequency_std_hz its
            1-sigma from the bin quantisation, Hz.
        bandwidth_hz: width of the line or band, Hz (the span for a whole-band rise).
        first_bin, last_bin: the finding's bins.
        peak_rise_db: largest rise of one of its bins over the reference, dB.
        excess_db: J/N in the finding's own bins, dB; excess_std_db its 1-sigma from the bin noise.
        jammer_to_noise_db: jammer over the noise of the whole span, dB (an SDR monitor's J/N).
        level_rise_db: input-referred rise of the whole band, dB (NaN without learned reference).
        pga_change_db: PGA gain minus the reference's, dB (negative: the AGC lowered it).
        outcome: the test's statistic, thresholds and decision.
    """

    state: int
    jammer_type: int
    reference: int
    confidence: float
    frequency_hz: float
    frequency_std_hz: float
    bandwidth_hz: float
    first_bin: int
    last_bin: int
    peak_rise_db: float
    excess_db: float
    excess_std_db: float
    jammer_to_noise_db: float
    level_rise_db: float
    pga_change_db: float
    outcome: TestOutcome


@dataclass
class _Test:
    """One test's result before it is described: -log10 p, the rise r, noise sigma and reference
    level (dB per bin, untested bins 0), the strongest window, the rise that sets its extent."""

    statistic: float
    r: np.ndarray | None = None
    sigma: np.ndarray | None = None
    ref_db: np.ndarray | None = None
    first: int = -1
    last: int = -1
    whole_band: bool = False
    extent: np.ndarray | None = None
    level_rise_db: float = math.nan
    pga_change_db: float = math.nan


def _log10_q(z: float) -> float:
    """log10 of the standard normal upper tail Q(z), without underflow."""
    return float(log_ndtr(-z)) / math.log(10.0)


class ReceiverSpectrumMonitor:
    """Learns a clean reference per RF block and tests each report against it (module docstring).

    Args:
        params: :class:`SpectrumParams` (defaults if None).

    Attributes:
        counts: ``reports``, ``tested_learned``, ``tested_in_spectrum``, ``untested``, ``learned``
            (reports added to a reference), ``reference_resets`` (centre, span, bin count or PGA
            reporting of a block changed).

    Examples:
        >>> bins = np.full(256, 30.0)
        >>> bins[100] += 10.0
        >>> d = ReceiverSpectrumMonitor().update(SpectrumInput(bins, 1583.4e6, 128e6, 0.5e6, 12.0))
        >>> (d.state == STATE_SUSPECTED, d.jammer_type == JAMMER_CW, d.frequency_hz / 1e6)  # DETECTED next report
        (True, True, 1569.9)
    """

    def __init__(self, params: SpectrumParams | None = None) -> None:
        self.params = params if params is not None else SpectrumParams()
        self._blocks: dict[int, BlockReference] = {}
        self.counts: Counter[str] = Counter(dict.fromkeys(
            ("reports", "tested_learned", "tested_in_spectrum", "untested", "learned", "reference_resets"), 0))

    def reference_count(self, rf_block_id: int) -> int:
        """Clean reports in the reference of one RF block."""
        block = self._blocks.get(int(rf_block_id))
        return 0 if block is None else block.count

    def reset(self, rf_block_id: int | None = None) -> None:
        """Forget the reference of one RF block (None: of all), e.g. after the antenna changed."""
        if rf_block_id is None:
            self._blocks.clear()
        else:
            self._blocks.pop(int(rf_block_id), None)

    def check(self, spectrum: SpectrumInput) -> None:
        """Whether :meth:`update` can take ``spectrum``, without taking it.

        Raises:
            ValueError: a bin count other than ``params.bins``, or a span that is not
                ``bins * resolution_hz`` within ``geometry_tolerance``.
        """
        p = self.params
        n = spectrum.power_db.size
        if n != p.bins:
            raise ValueError(f"expected {p.bins} bins, got {n}")
        if abs(n * spectrum.resolution_hz - spectrum.span_hz) > p.geometry_tolerance * spectrum.span_hz:
            raise ValueError(f"span {spectrum.span_hz} Hz is not {n} bins x {spectrum.resolution_hz} Hz")

    def update(self, spectrum: SpectrumInput) -> SpectrumDetection:
        """Test one report, then learn it if it passed (or while learning without a test).

        Raises:
            ValueError: a bin count other than ``params.bins``, or a span that is not
                ``bins * resolution_hz`` within ``geometry_tolerance``.
        """
        self.check(spectrum)
        p = self.params
        self.counts["reports"] += 1
        block = self._block(spectrum)
        if block.count >= p.min_reference_reports and block.sigma is not None:
            kind, test = REFERENCE_LEARNED, self._test_learned(block, spectrum)
        elif p.fallback_in_spectrum:
            kind, test = REFERENCE_IN_SPECTRUM, self._test_in_spectrum(spectrum)
        else:
            kind, test = REFERENCE_NONE, _Test(math.nan)
        self.counts[("untested", "tested_in_spectrum", "tested_learned")[kind]] += 1
        detection = self._persist(block, self._describe(spectrum, kind, test))
        if detection.state in (STATE_NONE, STATE_UNKNOWN):
            self._learn(block, spectrum)
        return detection

    def _test_learned(self, block: BlockReference, spectrum: SpectrumInput) -> _Test:
        p = self.params
        x = spectrum.power_db
        assert block.shape is not None and block.sigma is not None
        r = x - np.median(x) - block.shape
        r -= np.median(r)
        tested = block.shape >= np.max(block.shape) - p.passband_db
        test = self._scan(r, block.sigma, tested, p.window_bins, block.window_scale)
        test.ref_db = x - r
        test.pga_change_db = float(spectrum.pga_gain_db) - block.pga_gain_db
        test.level_rise_db = rise = self._input_level(spectrum) - block.level_db
        level_std = block.level_std_db(p.level_noise_floor_db)
        level = -_log10_q(rise / level_std) if rise >= p.min_level_rise_db else 0.0
        test.whole_band = level > test.statistic
        test.statistic = max(0.0, max(test.statistic, level) - math.log10(2.0))
        return test

    def _test_in_spectrum(self, spectrum: SpectrumInput) -> _Test:
        p = self.params
        x = spectrum.power_db
        baseline = median_filter(x, size=p.baseline_bins, mode="nearest")
        r = x - baseline
        if p.mask_center_spur:
            r[int(round(p.center_bin))] = 0.0
        half = p.local_scale_bins // 2
        local = trimmed_std(sliding_window_view(np.pad(r, half, mode="edge"), p.local_scale_bins), axis=1)
        tested = baseline >= np.max(baseline) - p.passband_db
        widths = tuple(w for w in p.window_bins if w <= p.max_line_bins) or (1,)
        test = self._scan(r, np.maximum(local, p.noise_floor_db), tested, widths, {})
        test.ref_db = baseline  # the extent of a line against a 4x longer median: a band's edge is no line
        test.extent = np.where(tested, x - median_filter(x, size=4 * p.baseline_bins + 1, mode="nearest"), 0.0)
        return test

    def _scan(self, r: np.ndarray, sigma: np.ndarray, tested: np.ndarray, widths: tuple[int, ...],
              scale: dict[int, float]) -> _Test:
        """The strongest window over the tested bins, statistic ``-log10(n_windows Q(T))``."""
        r = np.where(tested, r, 0.0)
        z = r / sigma
        n_tests = max(1, sum(max(0, int(tested.sum()) - w + 1) for w in widths))
        best_t, first, last = -math.inf, -1, -1
        for w in widths:
            t = window_sums(z, w) / (math.sqrt(w) * scale.get(w, 1.0))
            min_rise = self.params.min_line_rise_db if w <= self.params.max_line_bins else self.params.min_rise_db
            t[window_sums(r, w) < w * min_rise] = -math.inf
            j = int(np.argmax(t))
            if t[j] > best_t:
                best_t, first, last = float(t[j]), j, j + w - 1
        statistic = max(0.0, -_log10_q(best_t) - math.log10(n_tests)) if math.isfinite(best_t) else 0.0
        return _Test(statistic, r, sigma, first=first, last=last)

    def _describe(self, spectrum: SpectrumInput, kind: int, test: _Test) -> SpectrumDetection:
        p = self.params
        suspect, alarm = p.thresholds()
        decision = decide(test.statistic, suspect, alarm)
        state = (STATE_UNKNOWN, STATE_NONE, STATE_SUSPECTED, STATE_DETECTED)[decision]
        outcome = TestOutcome(TEST_NAME, CATEGORY_JAMMING, decision, test.statistic, suspect, alarm,
                              p.suspect_false_alarm_probability, UNIT)
        v = dict.fromkeys(("frequency_hz", "frequency_std_hz", "bandwidth_hz", "peak_rise_db", "excess_db",
                           "excess_std_db", "jammer_to_noise_db"), math.nan)
        jammer, first, last = JAMMER_NONE, -1, -1
        if state in (STATE_SUSPECTED, STATE_DETECTED) and test.whole_band:
            jammer, first, last = JAMMER_WIDEBAND, 0, spectrum.power_db.size - 1
            excess = 10.0 * math.log10(max(10.0 ** (test.level_rise_db / 10.0) - 1.0, 1e-30))
            v.update(frequency_hz=float(spectrum.center_frequency_hz), frequency_std_hz=0.0,
                     bandwidth_hz=float(spectrum.span_hz), peak_rise_db=test.level_rise_db, excess_db=excess,
                     jammer_to_noise_db=excess)
        elif state in (STATE_SUSPECTED, STATE_DETECTED):
            assert test.r is not None and test.sigma is not None and test.ref_db is not None
            r, ref_db = test.r, test.ref_db
            first, last = self._region(r if test.extent is None else test.extent, test.first, test.last)
            if test.extent is not None and last - first >= p.max_line_bins:  # a fallback finding wider than a line
                r, ref_db = test.extent, spectrum.power_db - test.extent
            peak = first + int(np.argmax(r[first:last + 1]))
            if last - first < p.max_line_bins:
                jammer, centre = JAMMER_CW, peak + _parabolic_offset(r, peak)
                v.update(frequency_std_hz=spectrum.resolution_hz / math.sqrt(12.0))
            else:
                jammer = JAMMER_WIDEBAND if kind == REFERENCE_LEARNED else JAMMER_UNKNOWN
                centre = 0.5 * (first + last)
                v.update(frequency_std_hz=spectrum.resolution_hz / math.sqrt(24.0))
            frequency_hz = spectrum.center_frequency_hz + (centre - p.center_bin) * spectrum.resolution_hz
            v.update(frequency_hz=float(frequency_hz),
                     bandwidth_hz=(last - first + 1) * spectrum.resolution_hz, peak_rise_db=float(r[peak]),
                     **_excess(r, test.sigma, ref_db, first, last))
        confidence = (0.0, p.fallback_confidence, 1.0)[kind]
        return SpectrumDetection(state=state, jammer_type=jammer, reference=kind, confidence=confidence,
                                 first_bin=first, last_bin=last, level_rise_db=test.level_rise_db,
                                 pga_change_db=test.pga_change_db, outcome=outcome, **v)

    def _persist(self, block: BlockReference, d: SpectrumDetection) -> SpectrumDetection:
        """DETECTED only after ``alarm_persistence`` reports in a row with overlapping findings
        (within a bin); before that SUSPECTED, with the decision SUSPECT."""
        if d.state not in (STATE_SUSPECTED, STATE_DETECTED):
            block.streak, block.last_bins = 0, None
            return d
        prev = block.last_bins
        overlap = prev is not None and d.first_bin <= prev[1] + 1 and prev[0] <= d.last_bin + 1
        block.streak = block.streak + 1 if overlap else 1
        block.last_bins = (d.first_bin, d.last_bin)
        if d.state == STATE_DETECTED and block.streak < self.params.alarm_persistence:
            return replace(d, state=STATE_SUSPECTED, outcome=replace(d.outcome, decision=DECISION_SUSPECT))
        return d

    def _region(self, r: np.ndarray, first: int, last: int) -> tuple[int, int]:
        """The window grown and trimmed to where the rise stays at or above ``band_edge_fraction``
        of the window's mean rise (untested bins have r = 0 and stop the growth)."""
        edge = self.params.band_edge_fraction * float(np.mean(r[first:last + 1]))
        a, b = first, last
        while a > 0 and r[a - 1] >= edge:
            a -= 1
        while b < r.size - 1 and r[b + 1] >= edge:
            b += 1
        while a < b and r[a] < edge:
            a += 1
        while b > a and r[b] < edge:
            b -= 1
        return a, b

    def _input_level(self, spectrum: SpectrumInput) -> float:
        """Median bin level referred to the PGA input, dB."""
        level, pga = float(np.median(spectrum.power_db)), float(spectrum.pga_gain_db)
        return level - pga if self.params.spectrum_after_pga and math.isfinite(pga) else level

    def _block(self, spectrum: SpectrumInput) -> BlockReference:
        geometry = (float(spectrum.power_db.size), float(spectrum.center_frequency_hz), float(spectrum.span_hz),
                    float(math.isfinite(spectrum.pga_gain_db)))
        key = int(spectrum.rf_block_id)
        block = self._blocks.get(key)
        if block is None or block.geometry != geometry:
            self.counts["reference_resets"] += block is not None
            block = self._blocks[key] = BlockReference(geometry, self.params.reference_reports,
                                                       self.params.window_bins, self.params.noise_floor_db)
        return block

    def _learn(self, block: BlockReference, spectrum: SpectrumInput) -> None:
        block.learn(spectrum.power_db, self._input_level(spectrum), float(spectrum.pga_gain_db))
        self.counts["learned"] += 1


def _parabolic_offset(r: np.ndarray, peak: int) -> float:
    """Vertex of the parabola through ``r[peak - 1 : peak + 2]`` relative to ``peak``, bins, in
    [-0.5, 0.5] (0 at the ends of the spectrum or without a maximum)."""
    if peak <= 0 or peak >= r.size - 1:
        return 0.0
    left, mid, right = float(r[peak - 1]), float(r[peak]), float(r[peak + 1])
    curvature = left - 2.0 * mid + right
    return 0.0 if curvature >= 0.0 else float(np.clip(0.5 * (left - right) / curvature, -0.5, 0.5))


def _excess(r: np.ndarray, sigma: np.ndarray, ref_db: np.ndarray, first: int, last: int) -> dict[str, float]:
    """J/N of bins ``first..last`` (rise ``r`` over the reference ``ref_db``, dB): in their own band,
    with its std from the per-bin noise ``sigma``, and over the noise of the whole span."""
    rise = 10.0 ** (r[first:last + 1] / 10.0)
    excess = float(np.sum(rise - 1.0))
    if excess <= 0.0:
        return dict(excess_db=math.nan, excess_std_db=math.nan, jammer_to_noise_db=math.nan)
    std = math.sqrt(float(np.sum((LN10_OVER_10 * rise * sigma[first:last + 1]) ** 2)))
    noise = 10.0 ** ((ref_db - float(np.max(ref_db))) / 10.0)
    span_jn = float(np.sum(noise[first:last + 1] * (rise - 1.0))) / float(np.sum(noise))
    return dict(excess_db=10.0 * math.log10(excess / rise.size), excess_std_db=std / excess / LN10_OVER_10,
                jammer_to_noise_db=10.0 * math.log10(span_jn))
