"""Short-time FFT ridge analysis of one IF block (ours): in-block noise level, swept-jammer detection,
sweep period, shape, swept band and rate, for real jammers at common SDR rates. This module is the orchestrator
(``analyse``, ``RidgeParams``, ``RidgeResult``); each stage has its own module.

Why: Kang et al.'s per-sample tracker (tracker.py) follows a saw-tooth whose rate per sample squared is
small (1e12 Hz/s at 38.192 MS/s: 7e-4 cycles/sample^2). Real jammers seen by 4-20 MS/s front ends sweep
10-50x faster per sample, in triangles, hooked saw-tooths, with non-constant rates and beyond the sampled
band (the jammer is then in band only part of each period). The short-time spectrum sees all of these the
same way: in every frame a swept tone is one ridge a few bins wide, wherever it is and however it moves.
Everything is vectorised numpy or compiled (numba) over the frames of one block (no per-sample loop in Python).

Stages (``analyse``), each described in its module's docstring:

1. Frame length (``rfi_monitor.frame_length``): the frame length L whose frame peak excess over noise is the
   largest, tried on a slice of the block.
2. Short-time spectrum and in-block noise level per bin (``rfi_monitor.stft``): Hann frames of L at hop L/2, the
   noise level from the frames below a cut, median-smoothed across bins; the block's noise power N by Parseval.
3. Ridge per frame (``rfi_monitor.ridge_extraction``): the strongest bin, interpolated, present above
   ``ln(B) + presence_nats``; and the spectral phasor of each frame.
4. Period (``rfi_monitor.ridge_periodicity``): the autocorrelation of the spectral phasor over frames.
5. Sweep profile and shape (``rfi_monitor.sweep_shape``): the ridge folded on the period, in-band bins, the shape
   rule (saw-tooth up or down, triangle, hooked), swept band and rate; a saw-tooth's hook is tested again at the
   resolution of a sample (``rfi_monitor.fine_hook``); a periodic ridge whose profile shows no shape gets its label
   from the spectrum folded on the period (``rfi_monitor.folded_spectrum``).
6. Current frequency: at the block's last sample, from a saw-tooth's sweep law (``rfi_monitor.sweep_law``), else
   from the folded profile at the last sample's phase, else the ridge of the last frame moved on by the rate; NaN
   when the jammer is out of the band at the block end. Its 1-sigma: the law's error at the block end (its lack of
   fit and its standard error there), else the RMS deviation of the present frames' ridge from the profile
   (periodic) or from the local straight line through three consecutive frames, at least one bin / sqrt(12). The
   law is fitted, and the profile read, with each profile bin at the mean phase of its frames, not at its centre
   (``rfi_monitor.sweep_law``'s module docstring: a period of a whole number of frames puts every frame of a bin
   at its start).

A frequency track that is coherent but not periodic inside the block (a single slow sweep, a period
longer than ``max_period_s``) is reported as ``sweeping`` without a period: present in at least
``min_present_fraction`` of the frames, consecutive ridges within 2 bins in most of them, and a span of
at least 4 bins (``joined_span``).

A sweep too weak for the per-frame ridge whose period is known from elsewhere (the evidence over blocks,
``rfi_monitor.integration``) gets its shape from ``folded_shape`` (``rfi_monitor.folded_spectrum``).

Frequencies are digital, cycles/sample: complex input signed in [-0.5, 0.5) (fftshift order), real input
in [0, 0.5]. Powers in sample units^2. The names the monitor and the tools use are re-exported here
(``stft_power``, ``noise_levels``, ``choose_frame_length``, ``folded_shape``, ``fine_profile``, the ``SHAPE_*`` codes,
...), so that ``ridge.<name>`` keeps working.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from rfi_monitor.fine_hook import (
    FINE_MIN_RETURN,
    FineProfile,
    analytic_signal,
    fine_hook_shape,
    fine_profile,
    fine_return,
    noise_lag_product,
)
from rfi_monitor.folded_spectrum import _fold_shape, folded_shape
from rfi_monitor.frame_length import MIN_SELECT_EXCESS, SELECT_Z, choose_frame_length, null_peak_excess
from rfi_monitor.ridge_extraction import FrameRidges, frame_ridges, joined_span
from rfi_monitor.ridge_periodicity import _periodicity
from rfi_monitor.stft import _noise_power, estimator_gain, noise_levels, stft_power
from rfi_monitor.sweep_law import bin_mean_phase, law_at_block_end, profile_abscissa_bias
from rfi_monitor.sweep_shape import (
    HOOKED_SAWTOOTH,
    MIN_RETURN_BINS,
    SAW_P,
    SAWTOOTH_DOWN,
    SAWTOOTH_UP,
    SHAPE_NAMES,
    SHAPE_UNKNOWN,
    TRIANGLE,
    _fold_residuals,
    _return_bins,
    _shape,
    phase_profiles,
)
from rfi_node_common.params import parameter

__all__ = [
    "FINE_MIN_RETURN", "HOOKED_SAWTOOTH", "MIN_SELECT_EXCESS", "SAWTOOTH_DOWN", "SAWTOOTH_UP", "SELECT_Z",
    "SHAPE_NAMES", "SHAPE_UNKNOWN", "TRIANGLE", "FineProfile", "RidgeParams", "RidgeResult", "analyse",
    "analytic_signal", "choose_frame_length", "estimator_gain", "fine_profile", "fine_return", "folded_shape",
    "frequency_at_period", "joined_span", "noise_lag_product", "noise_levels", "null_peak_excess", "stft_power",
]


@dataclass(frozen=True)
class RidgeParams:
    """Parameters of the short-time FFT ridge analysis (module docstring).

    Attributes:
        min_frame_length, max_frame_length: the candidate frame lengths are the powers of two between
            them, samples (>= 8).
        select_samples: samples of the block used to choose the frame length (0: the whole block).
        max_period_s: longest sweep period searched, s (also limited to a quarter of the block).
        min_period_frames: shortest period, frames (hops of L/2), >= 3.
        detect_sigma: significance of the periodicity peak, noise standard deviations.
        min_strength: smallest normalised autocorrelation peak-to-trough of a periodic sweep, (0, 1].
        presence_nats: per-frame ridge threshold above ln(B), nats of the exponential (4.6: 1 % false).
        noise_smooth_bins: width of the median across bins of the noise level (odd, >= 3).
        phase_bins: bins of the folded sweep profile, >= 8.
        hook_rate_ratio: a saw-tooth whose two steps after the flyback both exceed this times its median
            step is hooked (an overshoot relaxing back fast; the other hook test, a swept return, has no
            parameter), > 1.
        min_present_fraction: a non-periodic ridge must be present in at least this share of the frames.
        tracking_samples: while a chirp is tracked (the last block was CHIRP), only the last this many
            samples of a block are analysed (speed; the J/N and the CW test still use the whole block; a
            block whose tail shows no sweep is analysed whole); 0: always the whole block.
        acquisition_samples: while nothing is tracked (the last block was neither CW nor CHIRP), only the last
            this many samples of a block are analysed first: a block whose part shows anything (a type other than
            NONE, a sweep, a period) is analysed whole, so only quiet blocks are analysed in part (speed: a 1 ms
            block at the paper's 38.192 MS/s is analysed as a 16.4 MS/s front end's block would be; the J/N, the CW
            test and the evidence over blocks use the whole block; blocks of at most this many samples are
            always analysed whole); 0: always the whole block.
    """

    min_frame_length: int = parameter(
        8,
        'Shortest short-time FFT frame tried by the stft estimator, samples (power of two): the frame lengths tried '
        'are the powers of two from ridge_min_frame_length to ridge_max_frame_length; the one where the ridge stands '
        'highest above the noise is used (a sweep of k cycles/sample^2 is sharpest near 1/sqrt(k) samples), chosen '
        'on the first block, every 16 blocks while no jammer is tracked, every 64 blocks while one is, and at once '
        'when a block shows a chirp or a wideband rise at a length chosen while nothing was tracked.',
        minimum=8, maximum=2**16)
    max_frame_length: int = parameter(
        128, 'Longest short-time FFT frame tried by the stft estimator, samples (power of two).',
        minimum=8, maximum=2**16)
    select_samples: int = parameter(
        8192, 'Samples of a block used to choose the frame length (stft); 0: the whole block.',
        minimum=0, maximum=2**31 - 1)
    max_period_s: float = parameter(
        250e-6, 'stft: longest sweep period searched, s (also at most a quarter of the analysed samples).',
        minimum=1e-7, maximum=10.0)
    min_period_frames: int = parameter(
        4, 'Shortest sweep period searched (stft), frames of half the frame length.',
        minimum=3, maximum=10**6)
    detect_sigma: float = parameter(
        7.0, 'stft: significance of a sweep period, standard deviations of the noise autocorrelation.',
        minimum=1.0, maximum=100.0)
    min_strength: float = parameter(
        0.08, 'stft: smallest normalised autocorrelation peak-to-trough of a periodic sweep, (0, 1].',
        minimum=1e-6, maximum=1.0)
    presence_nats: float = parameter(
        4.6,
        "stft: a frame's ridge is present when its excess over the noise exceeds ln(bins) + this (nats of the "
        'exponential; 4.6: 1 % of noise frames).', minimum=0.1, maximum=100.0)
    noise_smooth_bins: int = parameter(
        5, 'Width of the median across bins of the in-block noise level (stft), odd.',
        minimum=3, maximum=10**4)
    phase_bins: int = parameter(
        32, 'stft: bins of the folded sweep profile (shape, swept band, rate).', minimum=8, maximum=4096)
    hook_rate_ratio: float = parameter(
        2.0,
        'stft: a saw-tooth whose two steps after its flyback both exceed this times its median step is hooked (so is '
        'one whose way back is swept over at least two profile bins).', minimum=1.0001, maximum=1e3)
    min_present_fraction: float = parameter(
        0.5,
        'A non-periodic ridge must be present in at least this share of the frames (stft), (0, 1].',
        minimum=1e-6, maximum=1.0)
    tracking_samples: int = parameter(
        16384,
        'stft: while a chirp is tracked only the last this many samples of a block are analysed (speed: 16384 samples'
        ' are 0.43 ms at 38.192 MS/s, 1.6 ms at 10 MS/s; the J/N and the CW test use the whole block; a block whose '
        'tail shows no sweep is analysed whole). 0: always the whole block.', minimum=0, maximum=2**31 - 1)
    acquisition_samples: int = parameter(
        16384,
        'stft: while nothing is tracked only the last this many samples of a block are analysed first, and the whole '
        "block when that part shows anything (a type other than NONE, a sweep, a period): quiet blocks at the paper's"
        " 38.192 MS/s are analysed as a 16.4 MS/s front end's 1 ms block is (speed; the J/N, the CW test and the "
        'evidence over blocks use the whole block). 0: always the whole block.', minimum=0, maximum=2**31 - 1)

    @property
    def frame_lengths(self) -> tuple[int, ...]:
        """The candidate frame lengths, increasing."""
        out, L = [], int(self.min_frame_length)
        while L <= int(self.max_frame_length):
            out.append(L)
            L *= 2
        return tuple(out)

    def __post_init__(self) -> None:
        a, b = int(self.min_frame_length), int(self.max_frame_length)
        if a < 8 or b < a or a & (a - 1) or b & (b - 1):
            raise ValueError("min_frame_length <= max_frame_length must be powers of two >= 8")
        for name in ("max_period_s", "detect_sigma", "min_strength", "presence_nats", "hook_rate_ratio",
                     "min_present_fraction"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0):
                raise ValueError(f"{name} must be finite and > 0")
        if self.min_strength > 1 or self.min_present_fraction > 1:
            raise ValueError("min_strength and min_present_fraction must be <= 1")
        if int(self.tracking_samples) < 0 or 0 < int(self.tracking_samples) < 1024:
            raise ValueError("tracking_samples must be 0 or >= 1024")
        if int(self.acquisition_samples) < 0 or 0 < int(self.acquisition_samples) < 1024:
            raise ValueError("acquisition_samples must be 0 or >= 1024")
        if int(self.min_period_frames) < 3 or int(self.phase_bins) < 8 or int(self.select_samples) < 0:
            raise ValueError("min_period_frames >= 3, phase_bins >= 8, select_samples >= 0")
        if int(self.noise_smooth_bins) < 3 or int(self.noise_smooth_bins) % 2 == 0:
            raise ValueError("noise_smooth_bins must be odd and >= 3")


@dataclass(frozen=True)
class RidgeResult:
    """What the ridge analysis found in one block (NaN where unknown; frequencies in cycles/sample).

    Attributes:
        frame_length, hop: samples.
        noise_power: in-block noise power per sample (sample units^2).
        peak_excess: mean frame peak excess over noise, minus the noise-only expectation (>= ~0 for noise).
        present_fraction: share of frames with a ridge above the presence threshold.
        periodic: a sweep period was found; period_samples, strength: it and its autocorrelation peak.
        sweeping: a swept jammer (periodic, or a coherent moving ridge) with a span of >= 4 bins.
        shape: SHAPE_* code; in_band_fraction: share of the period with the jammer in band.
        low, high: swept band limits seen in band; start: frequency at the sweep start (shape-dependent).
        rate: sweep rate of the main direction, cycles/sample^2 (signed; triangle: of the up part).
        frequency: ridge at the block end (NaN when absent); frequency_std: its 1-sigma.
        hook_checked: the sample-resolution hook test (``fine_profile``) ran on this block (a saw-tooth analysed with
            ``fine_hook``); False when it did not, so that a saw-tooth's shape says nothing about a hook the coarse
            profile cannot resolve.
    """

    frame_length: int
    hop: int
    noise_power: float
    peak_excess: float
    present_fraction: float
    periodic: bool
    period_samples: float
    strength: float
    sweeping: bool
    shape: int
    in_band_fraction: float
    low: float
    high: float
    start: float
    rate: float
    frequency: float
    frequency_std: float
    hook_checked: bool = False



@dataclass
class _Sweep:
    """What ``analyse`` found of the sweep (RidgeResult's fields in the making; NaN where unknown)."""

    shape: int = SHAPE_UNKNOWN
    in_band_fraction: float = math.nan
    low: float = math.nan
    high: float = math.nan
    start: float = math.nan
    rate: float = math.nan
    frequency_std: float = math.nan
    sweeping: bool = False
    shape_fold: int = SHAPE_UNKNOWN
    """the label of the spectrum folded on the period (``folded_spectrum``), used when the profile shows none"""
    hook_checked: bool = False
    prof: np.ndarray | None = None
    """the fine folded profile (periodic), its in-band bins and standard errors: the block-end frequency is read from
    them"""
    inband: np.ndarray | None = None
    se: np.ndarray | None = None
    phase_mean: np.ndarray | None = None
    """the mean phase of the frames in each bin of prof (``sweep_law.bin_mean_phase``): where the law is fitted and the
    profile read"""
    used: np.ndarray | None = None
    """the frames whose ridge entered prof (bool, shape (frames,))"""


def analyse(x: np.ndarray, cplx: bool, fs: float, par: RidgeParams, frame_length: int = 0,
            fine_hook: bool = True) -> RidgeResult:
    """Ridge analysis of one block (module docstring).

    Args:
        x: finite samples, shape (n,), float64 (real) or complex128, n >= 8 * min(frame_lengths).
        cplx: complex samples.
        fs: sample rate, Hz (> 0; converts max_period_s to frames).
        par: RidgeParams.
        frame_length: 0: choose it (step 1); else use this one.
        fine_hook: run the sample-resolution hook test (``fine_profile``, 0.3-1.4 ms per block) on a saw-tooth; the
            monitor skips it on the blocks of a tracked saw-tooth whose hook it tested recently (``hook_checked``).

    Returns:
        RidgeResult.
    """
    L = int(frame_length) if frame_length else choose_frame_length(x, cplx, par)
    hop = L // 2
    S, freqs = stft_power(x, L, cplx)
    lvl = noise_levels(S, par.noise_smooth_bins, cplx)
    noise = _noise_power(lvl, L, cplx, par.noise_smooth_bins)
    nfr = S.shape[0]
    # the ridge's strongest bins and the sums of the spectral phasor (its periodicity below) in one pass
    rd = frame_ridges(S, freqs, lvl, cplx, par.presence_nats)
    lmax = int(min(par.max_period_s * fs / hop, nfr // 4))
    per_fr, strength = _periodicity(rd.phasor, int(par.min_period_frames), lmax,
                                    par.min_strength, par.detect_sigma)
    periodic = math.isfinite(per_fr)
    if periodic:
        sw = _periodic_sweep(x, cplx, S, freqs, lvl, noise, rd, per_fr, L, par, fine_hook)
    elif rd.present_fraction >= par.min_present_fraction and nfr >= 8:
        sw = _track_sweep(rd, L)
    else:
        sw = _Sweep()
    freq, fstd = _block_end_frequency(x.size, sw, rd, periodic, per_fr, L, freqs, cplx)
    shape = sw.shape_fold if sw.shape == SHAPE_UNKNOWN else sw.shape
    return RidgeResult(L, hop, noise, rd.peak_excess, rd.present_fraction, periodic,
                       float(per_fr * hop) if periodic else math.nan, float(strength), sw.sweeping, int(shape),
                       sw.in_band_fraction, sw.low, sw.high, sw.start, sw.rate, freq, fstd, sw.hook_checked)


def frequency_at_period(x: np.ndarray, cplx: bool, fs: float, par: RidgeParams, period_samples: float,
                        rr: RidgeResult, tolerance: float) -> tuple[float, float, bool]:
    """A sweep whose period is known from elsewhere (the evidence over blocks, ``rfi_monitor.integration``) while this
    block's analysis rr did not call it a sweep (a swept band under 4 bins of the frame, or a frame too long for the
    period): (frequency at the block's last sample, its 1-sigma, cycles/sample; whether the block was analysed again).

    The frequency is stage 6's (``_block_end_frequency``: the sweep law, else the folded profile, else the last
    ridge) of an analysis that resolves the period: rr itself when its frame's hop fits ``min_period_frames`` times in
    the period, else the block analysed again at the longest frame that does (a frame longer than the period sees the
    sweep's comb lines, not its ridge). It is published only when that analysis found the period itself, within
    ``tolerance`` (relative; a multiple, a sub-multiple or no period: (NaN, NaN)): what the block's own frames show,
    with stage 6's 1-sigma, not a value read on a period the block does not show. NaN also when the jammer is out of
    band at the block end, when no allowed frame length resolves the period, or when rr's ridge is present in fewer
    than ``min_present_fraction`` of its frames (a jammer too weak for the block's frames: not analysed again)."""
    nan = math.nan
    if not (math.isfinite(period_samples) and period_samples > 0):
        return nan, nan, False
    fit = [L for L in par.frame_lengths if par.min_period_frames * (L // 2) <= period_samples]
    if not fit:
        return nan, nan, False
    if rr.present_fraction < par.min_present_fraction:
        return nan, nan, False           # the block's frames hardly show the jammer: nothing to read (and no second
                                         # analysis on every block of a jammer found only over blocks)
    again = rr.frame_length not in fit
    if again:
        rr = analyse(x, cplx, fs, par, fit[-1], fine_hook=False)
    if not (rr.periodic and abs(rr.period_samples - period_samples) <= tolerance * period_samples):
        return nan, nan, again
    return rr.frequency, rr.frequency_std, again


def _periodic_sweep(x: np.ndarray, cplx: bool, S: np.ndarray, freqs: np.ndarray, lvl: np.ndarray, noise: float,
                    rd: FrameRidges, per_fr: float, L: int, par: RidgeParams, fine_hook: bool) -> _Sweep:
    """Stage 5 of a periodic ridge (period per_fr frames): the folded profiles, the shape (hooks tested on the finer
    profile and at the resolution of a sample), the swept band and rate, and the ridge's scatter about the profile."""
    hop = L // 2
    binw = 1.0 / L
    f, present = rd.frequency, rd.present
    B = S.shape[1]
    # complex input: the spectrum is circular, a ridge in the first or last bin (-0.5 and 0.5 - 1/L cycles/
    # sample, not interpolated) is a tone near the +-0.5 edge on either side; such frames count as present
    # but their frequency does not enter the medians (a sweep through an edge would otherwise mix -0.5 and
    # +0.5 in one phase bin's median)
    fuse = present & (rd.bin > 0) & (rd.bin < B - 1) if cplx else present
    pp = phase_profiles(f, present, fuse, per_fr, int(par.phase_bins), binw)
    sw = _Sweep(in_band_fraction=pp.in_band_fraction, prof=pp.prof, inband=pp.inband, se=pp.se,
                phase_mean=bin_mean_phase(fuse, per_fr, pp.prof.size), used=fuse)
    shape, low, high, start, step, p_dir = _shape(pp.prof_s, pp.inband_s, par.hook_rate_ratio, pp.se_s)
    if shape in (SAWTOOTH_UP, SAWTOOTH_DOWN) and pp.prof.size > pp.shape_bins and \
            _return_bins(pp.prof, pp.inband, shape == SAWTOOTH_UP)[0] >= MIN_RETURN_BINS:
        shape = HOOKED_SAWTOOTH          # a return too short for the coarse profile, seen in the finer one
    if shape in (SAWTOOTH_UP, SAWTOOTH_DOWN) and fine_hook:
        # a return shorter than two profile bins and a frame: the sample-resolution profile of lag products
        # (fine_profile) sees it, or sees the flyback instantaneous
        sw.hook_checked = True
        shape = fine_hook_shape(x, cplx, per_fr * hop, lvl, freqs, noise, shape)
    if shape == SHAPE_UNKNOWN:
        # the per-frame ridge's profile shows no shape (a weak sweep, or one seen in pieces): the spectrum
        # itself folded on the period (folded_shape's synchronous average, O(frames x bins)) may; only the
        # label is taken from it (no sweep law is fitted to a profile that showed no shape)
        sw.shape_fold = _fold_shape(S, freqs, per_fr, L, cplx, par.hook_rate_ratio)[0]
    if math.isfinite(step):
        sw.rate = step / (per_fr * hop / pp.shape_bins)
    # a sweep: the ridge moves over >= 4 bins, or over >= 2 with a direction no chance gives (a saw-tooth
    # narrower than 4 bins of a short frame, e.g. 2.5 MHz at 12 MS/s with 16-sample frames)
    span_bins = (high - low) / binw if math.isfinite(high - low) else 0.0
    sw.sweeping = bool(span_bins >= 4 or (span_bins >= 2 and p_dir <= SAW_P))
    if present.any():
        rms_fold, nsel, q_lo, q_hi = _fold_residuals(f, present, pp.inband, pp.prof, float(per_fr), 0.02, 0.98)
        if math.isfinite(rms_fold):
            sw.frequency_std = rms_fold
        if nsel >= 20 and math.isfinite(low):
            # the profile averages over a phase bin and the frame: the swept band's edges come from the
            # ridge itself (2 % and 98 % points of the in-band ridge frequencies)
            low, high = q_lo, q_hi
            if shape in (SAWTOOTH_UP, TRIANGLE):
                start = low
            elif shape == SAWTOOTH_DOWN:
                start = high
    sw.shape, sw.low, sw.high, sw.start = shape, low, high, start
    return sw


def _track_sweep(rd: FrameRidges, L: int) -> _Sweep:
    """A ridge present in most frames without a period: a sweep when its track is coherent (consecutive ridges within
    2 bins in at least 80 % of the pairs) and spans at least 4 bins (``joined_span``); its band, mean rate (a straight
    line through the present frames) and direction (module docstring)."""
    hop = L // 2
    binw = 1.0 / L
    f, present = rd.frequency, rd.present
    sw = _Sweep()
    fp = f[present]
    dd = np.abs(np.diff(f))[present[1:] & present[:-1]]
    coherent = dd.size > 0 and float(np.mean(dd <= 2 * binw)) >= 0.8
    span = joined_span(f, present, 2 * binw)
    if coherent and span >= 4 * binw:
        sw.sweeping = True
        sw.low, sw.high = float(np.percentile(fp, 5)), float(np.percentile(fp, 95))
        tt = np.flatnonzero(present)
        slope = float(np.polyfit(tt, fp, 1)[0]) if tt.size >= 3 else math.nan
        sw.rate = slope / hop
        sw.shape = SAWTOOTH_UP if slope > 0 else SAWTOOTH_DOWN
        sw.start = sw.low if slope > 0 else sw.high
        sw.in_band_fraction = 1.0
    return sw


def _block_end_frequency(n: int, sw: _Sweep, rd: FrameRidges, periodic: bool, per_fr: float, L: int,
                         freqs: np.ndarray, cplx: bool) -> tuple[float, float]:
    """Stage 6 (module docstring): (frequency at the block's last sample, its 1-sigma), cycles/sample; a saw-tooth's
    law also sets sw's band, start and rate. n: the block's samples."""
    hop = L // 2
    binw = 1.0 / L
    f, present = rd.frequency, rd.present
    nfr = f.size
    fstd = sw.frequency_std
    if not math.isfinite(fstd) and nfr >= 3:
        # local straight line through three consecutive present frames
        ok = present[:-2] & present[1:-1] & present[2:]
        r2 = (f[1:-1] - 0.5 * (f[:-2] + f[2:]))[ok]
        if r2.size:
            fstd = float(np.sqrt(np.mean(r2 * r2) / 1.5))
    fstd = max(fstd, binw / math.sqrt(12.0)) if math.isfinite(fstd) else binw / math.sqrt(12.0)
    # frequency at the block's last sample: frame t's ridge is the frequency near its centre,
    # t hop + L / 2 - 1/2; a periodic sweep is read off its folded profile at the last sample's phase
    # (the last frame's centre is up to hop + L / 2 samples before the end), else the last ridge
    # moved on by the rate
    t_end = (n - 1 - (L - 1) / 2.0) / hop          # the last sample, in frame units
    freq = math.nan
    law = None
    prof_k, inband_k = sw.prof, sw.inband
    if periodic and prof_k is not None and inband_k is not None and sw.shape in (SAWTOOTH_UP, SAWTOOTH_DOWN,
                                                                                 HOOKED_SAWTOOTH):
        # saw-tooth: the sweep law fitted away from the flyback (where frames straddle it) gives the swept band's
        # ends, the mean rate and the frequency at the block end, corrected for the period's own error (it moves the
        # block end's phase), with its error there (sweep_law.law_at_block_end)
        law = law_at_block_end(prof_k, inband_k, per_fr, L, sw.high - sw.low, sw.phase_mean, f, sw.used, t_end, cplx,
                               sw.se)
    if law is not None:
        sw.low, sw.high, sw.start, sw.rate, freq, fstd = law
    elif periodic and prof_k is not None and inband_k is not None and sw.se is not None:
        # read from one or two profile bins; the 1-sigma stays the frames' scatter around the profile (the sweep at
        # the block end deviates from a bin's median as its frames do; the bins' standard errors alone, tried for
        # issue 26 item 3, covered 0-65 % of the errors where the sweep is not smooth, and with the ridge's
        # interpolation error added, in its second round, 71 % / 84 % within 1 / 2 sigma, 9-36 % within 1 sigma on
        # the hooked saw-tooth, the 4 MS/s 12 us capture row and the real triangle: docs/rfi_monitor/
        # frequency_std.md); read with the bins at their frames' mean phases (sweep_law.profile_abscissa_bias: the
        # correction to the read at the bins' centres)
        freq = _profile_frequency(prof_k, inband_k, sw.se, t_end / per_fr, sw.high - sw.low)[0]
        if math.isfinite(freq) and sw.phase_mean is not None:
            freq += profile_abscissa_bias(prof_k, inband_k, sw.phase_mean, t_end / per_fr, sw.high - sw.low)
    elif present[-1]:
        freq = float(f[-1]) + (float(sw.rate) * (t_end - (nfr - 1)) * hop if math.isfinite(sw.rate) else 0.0)
    if math.isfinite(freq) and not (float(freqs[0]) - 0.5 / L <= freq <= float(freqs[-1]) + 0.5 / L):
        freq = math.nan
    return freq, fstd


def _profile_frequency(prof: np.ndarray, inband: np.ndarray, se: np.ndarray, periods: float, span: float
                       ) -> tuple[float, float]:
    """The folded profile read at a phase (``periods``: the time in periods; its fraction is the phase), and its
    standard error: linearly between the two nearest bins when both are in band and not across a flyback (a step of
    half the swept span; the bins' medians are independent: ``sqrt((1 - a)^2 se0^2 + a^2 se1^2)``), else the nearer
    bin when in band, else (NaN, NaN)."""
    K = prof.size
    pos = np.mod(periods, 1.0) * K - 0.5
    k0 = int(math.floor(pos)) % K
    k1 = (k0 + 1) % K
    a = pos - math.floor(pos)
    if inband[k0] and inband[k1] and abs(prof[k1] - prof[k0]) < 0.5 * span:
        return (float((1 - a) * prof[k0] + a * prof[k1]),
                math.sqrt(((1 - a) * float(se[k0])) ** 2 + (a * float(se[k1])) ** 2))
    k = k0 if a < 0.5 else k1
    if inband[k]:
        return float(prof[k]), float(se[k])
    return math.nan, math.nan
