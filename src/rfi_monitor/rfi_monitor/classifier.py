"""Block-level jammer identification: NONE / CW / CHIRP / WIDEBAND / UNKNOWN, with a confidence.

Features of one block (vectorised numpy, no per-sample Python):

* ``jn_power_db``: J/N from the block power P against the calibrated noise floor N,
  ``10 log10(P / N - 1)`` (NaN until a floor is known).
* Welch PSD (Hann, ``nfft`` bins, non-overlapping frames) whitened by the front end's noise shape
  ``template`` (learned during calibration, median-smoothed across frequency so that a tone never
  enters it; flat before). The noise scale is the median whitened bin; bins whose excess exceeds
  ``max(sig_sigma / sqrt(frames), min_excess)`` times the scale, and is within ``sidelobe_db``
  of the strongest excess, are "occupied".
  ``jn_spectral_db`` = occupied excess power over noise power: a narrowband J/N that needs no
  absolute calibration and survives an AGC (which hides a jammer from the block power).
* ``occupancy``: occupied bins / all bins. A CW occupies the Hann main lobe (<= 4 bins); a chirp
  its swept band; wideband noise most bins (then the median scale itself rises and only the
  power J/N sees it).
* ``line_fraction``: share of the occupied excess power inside the strongest line's main lobe
  (+-2 bins): ~1 for a CW, also with the harmonic lines a 2-bit quantiser adds; <= 0.44 for chirps
  and band-limited noise.
* The tracker: period lock (Kang et al., Sec. 3.2) and the sweep rate estimate.

Decision (thresholds are parameters of ``ClassifierParams``):

    narrowband = jn_spectral_db >= detect_jn_db
    CW       if narrowband and (occupancy <= cw_max_occupancy or the strongest line holds
             >= CW_MIN_LINE_FRACTION of the occupied excess power: harmonics of a quantised CW)
    CHIRP    if narrowband and occupancy > cw_max_occupancy and the tracker's period is locked
             with a swept band |df| T that covers at least half the occupied band
             (or, before lock, |sweep rate| >= min_chirp_rate = 1.5e11 Hz/s at 38 MS/s; the rate
             estimate of a tracker on band-limited noise stays near 4e10 Hz/s)
    WIDEBAND if jn_power_db >= detect_jn_db and no CW/CHIRP (noise-like power rise, or a
             band-limited noise jammer that occupies bins but shows no sweep)
    NONE     otherwise; UNKNOWN while the floor is still being learned and nothing narrowband is
             seen.

Confidence: a logistic function of the margin (in dB) of the deciding J/N over its threshold,
times a structure term (CW: how far occupancy is below the CW limit; CHIRP: 1 when the period is
locked, 0.6 before). For NONE it is the complement of the detection logistic.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit
from scipy import fft as sp_fft

from rfi_monitor.numpy_kernels import MEDIAN_NEAREST, pairwise_sum, running_median
from rfi_monitor.stft import _frames_complex, fft_inplace, rfft_rows
from rfi_node_common.params import parameter

NONE, CW, CHIRP, WIDEBAND, UNKNOWN = 0, 1, 2, 3, 4
"""Type codes, identical to rfi_msgs/JammerState."""
LINE_HALF_WIDTH_BINS = 2
"""Half width of a line's Hann main lobe, Welch bins (the lobe spans +-2 bins)."""
CW_MIN_LINE_FRACTION = 0.7
"""A narrowband excess whose strongest line (Hann main lobe) holds at least this share of the
occupied excess power is a CW even when its occupancy exceeds ``cw_max_occupancy``. A CW through a
coarse quantiser (2 bits) or another front-end nonlinearity gets harmonic and intermodulation lines
(a hard-limited tone keeps 8 / pi^2 = 81 % of its power in the fundamental; above the significance
floor, measured: >= 98 % of the occupied excess), which occupy more bins than the main lobe; a chirp
spreads its power over its swept band (measured <= 0.44 for 2-10 MHz sweeps, band-limited noise
<= 0.39; benchmarks/rfi_monitor_paper.py confusion set)."""


