"""Our estimator: the short-time FFT analysis of each block (the "stft" estimator, docs/rfi_monitor/stft_estimator.md).

Pure module (no ROS). ``RfiMonitor`` (monitor module) hands it each checked block. Per block, in order:

1. the block's Welch PSD (classifier) and power, checked against the noise reference (noise_reference module);
2. the ridge analysis (ridge module) at the frame length chosen for the stream, on the block's tail first while a
   chirp is tracked or nothing is (``RidgeParams.tracking_samples`` / ``acquisition_samples``), on the whole block
   when the tail disagrees, the frame length chosen again when a jammer appears at a length chosen on noise;
3. the decision (``_decide``: CW, CHIRP, WIDEBAND or NONE from the ridge and the spectral features);
4. with no CW or chirp in the block: the evidence over blocks (integration module) and the spectral-step test of a
   noise jammer in part of the band (spectral_step module);
5. the J/N (against the reference; a chirp's also from the block's constant envelope, constant_envelope module),
   J/S, and a chirp's sweep fields, kept consistent across blocks (sweep_consistency module).

The paper's per-sample tracker is the other estimator (kalman_estimator module). A live node behind its stream may
ask for the light analysis instead (light_analysis module).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from rfi_monitor import ridge as rg
from rfi_monitor.analysis_worker import AnalysisWorker
from rfi_monitor.classifier import (
    CHIRP,
    CW,
    CW_MIN_LINE_FRACTION,
    NONE,
    WIDEBAND,
    BlockFeatures,
    features_from_psd,
    logistic,
    smooth_template,
    welch_psd,
)
from rfi_monitor.constant_envelope import constant_envelope_jn_db
from rfi_monitor.estimate import (
    BLANK_BLOCK,
    IMPLAUSIBLE_POWER,
    MAX_POWER_JN_DB,
    MIN_BLOCK_POWER,
    POWER_OVERFLOW,
    REF_IN_BLOCK,
    REF_LEARNED,
    TRACKER_COUNTERS,
    Block,
    BlockCounters,
    BlockSpectrum,
    JammerEstimate,
    jammer_to_signal_db,
    make_estimate,
    off_floor,
    relative_frequency_hz,
)
from rfi_monitor.integration import IntegratedDecision, Integrator
from rfi_monitor.light_analysis import LastFull, light_estimate
from rfi_monitor.noise_reference import NoiseReference
from rfi_monitor.params import RfiMonitorParams
from rfi_monitor.spectral_step import SpectralStep, StepDecision
from rfi_monitor.sweep_consistency import PERIOD_CONFIRM_MARGIN_DB, SUBHARMONIC_TOLERANCE, SweepMemory, multiple

RESELECT_BLOCKS = 64
"""The "stft" estimator chooses its frame length again every this many blocks while it reports a CW or a
chirp (choosing costs a few short-time FFTs of a slice of the block, about the cost of the analysis)."""
RESELECT_IDLE_BLOCKS = 16
"""... and every this many blocks while it reports neither (a jammer that appears is analysed at its best
frame length from at most this many blocks later; before that at the current one, which mostly sees it too, and
a block that shows anything at all makes it choose again at once). 4 before the speed work of issue 14 item 6:
choosing costs about 0.8 ms at 38.192 MS/s, 0.2 ms per quiet block at 4; on noise the choice is now the longest
frame whatever the block (ridge.choose_frame_length), so choosing often bought nothing there."""
ENVELOPE_MIN_IN_BAND = 0.9
"""The J/N of a chirp with an in-block noise reference is also read from the block's moments
(``constant_envelope``) only when the chirp is in band for at least this share of its period: a sweep that leaves
the band is pulsed in band, not of constant envelope (its estimate would err low, and the spectral one is kept
anyway; this spares the cost)."""
APERIODIC_MARGIN_DB = 3.0
"""A moving ridge without a period in the block (ridge: present in half the frames, coherent, over >= 4 bins) is a
chirp only from ``detect_jn_db`` minus this, dB (the in-block J/N of sweeps reads up to 1.3 dB low). On the whole
real clean captures in 1024-sample blocks (few frames) such ridges appeared by chance at J/N -16 to -5 dB (5 of
3,139 blocks, 3 of them below -9 dB); a periodic ridge (a 7-sigma period) needs no level."""


@dataclass
class _Ahead:
    """A block's ridge analysis started on the worker (StftEstimator._with_worker): on the last ``size`` samples,
    at ``frame_length`` (0: the worker chose it on the whole block first); its answer once collected."""

    size: int
    frame_length: int
    result: rg.RidgeResult | None = None
    collected: bool = False



@dataclass
class _Levels:
    """A block's spectrum and levels (step 1): its Welch PSD normalised to sum 1, the frames it averages, its power,
    its features, and the noise reference (power and REF_* code)."""

    norm: np.ndarray
    frames: int
    power: float
    feat: BlockFeatures
    floor: float
    ref: int


@dataclass
class _Verdict:
    """The block's type, confidence and J/N as the steps settle them (J/N against the reference and against the
    in-block noise level beside it)."""

    jtype: int
    conf: float
    jn: float
    jn_ref: float
    jn_in: float
    floor: float
    ref: int


class StftEstimator:
    """The short-time FFT analysis over a stream of blocks (module docstring; ``estimate.Estimator``).

    Args:
        params: the monitor's parameters (``estimator`` "stft").
        counters: the monitor's counters (shared).
        worker: an AnalysisWorker that runs the ridge analysis beside the rest of each block (analysis_worker
            module; the results are the same with or without it), or None.
    """

    def __init__(self, params: RfiMonitorParams, counters: BlockCounters, worker: AnalysisWorker | None = None
                 ) -> None:
        self.params = params
        self.worker = worker
        self._counts = counters
        self._integrator = Integrator(params.integration, params.classifier.detect_jn_db)
        self._step = SpectralStep(params.spectral_step, params.classifier.nfft)
        self._noise = NoiseReference(params)
        self._sweep = SweepMemory(params.integration.window_s)
        self.last_step: StepDecision | None = None
        self.last_integration: IntegratedDecision | None = None
        self.last_spectrum: BlockSpectrum | None = None
        """The Welch spectrum of the last block analysed in full (for display: ``RfiMonitor.last_spectrum``)."""
        self._last_single = NONE
        self._off_floor_run = 0
        self._last_full: LastFull | None = None
        self._full_levels: tuple[float, float, float, bool] | None = None
        self._frame_length = 0
        self._blocks_since_select = 0
        self._tracking = False
        self._chirp = False

    # --- the stream -------------------------------------------------------------------------
    def reset(self, keep_calibration: bool) -> None:
        if not keep_calibration:
            self._integrator.reset()
            self._step.reset()
            self._sweep.forget()
            self._noise.forget()
            self._last_full = None
        self._frame_length = 0

    def gap(self, missing_samples: int, stamp_ns: int, short: bool) -> None:
        """A short gap keeps the frame length and charges its samples to the integration's budget
        (``monitor.FRAME_KEEP_GAP_S``); a long one chooses the length again on the next block."""
        length = self._frame_length
        self.reset(keep_calibration=True)
        if short:
            self._frame_length = length
            self._integrator.skipped(missing_samples, stamp_ns)

    def skip_invalid(self, block: Block) -> None:
        """Nothing to keep continuous: each block is analysed on its own."""

    @property
    def calibrated(self) -> bool:
        """The "stft" estimator does not wait for a floor (its J/N reference is the in-block noise level until then):
        True once a floor is fixed (``noise_floor_power``) or learned from ``calibration_blocks`` blocks that passed
        as noise."""
        return self.params.noise_floor_power > 0 or math.isfinite(self._noise.floor)

    def counters(self) -> dict[str, int]:
        """The spectral-step test's counts (``estimate.SPECTRAL_STEP_COUNTERS``)."""
        d = dict.fromkeys(TRACKER_COUNTERS, 0)
        d["spectral_step_not_flat"] = self._step.not_flat
        d["spectral_step_relearned"] = self._step.relearned
        return d

    # --- one block --------------------------------------------------------------------------
    def analyse(self, block: Block, return_traces: bool, light: bool) -> JammerEstimate:
        """The full analysis of the block, or its light analysis (``light``: light_analysis module) when that
        suffices. ``return_traces`` is ignored (no per-sample estimates)."""
        if light:
            est = light_estimate(block, self._last_full, self.params, self._noise, self._counts)
            if est is not None:
                return est
            self._counts["light_escalations"] += 1
        est = self._with_worker(block)
        levels, self._full_levels = self._full_levels, None
        self._last_full = None
        if est.valid and levels is not None:
            power, noise, peak, integrated = levels
            jn_pow = 10 * math.log10(power / noise - 1.0) if power > noise > 0 else -math.inf
            self._last_full = LastFull(est, power, noise, jn_pow, peak, integrated, block.fs, block.cplx)
        return est

    def _with_worker(self, block: Block) -> JammerEstimate:
        """The full analysis (module docstring). With a worker (constructor),
        the block's ridge analysis starts there first, on the part of the block and at the frame length this
        process would use (when the frame length is due to be chosen again, the worker chooses it on the whole
        block first, as here); the result is used only if this process then analyses that part at that length,
        as it would have done itself (analysis_worker module docstring)."""
        w = self.worker
        ahead = None
        if w is not None and w.alive:
            due = self._frame_length == 0 or self._blocks_since_select >= (RESELECT_BLOCKS if self._tracking
                                                                             else RESELECT_IDLE_BLOCKS)
            tail = self._part_samples(block.n)
            if w.submit(block.samples, block.cplx, block.fs, self.params.ridge, 0 if due else self._frame_length,
                        tail, fine_hook=self._sweep.hook_test_due(block.stamp_ns, self._chirp)):
                ahead = _Ahead(tail if tail else block.n, 0 if due else self._frame_length)
        try:
            return self._full(block, ahead)
        finally:
            if w is not None:
                w.cancel()               # not used (an early return, or another length or part): dropped
                self._counts["worker_failures"] = w.failures

    def _part_samples(self, n: int) -> int:
        """How many of a block's last samples the ridge analysis takes first (0: the whole block):
        ``RidgeParams.tracking_samples`` while a chirp is tracked, ``acquisition_samples`` while nothing is (the
        last block was neither CW nor CHIRP), the whole block while a CW is."""
        r = self.params.ridge
        k = int(r.tracking_samples) if self._chirp else (0 if self._tracking else int(r.acquisition_samples))
        return k if 0 < k < n else 0

    def _collect_ahead(self, ahead: _Ahead) -> None:
        """The worker's answer for this block, into ``ahead.result`` (None if it failed); counted."""
        assert self.worker is not None
        ahead.result = self.worker.collect()
        ahead.collected = True
        self._counts["worker_blocks"] += ahead.result is not None
        self._counts["worker_failures"] = self.worker.failures

    def _full(self, block: Block, ahead: _Ahead | None) -> JammerEstimate:
        """Steps 1-5 of the module docstring."""
        self._full_levels = None
        lv = self._levels(block)
        if isinstance(lv, JammerEstimate):
            return lv
        rr, v = self._ridge_pass(block, lv, ahead)
        if not rr.noise_power >= MIN_BLOCK_POWER:
            # no noise at all in the block (a few non-zero samples): nothing to measure against
            return self._counts.rejected(BLANK_BLOCK, block)
        if v.ref == REF_IN_BLOCK and lv.power > rr.noise_power * 10 ** (MAX_POWER_JN_DB / 10):
            return self._counts.rejected(IMPLAUSIBLE_POWER, block)
        integrated = self._evidence_over_blocks(block, v)
        step = self._spectral_step_test(block, lv, v, integrated)
        if v.jtype == NONE:
            cp = self.params.classifier
            v.jn = max(v.jn, 5.0 * math.log10((1.0 if block.cplx else 2.0) / (lv.frames * cp.nfft)))
        if integrated is not None:
            if self._full_levels is not None:
                self._full_levels = self._full_levels[:3] + (True,)
            return self._integrated_estimate(integrated, v.jn, block, v.ref, rr)
        self._jn_beside_agc_and_envelope(block, rr, v)
        if v.jtype == NONE:
            # the floor learns only from blocks that pass as noise inside the block too
            p = self.params
            if block.clipped <= p.clip_lower_bound_fraction and not rr.periodic and v.jn_in < p.classifier.detect_jn_db:
                self._noise.learn(lv.power, lv.norm)
                self._step.learn()
        if not math.isfinite(v.jn):
            v.jn = math.nan
        return self._estimate(block, lv, rr, v, step)

    def _levels(self, block: Block) -> _Levels | JammerEstimate:
        """Step 1: the block's Welch PSD, power and features, checked against the noise reference (a rejection when
        the block cannot be analysed)."""
        p = self.params
        cp = p.classifier
        psd, frames = welch_psd(block.samples, cp.nfft, cp.max_frames)
        self.last_spectrum = BlockSpectrum(block.stamp_ns, psd, block.fs, block.fif, block.cplx)   # for display
        power = float(psd.sum())
        if not math.isfinite(power):
            return self._counts.rejected(POWER_OVERFLOW, block)
        if not power >= MIN_BLOCK_POWER:
            return self._counts.rejected(BLANK_BLOCK, block)
        floor, ref = self._noise.reference(block.fs, block.cplx, block.full_scale, math.nan)
        if ref != REF_IN_BLOCK:
            # a block far below or above a known floor: gain or scale no longer match it (monitor module docstring);
            # a learned floor that stays off for calibration_blocks blocks is learned again
            off = off_floor(power, floor)
            if off is not None:
                self._off_floor_run += 1
                if ref == REF_LEARNED and self._off_floor_run >= p.calibration_blocks:
                    self._counts["recalibrations"] += 1
                    self._noise.forget()
                    self._step.reset()           # the shape learned with that floor is as doubtful
                    self._off_floor_run = 0
                return self._counts.rejected(off, block)
        self._off_floor_run = 0
        norm = psd / power
        tpl = self._noise.template if self._noise.template is not None else smooth_template(norm,
                                                                                             cp.template_smooth_bins)
        feat = features_from_psd(psd, frames, tpl, cp, block.cplx)
        return _Levels(norm, frames, power, feat, floor, ref)

    def _ridge_pass(self, block: Block, lv: _Levels, ahead: _Ahead | None) -> tuple[rg.RidgeResult, _Verdict]:
        """Step 2 and 3: the ridge analysis at the stream's frame length, on the block's tail first, and the decision.

        The frame length is chosen on the first block, every RESELECT_IDLE_BLOCKS blocks while nothing is tracked,
        every RESELECT_BLOCKS while something is, and at once (the block analysed again) when a block shows a chirp
        or a wideband rise at a frame length chosen while nothing was tracked (a length chosen on noise can resolve a
        sweep as noise, or fold its period)."""
        p = self.params
        xs, cplx, stamp_ns, n = block.samples, block.cplx, block.stamp_ns, block.n
        reselected = False
        if self._frame_length == 0 or self._blocks_since_select >= (RESELECT_BLOCKS if self._tracking
                                                                    else RESELECT_IDLE_BLOCKS):
            if ahead is not None and ahead.frame_length == 0:
                self._collect_ahead(ahead)       # the worker chose it on the whole block, as below
            self._frame_length = (ahead.result.frame_length if ahead is not None and ahead.result is not None
                                  else rg.choose_frame_length(xs, cplx, p.ridge))
            self._blocks_since_select = 0
            reselected = True
        self._blocks_since_select += 1
        tail = self._part_samples(n)
        part = xs[-tail:] if tail else xs
        floor = lv.floor
        while True:
            rr = None
            if ahead is not None and ahead.size == part.size:
                # started on the worker (_with_worker): the same samples (the whole block, or its tail: the rule there
                # is this one, on state that has not changed since) at the same length
                if not ahead.collected:
                    self._collect_ahead(ahead)
                if ahead.result is not None and ahead.result.frame_length == self._frame_length:
                    rr = ahead.result
            ahead = None
            if rr is None:
                rr = rg.analyse(part, cplx, block.fs, p.ridge, self._frame_length,
                                fine_hook=self._sweep.hook_test_due(stamp_ns, self._chirp))
            rr = self._sweep.remember_hook(rr, stamp_ns)
            jtype, conf, jn, jn_ref, jn_in, floor = self._decide(lv.power, lv.feat, rr, lv.floor, lv.ref)
            self._full_levels = (lv.power, floor, lv.feat.peak_frequency, False)   # for the light analysis
            if part.size < n and self._chirp and not rr.sweeping:
                part = xs            # the tail shows no sweep (any more): the whole block decides
                continue
            if part.size < n and not self._chirp and (jtype != NONE or rr.sweeping or rr.periodic):
                part = xs            # a quiet stream's part shows something: the whole block decides
                continue
            # a jammer seen at a frame length chosen on blocks without one: choose again on this block
            if jtype in (NONE, CW) or reselected or self._tracking or rr.noise_power < MIN_BLOCK_POWER:
                break
            length = rg.choose_frame_length(xs, cplx, p.ridge)
            reselected = True
            self._blocks_since_select = 1
            if length == self._frame_length:
                break
            self._frame_length = length
        return rr, _Verdict(jtype, conf, jn, jn_ref, jn_in, floor, lv.ref)

    def _evidence_over_blocks(self, block: Block, v: _Verdict) -> IntegratedDecision | None:
        """Step 4a: the evidence of the blocks of the last integration_window_s (integration module); decides only
        when this block alone shows no CW or chirp (a single block that suffices adds no latency). Returns the
        decision that this block reports, or None."""
        if not self._integrator.enabled:
            return None
        if v.jtype in (CW, CHIRP):
            self._last_single = v.jtype        # one block suffices: no evidence gathered (speed while tracking)
            return None
        if self._last_single in (CW, CHIRP):
            self._integrator.restart()         # the jammer one block showed is gone: its evidence goes too
            self._sweep.integrated = None
        self._last_single = v.jtype
        d = self._integrator.add(block.samples, block.cplx, block.fs, block.stamp_ns)
        self.last_integration = d
        if d.type == CHIRP and math.isfinite(d.period_samples):
            self._sweep.integrated = (float(d.period_samples), int(block.stamp_ns))
        c = self._counts
        c["integration_window_blocks"] = d.blocks
        c["integration_blocks_thinned"] = self._integrator.thinned
        c["integration_switch_offs"] = self._integrator.switch_offs
        c["integration_submultiple_periods"] = self._integrator.submultiples
        c["integration_ambiguous_periods"] = self._integrator.ambiguous_periods
        if d.type == CHIRP and v.jtype in (NONE, WIDEBAND):
            # a periodic sweep in the window: no noise jammer makes one (the per-bin mean is removed, its frames are
            # independent), so a block reported WIDEBAND from its broad excess is a sweep seen too weakly per frame
            # for the ridge (measured: saw-tooths at J/N -2..0 dB on 2-bit captures)
            v.jtype = NONE
        if v.jtype == NONE and d.type != NONE:
            c["integrated_reports"] += 1
            return d
        return None

    def _spectral_step_test(self, block: Block, lv: _Levels, v: _Verdict, integrated: IntegratedDecision | None
                            ) -> StepDecision | None:
        """Step 4b: a noise jammer in part of the band behind an AGC: the step it makes in the spectrum's shape
        against the shape of the blocks that passed as noise (spectral_step module); blocks with a tone or a sweep
        are not summed. Returns the detection, or None."""
        if not self.params.spectral_step.enabled:
            return None
        if not (v.jtype in (NONE, WIDEBAND) and integrated is None):
            self._step.restart()
            return None
        step = self._step.test(lv.norm, lv.frames, block.cplx, block.stamp_ns)
        self.last_step = step
        if not step.detected:
            return None
        # a block already WIDEBAND from its power or spectral excess gets the band (and the larger J/N)
        if v.jtype == NONE:
            v.jtype = WIDEBAND
            v.conf = logistic(step.z - step.threshold, 1.0)
        if step.jn_db > v.jn:
            v.jn, v.ref = step.jn_db, REF_LEARNED     # measured against the learned noise shape
        self._counts["spectral_step_reports"] += 1
        return step

    def _jn_beside_agc_and_envelope(self, block: Block, rr: rg.RidgeResult, v: _Verdict) -> None:
        """Step 5a: the J/N of a CW or chirp against the in-block noise where an AGC hides it from the block power,
        and a chirp's from its constant envelope."""
        p = self.params
        if (v.jtype in (CW, CHIRP) and v.ref != REF_IN_BLOCK and math.isfinite(v.jn) and v.jn == v.jn_in
                and v.jn_in > v.jn_ref):
            # an AGC (or a gain change) hides the jammer from the block power; the noise measured in the block
            # beside the jammer shows it: J/N against REF_IN_BLOCK, and said so
            v.ref = REF_IN_BLOCK
        if (v.jtype in (CW, CHIRP) and v.ref == REF_IN_BLOCK and not block.coarse
                and block.clipped <= p.clip_lower_bound_fraction
                and (v.jtype == CW or rr.in_band_fraction >= ENVELOPE_MIN_IN_BAND)):
            # the in-block noise beside a strong fast sweep reads high (its leakage fills every bin of every frame):
            # the noise from the block's moments under a constant envelope (constant_envelope module) errs only
            # low in J/N, so the larger of the two J/Ns is kept
            jn_env = constant_envelope_jn_db(block.samples, block.cplx)
            if math.isfinite(jn_env) and jn_env > v.jn:
                v.jn = jn_env
                self._counts["jn_from_envelope"] += 1

    def _estimate(self, block: Block, lv: _Levels, rr: rg.RidgeResult, v: _Verdict, step: StepDecision | None
                  ) -> JammerEstimate:
        """Step 5b: J/S and the frequency fields (a CW's from the Welch peak, a noise jammer's band, a chirp's from
        the ridge: ``_chirp_fields``)."""
        p = self.params
        cp = p.classifier
        fs, fif, cplx = block.fs, block.fif, block.cplx
        nan = math.nan
        js = jammer_to_signal_db(v.jtype, v.jn, fs, cplx, p)
        freq = fstd = rate = per = f0 = bw = inb = nan
        shape = rg.SHAPE_UNKNOWN
        if v.jtype == CW:
            freq = relative_frequency_hz(lv.feat.peak_frequency, fs, fif, cplx)
            fstd = fs / cp.nfft / math.sqrt(12.0)
            rate = 0.0
        elif step is not None:
            # the band that rose: its centre, and the std of a uniform spread over it
            freq = relative_frequency_hz(0.5 * (step.low + step.high), fs, fif, cplx)
            fstd = (step.high - step.low) * fs / math.sqrt(12.0)
        elif v.jtype == CHIRP:
            freq, fstd, rate, per, f0, bw, inb, shape = self._chirp_fields(block, rr, v.jn)
        self._tracking = v.jtype in (CW, CHIRP)
        self._chirp = v.jtype == CHIRP
        lower = (block.clipped > p.clip_lower_bound_fraction or block.coarse) and v.jtype != NONE
        return make_estimate(block.stamp_ns, int(v.jtype), float(v.conf), float(v.jn), float(js), freq, fstd, rate,
                              per, f0, bw, fs, block.first, block.n, True, self._counts.snapshot(), None, "", v.ref,
                              bool(lower), float(block.clipped), int(shape), inb)

    def _chirp_fields(self, block: Block, rr: rg.RidgeResult, jn: float
                      ) -> tuple[float, float, float, float, float, float, float, int]:
        """(frequency, its std, rate, period, start, bandwidth, in-band fraction, shape) of a chirp, from the ridge,
        kept consistent with the evidence over blocks and recent blocks (sweep_consistency module)."""
        p = self.params
        cp = p.classifier
        fs, fif, cplx, stamp_ns = block.fs, block.fif, block.cplx, block.stamp_ns
        nan = math.nan
        freq = fstd = per = f0 = bw = inb = nan
        inverted = (not cplx) and fif < 0
        lo_dig = -0.5 if cplx else 0.0
        if math.isfinite(rr.frequency) and lo_dig <= rr.frequency <= 0.5:
            freq = relative_frequency_hz(rr.frequency, fs, fif, cplx)
            fstd = rr.frequency_std * fs
        else:
            self._counts["frequency_not_tracked"] += 1
        sgn = -1.0 if inverted else 1.0
        rate = sgn * rr.rate * fs * fs if math.isfinite(rr.rate) else nan
        shape = rr.shape
        if inverted and shape in (rg.SAWTOOTH_UP, rg.SAWTOOTH_DOWN):
            shape = rg.SAWTOOTH_DOWN if shape == rg.SAWTOOTH_UP else rg.SAWTOOTH_UP
        if rr.periodic:
            per = rr.period_samples / fs
            inb = rr.in_band_fraction
        if math.isfinite(rr.low) and math.isfinite(rr.high):
            a, b = relative_frequency_hz(rr.low, fs, fif, cplx), relative_frequency_hz(rr.high, fs, fif, cplx)
            bw = abs(b - a)
            if math.isfinite(rr.start):
                f0 = relative_frequency_hz(rr.start, fs, fif, cplx)
        m = multiple(rr.period_samples, self._sweep.integrated_period(stamp_ns)) if rr.periodic else 0
        if m >= 3 or (m == 2 and jn < cp.detect_jn_db):
            # SUBHARMONIC_TOLERANCE: the block's ridge locked on a multiple of the period the evidence over the window
            # found (a weak sweep whose period is near a whole number of hops beats with the frame grid); the
            # window's period is reported, the sweep law fitted on the multiple is not (frequency, rate, band and
            # start NaN), the shape and in-band fraction come from the block folded on it. Twice the window's period
            # only from a block below the detection J/N: the window's comb on amplitudes sees a symmetric triangle
            # (the same in-band pattern on the way up and down) at half its period, where a strong block is right
            p_int = self._sweep.integrated_period(stamp_ns)
            self._counts["block_periods_from_integration"] += 1
            per = p_int / fs
            freq = fstd = rate = f0 = bw = nan
            shape, inb, _, _ = rg.folded_shape(block.samples, cplx, p_int, p.ridge)
            if inverted and shape in (rg.SAWTOOTH_UP, rg.SAWTOOTH_DOWN):
                shape = rg.SAWTOOTH_DOWN if shape == rg.SAWTOOTH_UP else rg.SAWTOOTH_UP
            if shape == rg.SHAPE_UNKNOWN:
                inb = nan
        elif rr.periodic and not jn >= cp.detect_jn_db + PERIOD_CONFIRM_MARGIN_DB and not self._sweep.period_confirmed(
                rr.period_samples, stamp_ns, jn >= cp.detect_jn_db):
            # a block below (or just above) the detection J/N has a ridge in a few of its frames, and the
            # autocorrelation of so few can peak at a multiple of the period or beside it (stft_shapes.md at J/N
            # -5 dB: 4-100 % off): its period, and the sweep law fitted on it (frequency, rate, start) and the band
            # read with it, are published only when the evidence over blocks or a recent block found the same
            # period (PERIOD_CONFIRM_MARGIN_DB); else NaN (counted). The type, J/N and the block's shape stay.
            self._counts["block_periods_unconfirmed"] += 1
            per = inb = freq = fstd = rate = f0 = bw = nan
        if rr.periodic:
            self._sweep.add_block_period(rr.period_samples, stamp_ns)
        return freq, fstd, rate, per, f0, bw, inb, int(shape)

    def _integrated_estimate(self, d: IntegratedDecision, jn: float, block: Block, ref: int, rr: rg.RidgeResult
                             ) -> JammerEstimate:
        """A CW or chirp found only by the evidence over blocks (integration module). Type, confidence (0.5 at the
        threshold) and, for a CW, its frequency; a chirp's sweep period from the comb, and its sweep shape and
        in-band fraction from this block's short-time spectrum folded on that period (``ridge.folded_shape``:
        synchronous averaging over the block's periods; unknown / NaN when the block does not show it); the J/N
        is this block's own measurement (mostly its resolution: such a jammer is below what one block measures),
        flagged as a lower bound; a chirp's frequency at the block end from this block's own frames where they show
        the window's period (``ridge.frequency_at_period``: rr, the block's analysis, or the block analysed again at
        a frame that resolves the period; counted in ``integrated_frequencies`` and
        ``integrated_frequency_reanalyses``), NaN where they do not (issue 26 item 3); the other fields NaN."""
        p = self.params
        fs, fif, cplx = block.fs, block.fif, block.cplx
        nan = math.nan
        freq = fstd = rate = per = inb = nan
        shape = rg.SHAPE_UNKNOWN
        if d.type == CW:
            conf = logistic(10 * math.log10(max(d.cw_score, 1e-30)), 0.5)
            jn = max(jn, d.excess_db)
            freq = relative_frequency_hz(d.cw_frequency, fs, fif, cplx)
            fstd = fs / self._integrator.params.nfft / math.sqrt(12.0)
            rate = 0.0
        elif not math.isfinite(d.period_samples):
            # a sweep whose period the window's comb cannot tell from a multiple of a shorter one
            # (integration.resolve_submultiple): CHIRP without a period, shape or in-band fraction
            conf = logistic(d.chirp_z - d.chirp_threshold, 1.0)
        else:
            conf = logistic(d.chirp_z - d.chirp_threshold, 1.0)
            per = d.period_samples / fs
            f_dig, fstd_dig, again = rg.frequency_at_period(block.samples, cplx, fs, p.ridge, d.period_samples, rr,
                                                            SUBHARMONIC_TOLERANCE)
            self._counts["integrated_frequency_reanalyses"] += int(again)
            if math.isfinite(f_dig) and (-0.5 if cplx else 0.0) <= f_dig <= 0.5:
                freq, fstd = relative_frequency_hz(f_dig, fs, fif, cplx), fstd_dig * fs
                self._counts["integrated_frequencies"] += 1
            shape, inb, _, _ = rg.folded_shape(block.samples, cplx, d.period_samples, p.ridge)
            if (not cplx) and fif < 0 and shape in (rg.SAWTOOTH_UP, rg.SAWTOOTH_DOWN):
                # spectral inversion: the IF runs against RF (as in _chirp_fields)
                shape = rg.SAWTOOTH_DOWN if shape == rg.SAWTOOTH_UP else rg.SAWTOOTH_UP
            if shape == rg.SHAPE_UNKNOWN:
                inb = nan
        js = jammer_to_signal_db(d.type, jn, fs, cplx, p)
        self._tracking = False
        self._chirp = False
        return make_estimate(block.stamp_ns, int(d.type), float(conf), float(jn), float(js), freq, fstd, rate, per,
                              nan, nan, fs, block.first, block.n, True, self._counts.snapshot(), None, "", ref, True,
                              float(block.clipped), int(shape), float(inb))

    def _decide(self, power: float, feat: BlockFeatures, rr: rg.RidgeResult, floor: float, ref: int
                ) -> tuple[int, float, float, float, float, float]:
        """(type, confidence, J/N, J/N against the reference, J/N against the in-block level, the floor used)
        of the "stft" estimator (docs/rfi_monitor/stft_estimator.md, step 6)."""
        cp = self.params.classifier
        if ref == REF_IN_BLOCK:
            floor = rr.noise_power
        jn_ref = 10 * math.log10(power / floor - 1.0) if power > floor else -math.inf
        jn_in = 10 * math.log10(power / rr.noise_power - 1.0) if power > rr.noise_power > 0 else -math.inf
        thr = cp.detect_jn_db
        s = cp.confidence_slope_db
        narrow = feat.jn_spectral_db >= thr
        cw = narrow and (feat.occupancy <= cp.cw_max_occupancy or feat.line_fraction >= CW_MIN_LINE_FRACTION)
        jn = jn_ref
        if cw and not rr.sweeping:
            return (CW, logistic(feat.jn_spectral_db - thr, s), max(jn_ref, feat.jn_spectral_db, jn_in), jn_ref, jn_in,
                    floor)
        if rr.sweeping and (rr.periodic or max(jn_ref, jn_in) >= thr - APERIODIC_MARGIN_DB):
            conf = logistic(max(jn_ref, jn_in) - thr, s) * (1.0 if rr.periodic else 0.6)
            return CHIRP, conf, max(jn_ref, jn_in), jn_ref, jn_in, floor
        if ref != REF_IN_BLOCK and jn_ref >= thr:
            return WIDEBAND, logistic(jn_ref - thr, s), jn, jn_ref, jn_in, floor
        if narrow:
            return (WIDEBAND, 0.5 * logistic(feat.jn_spectral_db - thr, s), max(jn_ref, feat.jn_spectral_db), jn_ref,
                    jn_in, floor)
        conf = 1.0 - logistic(max(feat.jn_spectral_db, jn_ref) - thr, s)
        return NONE, conf, max(jn_ref, feat.jn_spectral_db), jn_ref, jn_in, floor
