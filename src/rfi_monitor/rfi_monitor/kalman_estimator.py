"""The paper's estimator: the per-sample tracker of Kang et al. on each block (the "kalman" estimator).

Pure module (no ROS). ``RfiMonitor`` (monitor module) hands it each checked block. Per block: the fused per-sample
loop (``tracker.track_block``: three-sample IF measurement, eq. 8/10 or its complex counterpart; adaptive fading KF,
eq. 11-20; LPD + AR sweep period, eq. 23-27; resets at the predicted sweep starts, eq. 21-22), cut at absolute
multiples of the periodicity detector's hop (``sweep_analysis``, ours), then the block features and the
identification (``classifier``), J/N from the block power against the calibrated noise floor (monitor module
docstring: calibration), and J/S = J/N + N - S from the nominal noise and signal powers.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from rfi_monitor import sweep_period as sp
from rfi_monitor.classifier import (
    CHIRP,
    CW,
    NONE,
    UNKNOWN,
    classify,
    features_from_psd,
    smooth_template,
    welch_psd,
)
from rfi_monitor.estimate import (
    BLANK_BLOCK,
    MIN_BLOCK_POWER,
    POWER_OVERFLOW,
    REF_FIXED,
    REF_LEARNED,
    SPECTRAL_STEP_COUNTERS,
    Block,
    BlockCounters,
    BlockSpectrum,
    BlockTraces,
    JammerEstimate,
    jammer_to_signal_db,
    off_floor,
    relative_frequency_hz,
)
from rfi_monitor.if_measurement import (
    STATUS_CORRECTION,
    STATUS_DOMAIN,
    STATUS_NEAR_ZERO,
    STATUS_NON_FINITE,
    STATUS_OK,
)
from rfi_monitor.params import RfiMonitorParams
from rfi_monitor.sweep_analysis import SweepAnalysis, analyse
from rfi_monitor.sweep_period import SweepFloat, SweepInt
from rfi_monitor.tracker import track_block
from rfi_monitor.tracker_state import (
    DEC_HISTORY,
    LAT_COARSE,
    MonitorFloat,
    MonitorInt,
    MonitorParam,
    new_trace_buffers,
    new_tracker_state,
)
from rfi_monitor.tracker_steps import MAX_ABS_RATE, lattice_init
from rfi_monitor.tracking_filters import FilterFloat

_STATUS_NAMES = {STATUS_OK: "measurements_ok", STATUS_NEAR_ZERO: "rejected_near_zero",
                 STATUS_DOMAIN: "rejected_arccos_domain", STATUS_NON_FINITE: "rejected_non_finite",
                 STATUS_CORRECTION: "rejected_chirp_correction"}



class KalmanEstimator:
    """The paper's per-sample tracker over a stream of blocks (module docstring; ``estimate.Estimator``).

    Args:
        params: the monitor's parameters (``estimator`` "kalman").
        counters: the monitor's counters (shared).

    Notes:
        Kang et al., eq. 8-27; see the module docstrings of if_measurement, tracking_filters, sweep_period, tracker
        and classifier for each part.
    """

    def __init__(self, params: RfiMonitorParams, counters: BlockCounters) -> None:
        self.params = params
        self._counts = counters
        self._tpar = params.tracker.as_array()
        self._packed: dict[bool, tuple[np.ndarray, np.ndarray]] = {}
        self._off_floor_run = 0
        self._cal_psd: list[np.ndarray] = []
        self._cal_pow: list[float] = []
        self._template: np.ndarray | None = None
        self._floor: float = params.noise_floor_power if params.noise_floor_power > 0 else math.nan
        self._resets_in_block = 0
        self.last_spectrum: BlockSpectrum | None = None
        """The Welch spectrum of the last block identified (for display: ``RfiMonitor.last_spectrum``)."""
        self._reset_tracker()

    def reset(self, keep_calibration: bool) -> None:
        self._reset_tracker()
        if not keep_calibration:
            self._forget_calibration()

    def gap(self, missing_samples: int, stamp_ns: int, short: bool) -> None:
        """The per-sample state is reset at any gap."""
        self._reset_tracker()

    def _reset_tracker(self) -> None:
        """Fresh per-sample tracker state (stream position and calibration kept)."""
        fst, ist, ring = self.params.tracker.initial_state()
        self._state = new_tracker_state(fst, ist, ring, sp.initial_state())
        self._analysis: SweepAnalysis | None = None
        self._stream_first: int | None = None

    @property
    def calibrated(self) -> bool:
        """True once the noise floor and shape are known (fixed, or learned from ``calibration_blocks`` blocks)."""
        return math.isfinite(self._floor) and self._template is not None

    def counters(self) -> dict[str, int]:
        """The per-sample tracker's counts (``estimate.TRACKER_COUNTERS``)."""
        d = {name: int(self._state.counters[code]) for code, name in _STATUS_NAMES.items()}
        d["sweep_resets"] = int(self._state.mist[MonitorInt.NRESETS])
        d["sweep_start_fits"] = int(self._state.mist[MonitorInt.NFIT])
        d["period_search_suspensions"] = int(self._state.mist[MonitorInt.NSUSP])
        d.update(dict.fromkeys(SPECTRAL_STEP_COUNTERS, 0))
        return d

    def skip_invalid(self, block: Block) -> None:
        """Run the per-sample loop over a rejected block's zeroed samples (keeps the state continuous)."""
        self._run_chunks(block.samples, block.cplx, block.first, block.fs, False)

    def analyse(self, block: Block, return_traces: bool, light: bool) -> JammerEstimate:
        """The per-sample loop over the block (always run: keeps the state continuous), then the identification.
        ``light`` is ignored (the "stft" estimator's)."""
        resets_before = int(self._state.mist[MonitorInt.NRESETS])
        if self._stream_first is None:
            self._stream_first = block.first
        traces = self._run_chunks(block.samples, block.cplx, block.first, block.fs, return_traces)
        self._resets_in_block = int(self._state.mist[MonitorInt.NRESETS]) - resets_before
        est = self._identify(block, traces)
        lower = block.clipped > self.params.clip_lower_bound_fraction or block.coarse
        ref = REF_FIXED if self.params.noise_floor_power > 0 else REF_LEARNED
        return dataclasses.replace(est, noise_reference=ref, jammer_to_noise_is_lower_bound=lower and est.valid,
                                   clipped_fraction=block.clipped)

    def _run_chunks(self, xc: np.ndarray, cplx: bool, first: int, fs: float, store: bool) -> BlockTraces | None:
        """Run the fused loop, stopping at absolute analysis boundaries (multiples of the hop) to run
        the periodicity detector, so that the result does not depend on how the stream is cut."""
        ap = self.params.analysis
        if not ap.enabled:
            return self._run_tracker(xc, cplx, first, store)
        hop = max(1, int(round(ap.hop_s * fs)))
        n = xc.size
        cuts = [0]
        b = (first // hop + 1) * hop
        while b <= first + n:
            cuts.append(b - first)
            b += hop
        if cuts[-1] != n:
            cuts.append(n)
        parts = []
        for i0, i1 in zip(cuts[:-1], cuts[1:], strict=False):
            if i1 <= i0:
                continue
            parts.append(self._run_tracker(xc[i0:i1], cplx, first + i0, store))
            if (first + i1) % hop == 0:
                # tracking mode (confirmed lattice): the detector has nothing to seed, and the
                # identification takes the confirmed lattice as the periodicity evidence
                if not (ap.skip_while_tracking and int(self._state.mist[MonitorInt.TRACK]) == 1):
                    self._run_analysis(first + i1)
        if not store:
            return None
        tr = [p for p in parts if p is not None]
        return BlockTraces(*(np.concatenate([getattr(t, name) for t in tr]) for name in
                             ("sample_index", "z", "f", "df", "p11", "z_ar", "reset")))

    def _run_analysis(self, at_index: int) -> None:
        """Periodicity detector on the decimated history; seeds the reset lattice when none runs."""
        st = self._state
        dec = int(self.params.sweep.decimation)
        ndec = int(st.mist[MonitorInt.NDEC])
        L = min(ndec, DEC_HISTORY)
        if L < self.params.analysis.min_window or self._stream_first is None:
            return
        idx = np.arange(ndec - L, ndec) & (DEC_HISTORY - 1)
        w = st.zdec[idx]
        # decimated value k averages measurements of samples m_first + k D .. + D - 1
        m_first = self._stream_first + 1
        first_centre = m_first + (ndec - L) * dec + 0.5 * (dec - 1)
        a = analyse(w, dec, first_centre, at_index, self.params.analysis)
        self._analysis = a
        if (a.periodic and self.params.refine_window > 0 and self.params.reset_at_sweep_start
                and st.mst[MonitorFloat.NEXT] < 0.0):
            per = a.period_samples
            k = math.ceil((at_index - a.start_index) / per)
            st.mst[MonitorFloat.NEXT] = a.start_index + k * per
            st.mst[MonitorFloat.TLAT] = per
            st.mist[MonitorInt.LATSRC] = LAT_COARSE
            l11, l12, l22 = lattice_init(per, float(self.params.refine_window))
            st.mst[MonitorFloat.L11], st.mst[MonitorFloat.L12], st.mst[MonitorFloat.L22] = l11, l12, l22
            st.mist[MonitorInt.MISSES] = 0
            st.mist[MonitorInt.NCONS] = 0
            st.mist[MonitorInt.FITAT] = -1
            if int(st.mist[MonitorInt.NRESETS]) == 0:
                st.mist[MonitorInt.LAST_START] = int(math.floor(st.mst[MonitorFloat.NEXT] - per))

    def _packed_params(self, cplx: bool) -> tuple[np.ndarray, np.ndarray]:
        """Packed sweep-period and monitor parameters of the fused loop for real / complex input
        (built once per kind: the parameters are frozen)."""
        packed = self._packed.get(cplx)
        if packed is not None:
            return packed
        p = self.params
        band = 1.0 if cplx else 0.5
        spar = p.sweep.as_array(band)
        mpar = np.zeros(len(MonitorParam))
        mpar[MonitorParam.CHIRP_CORR] = 1.0 if (p.chirp_correction and not cplx) else 0.0
        mpar[MonitorParam.MIN_ABS] = p.min_abs_ratio
        mpar[MonitorParam.DOMAIN] = p.domain_margin
        mpar[MonitorParam.POW_LAMBDA] = 1.0 / p.power_time_constant
        mpar[MonitorParam.RESET] = 1.0 if p.reset_at_sweep_start else 0.0
        mpar[MonitorParam.PHASE_GAIN] = p.phase_gain
        mpar[MonitorParam.WRAP] = 1.0 if cplx else 0.0
        mpar[MonitorParam.MAX_DF] = MAX_ABS_RATE
        mpar[MonitorParam.REFINE_W] = float(p.refine_window)
        mpar[MonitorParam.LAT_DRIFT] = p.lattice_period_drift
        mpar[MonitorParam.NOISE_COMP] = 1.0 if (p.noise_compensation and not cplx) else 0.0
        mpar[MonitorParam.RESET_CROSS] = 1.0 if p.reset_cross_covariance else 0.0
        mpar[MonitorParam.CONFIRM] = float(p.confirm_fits)
        self._packed[cplx] = (spar, mpar)
        return spar, mpar

    def _run_tracker(self, xc: np.ndarray, cplx: bool, first: int, store: bool) -> BlockTraces | None:
        st = self._state
        spar, mpar = self._packed_params(cplx)
        out = new_trace_buffers(xc.size) if store else None
        xr = np.ascontiguousarray(xc.real, dtype=np.float64)
        xi = np.ascontiguousarray(xc.imag, dtype=np.float64) if cplx else xr
        st.mst[MonitorFloat.FLOOR] = self._floor if math.isfinite(self._floor) else 0.0
        k = track_block(xr, xi, cplx, first, self._tpar, spar, mpar, st, out)
        if out is None:
            return None
        return BlockTraces(out.idx[:k], out.z[:k], out.f[:k], out.df[:k], out.p11[:k], out.zar[:k], out.reset[:k])


    def _forget_calibration(self) -> None:
        """Learn the noise floor (unless fixed) and shape again from the next blocks."""
        self._cal_psd, self._cal_pow, self._template = [], [], None
        self._floor = self.params.noise_floor_power if self.params.noise_floor_power > 0 else math.nan
        self._off_floor_run = 0

    def _identify(self, block: Block, traces: BlockTraces | None) -> JammerEstimate:
        """Block features, identification (classifier) and the estimates from the tracker's state."""
        xs, cplx, fs, fif, stamp_ns, first = (block.samples, block.cplx, block.fs, block.fif, block.stamp_ns,
                                              block.first)
        p = self.params
        cp = p.classifier
        st = self._state
        nan = math.nan
        # while calibrating the template is None (flat), as block_features needs it then
        psd, frames = welch_psd(xs, cp.nfft, cp.max_frames)        # block_features, the spectrum kept for display
        self.last_spectrum = BlockSpectrum(stamp_ns, psd, fs, fif, cplx)
        feat = features_from_psd(psd, frames, self._template, cp, cplx)
        if not math.isfinite(feat.power):
            return self._counts.rejected(POWER_OVERFLOW, block, traces)
        if not feat.power >= MIN_BLOCK_POWER:
            return self._counts.rejected(BLANK_BLOCK, block, traces)
        if self.calibrated:
            off = off_floor(feat.power, self._floor)
            if off is not None:
                self._off_floor_run += 1
                if self._off_floor_run >= p.calibration_blocks and not p.noise_floor_power > 0:
                    self._counts["recalibrations"] += 1
                    self._forget_calibration()
                return self._counts.rejected(off, block, traces)
        self._off_floor_run = 0
        if not self.calibrated:
            self._cal_psd.append(feat.psd / feat.psd.sum())
            self._cal_pow.append(feat.power)
            if len(self._cal_psd) >= p.calibration_blocks:
                med = np.median(np.stack(self._cal_psd), axis=0)
                self._template = smooth_template(med, cp.template_smooth_bins)
                if not math.isfinite(self._floor):
                    # floor = median over blocks of (power - narrowband excess above the shape)
                    resid = []
                    for psd in self._cal_psd:
                        white = psd / self._template
                        s = float(np.median(white))
                        exc = np.sum(np.maximum(white - s * (1 + cp.min_excess), 0.0) * self._template)
                        resid.append(max(1.0 - exc, 0.0))
                    self._floor = float(np.median(np.array(self._cal_pow) * np.array(resid)))
                    if not (math.isfinite(self._floor) and self._floor >= MIN_BLOCK_POWER):
                        # the blocks were all narrowband excess (no noise seen): nothing to measure J/N against
                        self._counts["calibrations_discarded"] += 1
                        self._forget_calibration()
            return JammerEstimate(stamp_ns, UNKNOWN, 0.5, nan, nan, nan, nan, nan, nan, nan, nan, fs, first,
                                  xs.size, True, self._counts.snapshot(), traces)
        jn_pow = 10 * math.log10(feat.power / self._floor - 1.0) if feat.power > self._floor else -math.inf
        locked = bool(st.si[SweepInt.LOCKED] == 1)
        df = float(st.fst[FilterFloat.DF])
        # a chirp's swept band |df| T must explain the occupied band (a lock on noise peaks does not)
        band = 1.0 if cplx else 0.5
        per_s = float(st.sf[SweepFloat.PERIOD])
        lattice = float(st.mst[MonitorFloat.NEXT]) >= 0.0 and int(st.mist[MonitorInt.LATSRC]) > 0
        if lattice and float(st.mst[MonitorFloat.TLAT]) > 0:
            per_s = float(st.mst[MonitorFloat.TLAT])
        swept = abs(df) * per_s if per_s > 0 else 0.0
        chirp_ok = (locked or lattice or self._resets_in_block > 0) and swept >= 0.5 * feat.occupancy * band
        an = self._analysis
        hop = max(1, int(round(p.analysis.hop_s * fs)))
        periodic = (p.analysis.enabled and an is not None and an.periodic
                    and an.sample_index >= first + xs.size - 2 * hop)
        if int(st.mist[MonitorInt.TRACK]) == 1:
            # tracking mode: confirm_fits significant sweep-start steps in a row at the lattice's
            # period are the periodicity evidence (the detector may not run then)
            chirp_ok = True
        if periodic and an is not None:
            chirp_ok = True
            if not (locked or lattice):
                per_s = an.period_samples
        locked = locked or lattice or periodic
        jtype, conf = classify(feat, jn_pow, chirp_ok, df, True, cp)
        jn = max(jn_pow, feat.jn_spectral_db)
        if jtype == NONE:
            # at least the block power's resolution (module docstring): a NONE never carries a NaN J/N
            jn = max(jn, 5.0 * math.log10((1.0 if cplx else 2.0) / (feat.frames * cp.nfft)))
        js = jammer_to_signal_db(jtype, jn, fs, cplx, self.params)
        freq = fstd = rate = per = f0 = bw = nan
        if jtype in (CW, CHIRP):
            freq = relative_frequency_hz(float(st.fst[FilterFloat.F]), fs, fif, cplx)
            fstd = math.sqrt(max(float(st.fst[FilterFloat.P11]), 0.0)) * fs
            sgn = -1.0 if (not cplx and fif < 0) else 1.0
            if jtype == CW:
                # the three-sample measurement is biased towards fs/4 at low J/N (arccos of a
                # noisy ratio, clipped tails), so a CW's frequency comes from the interpolated
                # Welch peak; its 1-sigma is taken as one bin / sqrt(12)
                freq = relative_frequency_hz(feat.peak_frequency, fs, fif, cplx)
                fstd = fs / cp.nfft / math.sqrt(12.0)
                rate = 0.0
            else:
                f_dig = float(st.fst[FilterFloat.F])
                lo_dig = -0.5 if cplx else 0.0
                if not (lo_dig <= f_dig <= 0.5 and math.isfinite(fstd) and fstd < 0.25 * fs
                        and abs(df) < 0.5):
                    # a run-away track (outside the sampled band, or a std no measurement supports):
                    # never published as valid; the per-sample tracker starts again (issue 14 item 4)
                    self._counts["tracker_resets_invalid"] += 1
                    self._counts["frequency_not_tracked"] += 1
                    self._reset_tracker()
                    return JammerEstimate(stamp_ns, int(jtype), float(conf), float(jn), float(js), nan, nan, nan,
                                          nan, nan, nan, fs, first, xs.size, True, self._counts.snapshot(), traces)
                rate = sgn * df * fs * fs
                if locked:
                    per = per_s / fs
                    bw = abs(rate) * per
                    if math.isfinite(st.mst[MonitorFloat.F0]):
                        f0 = relative_frequency_hz(float(st.mst[MonitorFloat.F0]), fs, fif, cplx)
        if not math.isfinite(jn):
            jn = nan
        return JammerEstimate(stamp_ns, int(jtype), float(conf), float(jn), float(js), freq, fstd, rate, per,
                              f0,
                              bw, fs, first, xs.size, True, self._counts.snapshot(), traces)


    @property
    def state_summary(self) -> dict[str, float]:
        """Current tracker state: frequency (cycles/sample), rate, P, period (samples), last start."""
        st = self._state
        lattice = float(st.mst[MonitorFloat.NEXT]) >= 0.0 and int(st.mist[MonitorInt.LATSRC]) > 0
        per = float(st.mst[MonitorFloat.TLAT]) if lattice else float(st.sf[SweepFloat.PERIOD])
        locked = lattice or int(st.si[SweepInt.LOCKED]) == 1
        return {"f": float(st.fst[FilterFloat.F]), "df": float(st.fst[FilterFloat.DF]),
                "p11": float(st.fst[FilterFloat.P11]),
                "p22": float(st.fst[FilterFloat.P22]), "period_samples": per if locked else math.nan,
                "locked": float(locked), "lpd_locked": float(st.si[SweepInt.LOCKED]),
                "lpd_period_samples": float(st.sf[SweepFloat.PERIOD]),
                "lattice_source": float(st.mist[MonitorInt.LATSRC]),
                "last_start": float(st.mist[MonitorInt.LAST_START]),
                "tracking_mode": float(st.mist[MonitorInt.TRACK])}