@dataclass(frozen=True)
class ClassifierParams:
    """Identification thresholds.

    Attributes:
        nfft: Welch frame length, samples (power of two, >= 32).
        max_frames: at most this many frames per block (evenly spaced), >= 8.
        sig_sigma: significance of an occupied bin, in standard deviations of the Welch average.
        min_excess: minimum relative excess of an occupied bin over the noise (guards template
            mismatch between captures), > 0.
        detect_jn_db: J/N threshold of a jammer, dB. Front-end spurs of real captures are around
            -11 to -20 dB; a jammer that matters is J/N > 0 dB.
        cw_max_occupancy: largest occupied fraction of the band of a CW, (0, 1).
        min_chirp_rate: |sweep rate| that marks a chirp before the period locks, cycles/sample^2.
        template_smooth_bins: width of the median filter that smooths the learned noise template.
        sidelobe_db: bins more than this below the strongest excess are not occupied (Hann
            sidelobes of a strong CW are below -31 dB), dB.
        confidence_slope_db: dB margin that maps to a logistic confidence of 0.73.
    """

    nfft: int = parameter(
        256,
        'Welch frame length, samples (a power of two). Sets the spectral resolution fs / nfft (149 kHz at 38.192 MHz)'
        ' and the CW frequency resolution.', minimum=32, maximum=2**20)
    max_frames: int = parameter(
        256, 'At most this many Welch frames per block (evenly spaced; speed).', minimum=8, maximum=10**7)
    sig_sigma: float = parameter(
        6.0, 'Significance of an occupied spectral bin, standard deviations of the Welch average.',
        minimum=1e-6, maximum=1e3)
    min_excess: float = parameter(
        0.5,
        'Smallest relative excess of an occupied bin over the noise, dimensionless (guards a mismatch between the '
        'learned noise shape and the front end).', minimum=1e-6, maximum=1e6)
    detect_jn_db: float = parameter(
        -6.0,
        'J/N above which a jammer is declared, dB. Front-end spurs of real captures are at -11 to -20 dB; raise it if'
        ' spurs are reported as CW.', minimum=-100.0, maximum=100.0)
    cw_max_occupancy: float = parameter(
        0.05, 'Largest occupied fraction of the band of a CW, (0, 1).', minimum=1e-6, maximum=0.999999)
    min_chirp_rate: float = parameter(
        1e-4,
        '|Sweep rate| that marks a chirp before the period locks, cycles/sample^2 (1.5e11 Hz/s at 38.192 MHz is '
        '1e-4).', minimum=1e-12, maximum=1.0)
    template_smooth_bins: int = parameter(
        15, 'Width of the median filter smoothing the learned noise shape, bins.',
        minimum=1, maximum=2**20)
    sidelobe_db: float = parameter(
        30.0,
        'Bins more than this below the strongest excess are not occupied, dB (Hann sidelobes of a strong CW are below'
        ' -31 dB).', minimum=0.0, maximum=300.0)
    confidence_slope_db: float = parameter(
        2.0, 'J/N margin over the threshold that maps to a confidence of 0.73, dB.',
        minimum=1e-6, maximum=100.0)

    def __post_init__(self) -> None:
        if self.nfft < 32 or self.nfft & (self.nfft - 1):
            raise ValueError("nfft must be a power of two >= 32")
        if self.max_frames < 8:
            raise ValueError("max_frames must be >= 8")
        for name in ("sig_sigma", "min_excess", "min_chirp_rate", "confidence_slope_db"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0):
                raise ValueError(f"{name} must be finite and > 0")
        if not math.isfinite(self.detect_jn_db):
            raise ValueError("detect_jn_db must be finite")
        if not 0 < self.cw_max_occupancy < 1:
            raise ValueError("cw_max_occupancy must be in (0, 1)")
        if self.template_smooth_bins < 1:
            raise ValueError("template_smooth_bins must be >= 1")


@dataclass(frozen=True)
class BlockFeatures:
    """Spectral features of one block (see module docstring); powers in sample units^2."""

    power: float
    psd: np.ndarray          # shape (bins,), Welch PSD normalised so that sum == power
    frames: int
    noise_scale: float       # median whitened bin (noise power per bin / template)
    jn_spectral_db: float
    occupancy: float
    peak_bin: int
    peak_frequency: float    # parabolic-interpolated Welch peak, cycles/sample (complex: signed)
    line_fraction: float = 0.0   # share of the occupied excess power in the strongest line's main lobe


def welch_psd(x: np.ndarray, nfft: int, max_frames: int) -> tuple[np.ndarray, int]:
    """Welch PSD of a block: Hann window, non-overlapping frames, at most max_frames frames.

    Args:
        x: samples, shape (n,), float or complex, n >= nfft.
        nfft: frame length.
        max_frames: frame cap (evenly spaced frames).

    Returns:
        (psd, frames): psd shape (nfft,) complex input (fftshift order: -fs/2..fs/2) or
        (nfft // 2 + 1,) real input, normalised so that psd.sum() equals the mean power.
    """
    nfr = x.size // nfft
    if nfr < 1:
        raise ValueError("block shorter than one frame")
    fr = x[: nfr * nfft].reshape(nfr, nfft)
    if nfr > max_frames:
        fr = fr[np.linspace(0, nfr - 1, max_frames).astype(np.int64)]
    cplx = np.iscomplexobj(x)
    if fr.shape[0] == nfr and x.dtype == (np.complex128 if cplx else np.float64):
        # all frames (the monitor's case): the window, |X|^2 summed over the frames, the power and the normalisation
        # in compiled loops (speed), the same arithmetic in the same order as the numpy expressions below
        xc = np.ascontiguousarray(x)
        if cplx:
            xv = xc.view(np.float64)
            fwc = np.empty((nfr, nfft), dtype=np.complex64)
            _frames_complex(xv, nfft, _hann32(nfft), fwc)
            return _complex_psd(fft_inplace(fwc, True), xv), nfr
        fw32 = np.empty((nfr, nfft), dtype=np.float32)
        _window_frames(xc, _hann32(nfft), fw32)
        return _real_psd(rfft_rows(fw32), xc), nfr
    # single precision FFT (scipy's pocketfft; numpy's float32 path is slower than its float64 one):
    # the PSD needs ~1e-3 relative accuracy (it is smoothed and thresholded in dB), float32 gives
    # 1e-7; 53 us instead of 74 us for 149 frames of 256 on the development machine
    w = _hann32(nfft)
    fw = fr.astype(np.complex64 if cplx else np.float32)
    fw *= w
    spec = sp_fft.fft(fw, axis=1, overwrite_x=True) if cplx else sp_fft.rfft(fw, axis=1, overwrite_x=True)
    # |X|^2 summed over frames without temporaries (speed): (re, im) pairs of the float view
    v = np.ascontiguousarray(spec).view(np.float32)
    p2 = np.einsum("ij,ij->j", v, v).astype(np.float64)   # float32 sums of <= max_frames terms: ~1e-5
    p = (p2[0::2] + p2[1::2]) / fr.shape[0]
    fv = np.ascontiguousarray(fr)
    fv = (fv.view(np.float64) if cplx else fv).ravel()
    pw = float(np.add.reduce(fv * fv)) / fr.size      # not np.dot: no multi-threaded BLAS
    if cplx:
        p = np.fft.fftshift(p)
    return _normalised(p, pw), int(fr.shape[0])


def _normalised(p: np.ndarray, power: float) -> np.ndarray:
    """``p`` scaled so that it sums to ``power``; all zero when ``p`` holds no power (a blank block, or one
    whose only non-zero samples fall on the window's zeros), which the monitor rejects (``blank_block``)."""
    total = float(p.sum())
    if not total > 0.0:
        return np.zeros_like(p)
    return p * (power / total)


@njit(cache=True)
def _window_frames(x: np.ndarray, w32: np.ndarray, out: np.ndarray) -> None:
    """out[i, j] = float32(x[i nfft + j]) * w32[j] (the float32 conversion and the Hann window of
    ``welch_psd`` in one pass; same float32 arithmetic as astype + multiply)."""
    nfr, nfft = out.shape
    for i in range(nfr):
        o = i * nfft
        for j in range(nfft):
            out[i, j] = np.float32(x[o + j]) * w32[j]


@njit(cache=True)
def _real_psd(spec: np.ndarray, x: np.ndarray) -> np.ndarray:
    """``welch_psd``'s PSD from the rfft of its frames (frames, bins) of the real samples x: |X|^2 summed over the
    frames in double (``frame_power``) over the frames, normalised (``_normalised``) to the power of the frames'
    samples (numpy's pairwise sum of the squares)."""
    nfr = spec.shape[0]
    nfft = 2 * (spec.shape[1] - 1)
    p = frame_power(spec) / nfr
    fv = x[: nfr * nfft]
    return _normalised_compiled(p, pairwise_sum(fv * fv, 0.0) / fv.size)


@njit(cache=True)
def _complex_psd(spec: np.ndarray, xv: np.ndarray) -> np.ndarray:
    """``welch_psd``'s PSD from the FFT of its frames (frames, nfft) of complex samples (xv: their float64 view, re and
    im pairs): re^2 and im^2 each summed over the frames in float32 (as ``np.einsum("ij,ij->j")`` of the float32 view
    sums them: in frame order), added in double, over the frames, in fftshift order, normalised (``_normalised``) to
    the power of the frames' samples (numpy's pairwise sum of the squares of the float64 view, over the samples)."""
    nfr, nfft = spec.shape
    sre = np.zeros(nfft, dtype=np.float32)
    sim = np.zeros(nfft, dtype=np.float32)
    for i in range(nfr):
        for b in range(nfft):
            v = spec[i, b]
            re = v.real
            im = v.imag
            sre[b] += re * re
            sim[b] += im * im
    p = np.empty(nfft)
    h = nfft // 2
    for b in range(nfft):
        j = b + nfft - h if b < h else b - h                 # np.fft.fftshift
        p[b] = (np.float64(sre[j]) + np.float64(sim[j])) / nfr
    fv = xv[: 2 * nfr * nfft]
    return _normalised_compiled(p, pairwise_sum(fv * fv, 0.0) / (nfr * nfft))


@njit(cache=True)
def _normalised_compiled(p: np.ndarray, power: float) -> np.ndarray:
    """:func:`_normalised` compiled (numpy's pairwise sum of p)."""
    total = pairwise_sum(p, 0.0)
    if not total > 0.0:
        return np.zeros_like(p)
    return p * (power / total)


@njit(cache=True)
def frame_power(spec: np.ndarray) -> np.ndarray:
    """Sum over frames (rows) of |X|^2 of a complex64 spectrum, accumulated in double."""
    nfr, nb = spec.shape
    acc = np.zeros(nb)
    for i in range(nfr):
        for b in range(nb):
            v = spec[i, b]
            re = np.float64(v.real)
            im = np.float64(v.imag)
            acc[b] += re * re + im * im
    return acc


_HANN: dict[int, np.ndarray] = {}
_HANN32: dict[int, np.ndarray] = {}


def _hann32(nfft: int) -> np.ndarray:
    """Cached single-precision Hann window of nfft points (read-only)."""
    w = _HANN32.get(nfft)
    if w is None:
        w = _hann(nfft).astype(np.float32)
        w.flags.writeable = False
        _HANN32[nfft] = w
    return w


def _hann(nfft: int) -> np.ndarray:
    """Cached Hann window of nfft points (read-only)."""
    w = _HANN.get(nfft)
    if w is None:
        w = np.hanning(nfft)
        w.flags.writeable = False
        _HANN[nfft] = w
    return w


def smooth_template(psd: np.ndarray, width: int) -> np.ndarray:
    """Noise-shape template from a (clean) PSD: median filter across frequency, sum normalised to 1.

    One compiled pass (:func:`_smooth_template`; speed: it runs on every block while no template is learned) that
    gives to the bit what ``scipy.ndimage.median_filter(psd, size=width, mode="nearest")``, the floor at 1e-6 of
    its largest bin and the division by its (pairwise) sum gave."""
    return _smooth_template(np.ascontiguousarray(psd, dtype=np.float64), int(width))


@njit(cache=True)
def _smooth_template(psd: np.ndarray, width: int) -> np.ndarray:
    """:func:`smooth_template`: the running median over ``width`` bins (bins width // 2 before to width - 1 - width // 2
    after, the edge bins repeated; the element of rank width // 2: scipy's median_filter), the floor, the sum. The
    PSD is finite (the monitor rejects a block whose power is not). ``numpy_kernels.running_median``: the window kept
    sorted as it slides (O(width) a bin, not the O(width^2) of sorting each window; the same element of the same
    rank)."""
    t = running_median(psd, width, MEDIAN_NEAREST)
    floor = 1e-6 * np.max(t)
    for i in range(t.size):
        t[i] = max(t[i], floor)
    return t / pairwise_sum(t, 0.0)


def block_features(x: np.ndarray, template: np.ndarray | None, par: ClassifierParams) -> BlockFeatures:
    """Spectral features of one block.

    Args:
        x: finite samples, shape (n,), n >= par.nfft.
        template: noise PSD shape (sum 1), shape as welch_psd; None: flat.
        par: ClassifierParams.
    """
    psd, frames = welch_psd(x, par.nfft, par.max_frames)
    return features_from_psd(psd, frames, template, par, np.iscomplexobj(x))


def features_from_psd(psd: np.ndarray, frames: int, template: np.ndarray | None, par: ClassifierParams,
                      cplx: bool) -> BlockFeatures:
    """``block_features`` from a Welch PSD already computed (``welch_psd``) of real or complex samples."""
    tpl = np.full(psd.size, 1.0 / psd.size) if template is None else np.ascontiguousarray(template,
                                                                                      dtype=np.float64)
    (power, scale, jn_spec, occupancy, k, dk,
     line) = _spectral_features(psd, tpl, max(par.sig_sigma / math.sqrt(frames), par.min_excess),
                                10 ** (-par.sidelobe_db / 10))
    nb = psd.size
    if cplx:
        f_pk = (k + dk - nb // 2) / par.nfft
    else:
        f_pk = (k + dk) / par.nfft
    return BlockFeatures(power, psd, frames, scale, jn_spec, occupancy, k, f_pk, line)


@njit(cache=True)
def _spectral_features(psd: np.ndarray, tpl: np.ndarray, thr: float, sidelobe: float
                       ) -> tuple[float, float, float, float, int, float, float]:
    """The features of ``block_features`` (module docstring) from the Welch PSD, in one compiled
    pass (speed: ~15 small numpy calls before). Returns (power, noise scale, jn_spectral_db,
    occupancy, peak bin k, parabolic offset of the peak in bins, line_fraction); ``thr`` is the
    occupied-bin threshold on the relative excess, ``sidelobe`` the relative floor below the
    strongest excess (linear)."""
    nb = psd.size
    white = psd / tpl
    power = 0.0
    tsum = 0.0
    for i in range(nb):
        power += psd[i]
        tsum += tpl[i]
    scale = float(np.median(white))
    k = int(np.argmax(white))
    dk = 0.0
    if 0 < k < nb - 1:
        a = math.log(psd[k - 1] + 1e-300)
        b = math.log(psd[k] + 1e-300)
        c = math.log(psd[k + 1] + 1e-300)
        den = a - 2 * b + c
        dk = 0.5 * (a - c) / den if den < 0 else 0.0
    if not scale > 0:
        return power, scale, -math.inf, 0.0, k, dk, 0.0
    # the relative floor keeps a strong CW's Hann sidelobes (< -31 dB) out of its occupancy
    emax = white[k] / scale - 1.0
    lim = max(thr, sidelobe * emax)
    noise_power = scale * tsum
    jpow = 0.0
    lpow = 0.0
    nocc = 0
    lo, hi = max(k - LINE_HALF_WIDTH_BINS, 0), min(k + LINE_HALF_WIDTH_BINS + 1, nb)
    for i in range(nb):
        if white[i] / scale - 1.0 > lim:
            e = (white[i] - scale) * tpl[i]
            jpow += e
            nocc += 1
            if lo <= i < hi:
                lpow += e
    jn_spec = 10 * math.log10(jpow / noise_power) if jpow > 0 else -math.inf
    line = lpow / jpow if jpow > 0 else 0.0
    return power, scale, jn_spec, nocc / nb, k, dk, line


def logistic(margin_db: float, slope_db: float) -> float:
    """1 / (1 + exp(-margin / slope)), safe for any margin (NaN -> 0.5)."""
    if not math.isfinite(margin_db):
        return 1.0 if margin_db > 0 else 0.0 if margin_db < 0 else 0.5
    return 1.0 / (1.0 + math.exp(-max(-50.0, min(50.0, margin_db / slope_db))))


def classify(feat: BlockFeatures, jn_power_db: float, period_locked: bool, sweep_rate: float,
             calibrated: bool, par: ClassifierParams) -> tuple[int, float]:
    """Type code and confidence of one block (decision rules in the module docstring).

    Args:
        feat: BlockFeatures.
        jn_power_db: J/N from power against the calibrated floor, dB (NaN when not calibrated).
        period_locked: the tracker's sweep period is locked.
        sweep_rate: the tracker's sweep rate estimate, cycles/sample^2.
        calibrated: the noise floor is known.
        par: ClassifierParams.
    """
    thr = par.detect_jn_db
    s = par.confidence_slope_db
    nb = feat.jn_spectral_db >= thr
    if nb:
        c_det = logistic(feat.jn_spectral_db - thr, s)
        if feat.occupancy <= par.cw_max_occupancy or feat.line_fraction >= CW_MIN_LINE_FRACTION:
            structure = 1.0 - 0.5 * min(feat.occupancy / par.cw_max_occupancy, 1.0)
            return CW, c_det * structure
        if period_locked:
            return CHIRP, c_det
        if abs(sweep_rate) >= par.min_chirp_rate:
            return CHIRP, 0.6 * c_det
    if calibrated and math.isfinite(jn_power_db) and jn_power_db >= thr:
        return WIDEBAND, logistic(jn_power_db - thr, s)
    if nb:
        return WIDEBAND, 0.5 * logistic(feat.jn_spectral_db - thr, s)
    if not calibrated:
        return UNKNOWN, 0.5
    m = max(feat.jn_spectral_db, jn_power_db if math.isfinite(jn_power_db) else -math.inf)
    return NONE, 1.0 - logistic(m - thr, s)
